"""Checkpoints: everything a run carries from one step to the next, in one HDF5 file.

The solver's :class:`~dolfin_mpm.explicit.state.State` (per rank: every particle array, ``cell``
and the material state included, the sinks' records, the non-local average's reference
positions and on several ranks its halo, the last changes of the internal forces; for the run:
time, step, time step and the fixed-point counters) and the scenario's own: the events applied
and the recorded history. The owned nodes' coordinates are stored to refuse a checkpoint of
another grid or partition. Rank 0 gathers and writes it under
a temporary name, flushes it to disk and renames it over the previous checkpoint, so that a
crash at any moment leaves the last complete one. Restoring it into a freshly built scenario
continues the run bit for bit on the same number of ranks. On another number, the particles go
to the owners of their cells on the new partition and the non-local pair lists are built anew:
the run continues to round-off (the sums are taken in another order).
"""

import hashlib
import json
import math
import os
from pathlib import Path

import h5py
import numpy as np
from mpi4py import MPI
from scipy.spatial import cKDTree

from dolfin_mpm.core.locate import locate
from dolfin_mpm.io.disk import ensure_room, tree_bytes
from dolfin_mpm.parallel.migration import migrate

__all__ = ["FORMAT", "RESUMABLE", "CheckpointError", "read", "restore", "scenario_record", "write"]

#: Layout version, stored in the file.
FORMAT = 5
#: Scenario keys a resumed run may change (the end time and the output, not the physics).
RESUMABLE = ("time.end", "output.")


class CheckpointError(RuntimeError):
    """A checkpoint that cannot be written, read or applied; says which and why."""


def _local_state(sim) -> dict:
    s = sim.solver
    grid = s.grid
    # R's order: the same partition on resume.
    return {**s.state.tree(grid.num_owned_nodes * grid.gdim), "nodes": grid.node_x[: grid.num_owned_nodes]}


def _write_tree(group: h5py.Group, tree: dict) -> None:
    for name, value in tree.items():
        if isinstance(value, dict):
            _write_tree(group.create_group(name), value)
        else:
            group.create_dataset(name, data=value)


def _read_tree(group: h5py.Group) -> dict:
    return {k: _read_tree(v) if isinstance(v, h5py.Group) else v[()] for k, v in group.items()}


def _digest(attrs: dict, tree: dict) -> str:
    """SHA-256 of the attributes and every array of ``tree``: names, types, shapes and bytes."""
    h = hashlib.sha256()

    def add(name: str, value) -> None:
        a = np.ascontiguousarray(value)
        h.update(f"{name}|{a.dtype.str}|{a.shape}|".encode())
        h.update(a.tobytes())

    def walk(prefix: str, node: dict) -> None:
        for name in sorted(node):
            if isinstance(node[name], dict):
                walk(f"{prefix}{name}/", node[name])
            else:
                add(prefix + name, node[name])

    for name in sorted(set(attrs) - {"sha256", "scenario"}):
        add(f"@{name}", attrs[name])
    h.update(str(attrs.get("scenario", "")).encode())
    walk("", tree)
    return h.hexdigest()


def _flat(config: dict, prefix: str = "") -> dict:
    """``{"a.b.c": value}`` of a nested scenario, without the keys a resume may change."""
    out = {}
    for key, value in config.items():
        path = f"{prefix}{key}"
        if isinstance(value, dict):
            out.update(_flat(value, path + "."))
        elif not path.startswith(RESUMABLE):
            out[path] = value
    return out


def scenario_record(config: dict) -> str:
    """The scenario's physics and numerics as canonical JSON (what a resume must not change)."""
    return json.dumps(_flat(config), sort_keys=True, default=str)


def write(path, sim, history: dict[str, np.ndarray]) -> None:
    """Write the checkpoint of ``sim`` to ``path`` atomically (collective).

    Args:
        path: the checkpoint file; a file of that name is replaced only once the new one is
            complete on disk.
        sim: the :class:`~dolfin_mpm.app.scenario.Simulation`.
        history: recorded columns by name, each ``shape=(records,)``.

    Raises:
        CheckpointError: the write failed (folder gone, disk full, ...); on every rank.

    """
    comm = sim.solver.comm
    parts = comm.gather(_local_state(sim), root=0)
    partition = sim.solver.grid.partition
    error = None
    if comm.rank == 0:
        path = Path(path)
        tmp = path.with_name(path.name + ".tmp")
        try:
            ensure_room(path.parent, tree_bytes([parts, history]))
            with h5py.File(tmp, "w") as f:
                attrs = {
                    "format": FORMAT,
                    "ranks": comm.size,
                    "applied": np.array(sim.applied, dtype=np.int64),
                    "scenario": scenario_record(sim.config),
                    "repartitioned": partition is not None,
                    **sim.solver.state.scalars(),
                }
                ranks = {f"rank{rank}": part for rank, part in enumerate(parts)}
                if partition is not None:  # the cells dealt anew during the run: to deal them again
                    ranks["partition"] = dict(zip(("cells", "ranks"), partition))
                f.attrs.update(attrs, sha256=_digest(attrs, ranks))  # the state, and apart ...
                _write_tree(f, {**ranks, "history": history})
                f["history"].attrs["sha256"] = _digest({}, history)  # ... what the run recorded
            fd = os.open(tmp, os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
            os.replace(tmp, path)
        except (OSError, RuntimeError) as e:
            tmp.unlink(missing_ok=True)
            kept = "the previous checkpoint is intact" if path.exists() else "no earlier checkpoint exists"
            error = f"writing the checkpoint {path} failed ({e}); {kept}"
    error = comm.bcast(error, root=0)
    if error:
        raise CheckpointError(error)


def read(path, comm) -> dict:
    """The part of the checkpoint for this rank at ``path`` and the run's attributes (collective).

    Returns:
        ``{"attrs": ..., "history": ..., "nodes": ...}`` and this rank's part of the state
        (see :meth:`State.tree <dolfin_mpm.explicit.state.State.tree>`).

    On another number of ranks than the checkpoint's, rank 0 gets every particle and the
    sinks' and the dissipation's totals, the others none, and every rank all nodes with their
    ``R_changes``: :func:`restore` then hands the particles to their owners. On the same
    number, after a run that dealt its cells anew, rank 0 also gets their ``partition``.

    Raises:
        CheckpointError: missing, unreadable or corrupted file (its checksum or its values), or
            of another format.

    """
    parts, error = None, None
    if comm.rank == 0:
        try:
            with h5py.File(path, "r") as f:
                attrs = dict(f.attrs)
                if attrs.get("format") != FORMAT:
                    raise CheckpointError(
                        f"{path}: written in format {attrs.get('format')}; this version reads format {FORMAT}"
                    )
                tree = _read_tree(f)
                history_sha = f["history"].attrs.get("sha256")
            history = tree.pop("history")
            if _digest(attrs, tree) != attrs.get("sha256") or _digest({}, history) != history_sha:
                raise CheckpointError(f"{path} is corrupted: its checksum does not match its contents")
            written = int(attrs["ranks"])
            _check_values(attrs, tree, written)
            ranks = [tree[f"rank{r}"] for r in range(written)]
            if written != comm.size:
                whole = _merged(ranks)
                ranks = [whole, *[_emptied(whole) for _ in range(comm.size - 1)]]
            elif "partition" in tree:
                ranks[0] = {**ranks[0], "partition": tree["partition"]}
            parts = [{"attrs": attrs, "history": history, **part} for part in ranks]
        except CheckpointError as e:
            error = str(e)
        except Exception as e:
            error = f"cannot read the checkpoint {path} ({type(e).__name__}: {e})"
    error = comm.bcast(error, root=0)
    if error:
        raise CheckpointError(error)
    return comm.scatter(parts, root=0)


def _merged(ranks: list[dict]) -> dict:
    """The ranks' parts of a checkpoint as one: a part for a run on another number of ranks.

    Particles and nodes are concatenated in rank order; the sinks' records and the dissipated
    work summed, the sinks' histories combined into the cumulative mass over all ranks. The
    non-local average's pair lists and halos are left out: they are built anew.
    """

    def joined(trees: list) -> dict | np.ndarray:
        if isinstance(trees[0], dict):
            return {k: joined([t[k] for t in trees]) for k in trees[0]}
        return np.concatenate(trees)

    sinks = {}
    for name in ranks[0]["sinks"]:
        records = [part["sinks"][name] for part in ranks]
        sink = {k: np.sum([r[k] for r in records], axis=0) for k in ("mass", "momentum", "count", "energy")}
        times = np.unique(np.concatenate([r["history"][:, 0] for r in records]))
        cumulative = sum(_at(r["history"], times) for r in records)
        sink["history"] = np.column_stack([times, cumulative]) if times.size else np.zeros((0, 2))
        sinks[name] = sink
    return {
        "particles": joined([part["particles"] for part in ranks]),
        "sinks": sinks,
        "nonlocal": {},
        "R_changes": np.concatenate([part["R_changes"] for part in ranks], axis=1),
        "dissipated": np.sum([part["dissipated"] for part in ranks]),
        "nodes": np.concatenate([part["nodes"] for part in ranks]),
        "resharded": True,
    }


def _at(history: np.ndarray, times: np.ndarray) -> np.ndarray:
    """A cumulative record ``(t, value)`` at ``times``: its last value at or before each (0 before)."""
    k = np.searchsorted(history[:, 0], times, side="right")
    return np.where(k > 0, history[np.maximum(k - 1, 0), 1], 0.0) if len(history) else np.zeros(len(times))


def _emptied(whole: dict) -> dict:
    """``whole`` without particles and with zero sinks and dissipation: a rank's part before its share."""
    particles = {
        k: ({n: a[:0] for n, a in v.items()} if isinstance(v, dict) else v[:0])
        for k, v in whole["particles"].items()
    }
    sinks = {
        name: {k: (np.zeros((0, 2)) if k == "history" else np.zeros_like(v)) for k, v in rec.items()}
        for name, rec in whole["sinks"].items()
    }
    return {**whole, "particles": particles, "sinks": sinks, "dissipated": np.zeros(())}


def _check_values(attrs: dict, tree: dict, ranks: int) -> None:
    """Refuse values no run writes: a checksum recomputed after an edit does not make them good."""

    def bad(what: str):
        return CheckpointError(f"the checkpoint is corrupted: {what}")

    if not (math.isfinite(attrs["time"]) and math.isfinite(attrs["dt"]) and attrs["dt"] > 0.0):
        raise bad(f"time {attrs['time']!r}, time step {attrs['dt']!r}")
    if not (attrs["step"] >= 0 and np.all(np.asarray(attrs["fixed_point"]) >= 0)):
        raise bad(f"step {attrs['step']!r}, loop counters {attrs['fixed_point']!r}")
    for r in range(ranks):
        particles = tree[f"rank{r}"]["particles"]
        n = len(particles["mass"])
        arrays = [a for k, a in particles.items() if k != "state"] + list(particles.get("state", {}).values())
        if any(np.shape(a)[:1] != (n,) for a in arrays):
            raise bad(f"rank {r}'s particle arrays differ in length")
        real = [particles[k] for k in ("x", "v", "sigma", "mass", "volume")]
        if not all(np.all(np.isfinite(a)) for a in real) or np.any(particles["volume"] <= 0.0):
            raise bad(f"rank {r} holds a particle with a non-finite value or a non-positive volume")


def restore(sim, data: dict) -> None:
    """Put the checkpoint ``data`` (from :func:`read`) into a freshly built ``sim``.

    Raises:
        CheckpointError: the checkpoint does not fit the scenario (other fields, sinks or grid).

    """
    s = sim.solver
    if not s.comm.allreduce(s.state.fits(data), MPI.LAND):  # on every rank
        raise CheckpointError("the checkpoint does not fit the scenario (particle fields or sinks differ)")
    resharded = data.get("resharded", False)
    if data["attrs"].get("repartitioned", False) and not resharded:  # the cells as they were dealt
        partition = data.get("partition")
        if partition is None:
            partition = {"cells": np.zeros((0, s.grid.gdim + 1), np.int64), "ranks": np.zeros(0, np.int32)}
        s.deal(partition["cells"], partition["ranks"])
    owned = s.grid.node_x[: s.grid.num_owned_nodes]
    if resharded:
        data = {**data, "R_changes": _owned_rows(data, owned, s.grid.gdim, s.comm)}
    elif not s.comm.allreduce(np.array_equal(data["nodes"], owned), MPI.LAND):  # on every rank
        raise CheckpointError(
            "the checkpoint does not fit the scenario (the grid's nodes, or their partition, differ)"
        )
    was, now = json.loads(data["attrs"]["scenario"]), json.loads(scenario_record(sim.config))
    changed = sorted(k for k in was.keys() | now.keys() if was.get(k) != now.get(k))
    if changed:
        shown = ", ".join(f"{k} ({was.get(k)!r} -> {now.get(k)!r})" for k in changed[:5])
        raise CheckpointError(
            f"the scenario differs from the one the checkpoint was written by: {shown}"
            f"{' and more' if len(changed) > 5 else ''}; a resumed run may change only "
            "time.end and output.*"
        )
    applied = np.asarray(data["attrs"]["applied"])
    if len(set(applied.tolist())) < applied.size or not np.all(
        (0 <= applied) & (applied < len(sim.config["events"]))
    ):
        raise CheckpointError(f"the checkpoint is corrupted: applied events {applied.tolist()}")
    sim.applied.clear()
    for k in data["attrs"]["applied"]:
        sim.apply_event(int(k))  # walls and damping as they were
    s.state.restore(data["attrs"], data)
    if resharded:  # rank 0 holds every particle: to the owners of their cells, then balanced
        P = s.particles
        migrate(s.grid, P, locate(s.grid, P.x, np.full(len(P), -1, dtype=np.int32))[0])
        s.state.balanced = 1.0  # another number of ranks: what its repartitions left does not hold
        if s.comm.size > 1 and s.imbalance() > s.model.options.rebalance:
            s.rebalance()


def _owned_rows(data: dict, owned: np.ndarray, gdim: int, comm) -> np.ndarray:
    """The columns of ``R_changes`` (all nodes of the checkpoint) of this rank's ``owned`` nodes.

    A node is the checkpoint's node within 1e-9 of the mesh's extent: a mesh made on another
    partition may place its nodes differently in the last bits. Raises ``CheckpointError`` on
    every rank unless the checkpoint's nodes are the grid's.
    """
    nodes = data["nodes"]
    extent = float(np.ptp(nodes, axis=0).max()) if len(nodes) else 0.0
    distance, rows = cKDTree(nodes).query(owned, distance_upper_bound=1e-9 * extent)
    matched = bool(np.all(np.isfinite(distance))) and len(np.unique(rows)) == len(rows)
    if not comm.allreduce(matched, MPI.LAND) or comm.allreduce(len(owned)) != len(nodes):
        raise CheckpointError("the checkpoint does not fit the scenario (the grid's nodes differ)")
    columns = (rows[:, None] * gdim + np.arange(gdim)).ravel()  # R holds gdim entries per node
    return np.asarray(data["R_changes"]).reshape(-1, len(nodes) * gdim)[:, columns]
