"""Checkpoints: everything a run carries from one step to the next, in one HDF5 file.

The solver's :class:`~dolfin_mpm.explicit.state.State` (per rank: every particle array, ``cell``
and the material state included, the sinks' records, the non-local average's reference
positions and on several ranks its halo, the last changes of the internal forces; for the run:
time, step, time step and the fixed-point counters) and the scenario's own: the events applied
and the recorded history. The owned nodes' coordinates are stored to refuse a checkpoint of
another grid or partition. Each rank's part is a group of its own: where h5py has MPI each rank
writes it through MPI-IO, otherwise rank 0 gathers them; each rank reads its own. The file is
written under a temporary name, flushed to disk and renamed over the previous checkpoint, so
that a crash at any moment leaves the last complete one. Each group carries the SHA-256 of its
arrays and the file that of its attributes and the groups' checksums. Restoring it into a
freshly built scenario continues the run bit for bit on the same number of ranks. On another
number, each rank takes whole groups, the particles go to the owners of their cells on the new
partition and the non-local pair lists are built anew: the run continues to round-off (the sums
are taken in another order).
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
FORMAT = 6
#: Scenario keys a resumed run may change (the end time and the output, not the physics).
RESUMABLE = ("time.end", "output.")
#: The state's arrays of owned nodes, rows of ``owned nodes * gdim`` (:meth:`State.tree
#: <dolfin_mpm.explicit.state.State.tree>`): on another number of ranks, each rank takes its nodes' columns.
NODAL = ("R_changes", "v_mean")


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


def _read_tree(group: h5py.Group, rows: int | None = None, keys=None) -> dict:
    """The arrays under ``group`` (its members ``keys``, default all) as nested dicts.

    With ``rows``, only the first ``rows`` of each.
    """

    def value(d: h5py.Dataset) -> np.ndarray:
        return d[()] if rows is None or d.ndim == 0 else d[:rows]

    members = group.keys() if keys is None else keys
    return {
        k: _read_tree(group[k], rows) if isinstance(group[k], h5py.Group) else value(group[k])
        for k in members
    }


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

    Each rank's part is the group ``rank<r>``; where h5py has MPI, every rank writes its own
    into the file through MPI-IO, otherwise rank 0 gathers and writes them all.

    Args:
        path: the checkpoint file; a file of that name is replaced only once the new one is
            complete on disk.
        sim: the :class:`~dolfin_mpm.app.scenario.Simulation`.
        history: recorded columns by name, each ``shape=(records,)``.

    Raises:
        CheckpointError: the write failed (folder gone, disk full, ...); on every rank.

    """
    comm = sim.solver.comm
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    part, partition = _local_state(sim), sim.solver.grid.partition
    attrs = {
        "format": FORMAT,
        "ranks": comm.size,
        "applied": np.array(sim.applied, dtype=np.int64),
        "scenario": scenario_record(sim.config),
        "repartitioned": partition is not None,
        **sim.solver.state.scalars(),
    }
    # On rank 0: the parts all ranks share (the cells as they were dealt, to deal them again).
    shared = {"history": history}
    if partition is not None and comm.rank == 0:
        shared["partition"] = dict(zip(("cells", "ranks"), partition))
    collective = comm.size > 1 and h5py.get_config().mpi
    parts = [part] if collective else comm.gather(part, root=0)
    nbytes = comm.allreduce(tree_bytes(part)) + tree_bytes(shared)
    error = None
    if comm.rank == 0:
        try:
            ensure_room(path.parent, nbytes)
        except OSError as e:
            error = str(e)
    error = comm.bcast(error, root=0)
    if error is None:
        try:
            if collective:
                _write_collective(tmp, comm, attrs, part, shared)
            elif comm.rank == 0:
                tree = {**{f"rank{r}": p for r, p in enumerate(parts)}, **shared}
                digests = {name: _digest({}, t) for name, t in tree.items()}
                with h5py.File(tmp, "w") as f:
                    f.attrs.update(attrs, sha256=_seal(attrs, digests))
                    for name, t in tree.items():
                        _write_tree(f.create_group(name), t)
                        f[name].attrs["sha256"] = digests[name]
        except (OSError, RuntimeError, ValueError) as e:
            error = str(e)
    errors = [e for e in comm.allgather(error) if e]
    if comm.rank == 0:
        try:
            if errors:
                raise OSError(errors[0])
            fd = os.open(tmp, os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
            os.replace(tmp, path)
        except OSError as e:
            tmp.unlink(missing_ok=True)
            kept = "the previous checkpoint is intact" if path.exists() else "no earlier checkpoint exists"
            error = f"writing the checkpoint {path} failed ({e}); {kept}"
    error = comm.bcast(error, root=0)
    if error:
        raise CheckpointError(error)


def _write_collective(tmp: Path, comm, attrs: dict, part: dict, shared: dict) -> None:
    """Every rank writes its ``part`` into ``rank<r>`` of one file through MPI-IO; rank 0 ``shared``.

    HDF5 makes the groups, datasets and attributes together on all ranks (their shapes and
    checksums are exchanged first); the data then goes in from each rank alone.
    """
    layouts = comm.allgather(_layout(part))
    digests = comm.allgather(_digest({}, part))
    shared_layout, shared_digests = comm.bcast(
        ({k: _layout(t) for k, t in shared.items()}, {k: _digest({}, t) for k, t in shared.items()})
        if comm.rank == 0
        else None,
        root=0,
    )
    groups = {**{f"rank{r}": layout for r, layout in enumerate(layouts)}, **shared_layout}
    checksums = {**{f"rank{r}": d for r, d in enumerate(digests)}, **shared_digests}
    with h5py.File(tmp, "w", driver="mpio", comm=comm) as f:
        f.attrs.update(attrs, sha256=_seal(attrs, checksums))
        for name, layout in groups.items():
            group = f.create_group(name)
            group.attrs["sha256"] = checksums[name]
            for key, (shape, dtype) in layout.items():
                group.create_dataset(key, shape, dtype)
        mine = {f"rank{comm.rank}": part, **(shared if comm.rank == 0 else {})}
        for name, tree in mine.items():
            for key, value in _leaves(tree):
                if np.size(value):
                    f[name][key][...] = value


def _leaves(tree: dict, prefix: str = ""):
    """``(path, array)`` of every array in ``tree``, ``path`` like ``particles/state/eps``."""
    for name, value in tree.items():
        if isinstance(value, dict):
            yield from _leaves(value, f"{prefix}{name}/")
        else:
            yield prefix + name, np.asarray(value)


def _layout(tree: dict) -> dict:
    """``{path: (shape, dtype)}`` of the arrays of ``tree`` (:func:`_leaves`)."""
    return {key: (a.shape, a.dtype.str) for key, a in _leaves(tree)}


def _seal(attrs: dict, digests: dict[str, str]) -> str:
    """SHA-256 of the attributes and of the checksums of the state's groups.

    Not of the history's: a resumed run records it anew, and it carries its own.
    """
    state = {name: np.frombuffer(d.encode(), np.uint8) for name, d in digests.items() if name != "history"}
    return _digest(attrs, state)


def read(path, comm) -> dict:
    """The part of the checkpoint for this rank at ``path`` and the run's attributes (collective).

    Every rank opens the file and reads its own part. On the same number of ranks as the
    checkpoint's that is its group ``rank<r>``, and after a run that dealt its cells anew rank 0
    also gets their ``partition``. On another number, rank r takes the groups r, r + N, ...
    (N ranks) merged into one part (:func:`_merged`: the particles and the sinks' and the
    dissipation's totals), and every rank all nodes with their :data:`NODAL` rows: :func:`restore`
    then hands the particles to the owners of their cells. No rank holds more particles than
    the groups it takes.

    Returns:
        ``{"attrs": ..., "history": ..., "nodes": ...}`` and this rank's part of the state
        (see :meth:`State.tree <dolfin_mpm.explicit.state.State.tree>`).

    Raises:
        CheckpointError: missing, unreadable or corrupted file (its checksums or its values), or
            of another format.

    """
    data, error = None, None
    try:
        with h5py.File(path, "r") as f:
            data = _read_part(f, path, comm)
    except CheckpointError as e:
        error = str(e)
    except Exception as e:
        error = f"cannot read the checkpoint {path} ({type(e).__name__}: {e})"
    errors = [e for e in comm.allgather(error) if e]
    if errors:
        raise CheckpointError(errors[0])
    return data


def _read_part(f: h5py.File, path, comm) -> dict:
    """The part of the open checkpoint ``f`` for this rank, checksums and values checked (:func:`read`)."""
    attrs = dict(f.attrs)
    if attrs.get("format") != FORMAT:
        raise CheckpointError(
            f"{path}: written in format {attrs.get('format')}; this version reads format {FORMAT}"
        )
    corrupted = CheckpointError(f"{path} is corrupted: its checksum does not match its contents")
    if _seal(attrs, {name: f[name].attrs.get("sha256", "") for name in f}) != attrs.get("sha256"):
        raise corrupted

    def checked(name: str) -> dict:
        tree = _read_tree(f[name])
        if _digest({}, tree) != f[name].attrs["sha256"]:
            raise corrupted
        return tree

    _check_attrs(attrs)
    written = int(attrs["ranks"])
    history = checked("history")
    taken = [comm.rank] if written == comm.size else list(range(comm.rank, written, comm.size))
    parts = []
    for r in taken:
        parts.append(checked(f"rank{r}"))
        _check_part(parts[-1], r)
    if written == comm.size:
        part = parts[0]
        if "partition" in f and comm.rank == 0:
            part["partition"] = checked("partition")
    else:
        every = [f[f"rank{r}"] for r in range(written)]  # each checked by the rank that takes it
        if not parts:  # none for this rank: the first's structure without its particles
            g = every[0]
            keys = ("sinks", *(k for k in NODAL if k in g), "dissipated", "nodes")
            parts = [{"particles": _read_tree(g["particles"], rows=0), **_read_tree(g, keys=keys)}]
            parts[0] = _emptied(parts[0])
        part = _merged(parts)
        part["nodes"] = np.concatenate([g["nodes"][()] for g in every])
        for k in NODAL:
            if all(k in g for g in every):  # (v_mean is not in the checkpoints of earlier versions)
                part[k] = np.concatenate([g[k][()] for g in every], axis=1)
    return {"attrs": attrs, "history": history, **part}


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
        **{
            k: np.concatenate([part[k] for part in ranks], axis=1)
            for k in NODAL
            if all(k in part for part in ranks)
        },
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


def _check_attrs(attrs: dict) -> None:
    """Refuse values no run writes: a checksum recomputed after an edit does not make them good."""
    if not (math.isfinite(attrs["time"]) and math.isfinite(attrs["dt"]) and attrs["dt"] > 0.0):
        raise CheckpointError(
            f"the checkpoint is corrupted: time {attrs['time']!r}, time step {attrs['dt']!r}"
        )
    if not (attrs["step"] >= 0 and np.all(np.asarray(attrs["fixed_point"]) >= 0)):
        raise CheckpointError(
            f"the checkpoint is corrupted: step {attrs['step']!r}, loop counters {attrs['fixed_point']!r}"
        )


def _check_part(part: dict, r: int) -> None:
    """Refuse particle arrays of unequal length, non-finite values or non-positive volumes of rank ``r``."""
    particles = part["particles"]
    n = len(particles["mass"])
    arrays = [a for k, a in particles.items() if k != "state"] + list(particles.get("state", {}).values())
    if any(np.shape(a)[:1] != (n,) for a in arrays):
        raise CheckpointError(f"the checkpoint is corrupted: rank {r}'s particle arrays differ in length")
    real = [particles[k] for k in ("x", "v", "sigma", "mass", "volume")]
    if not all(np.all(np.isfinite(a)) for a in real) or np.any(particles["volume"] <= 0.0):
        raise CheckpointError(
            f"the checkpoint is corrupted: rank {r} holds a particle with a non-finite value or a "
            "non-positive volume"
        )


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
        data = {**data, **_owned_rows(data, owned, s.grid.gdim, s.comm)}
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


def _owned_rows(data: dict, owned: np.ndarray, gdim: int, comm) -> dict:
    """The columns of the :data:`NODAL` rows (all nodes of the checkpoint) of this rank's ``owned`` nodes.

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
    columns = (rows[:, None] * gdim + np.arange(gdim)).ravel()  # gdim entries per node
    return {k: np.asarray(data[k]).reshape(-1, len(nodes) * gdim)[:, columns] for k in NODAL if k in data}
