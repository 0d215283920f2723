"""Checkpoints: everything a run carries from one step to the next, in one HDF5 file.

Per rank: every particle array (``cell`` and the material state included), the sinks'
records, the non-local average's reference positions (see :meth:`NonlocalAverage.state`) and
its halo on several ranks (see :meth:`DistributedAverage.state`), and the solver's last changes
of the internal forces (its fixed-point loop extrapolates them); for the run: time, step, time
step, damping, the events applied and the recorded history. Rank 0 gathers and writes it under
a temporary name, flushes it to disk and renames it over the previous checkpoint, so that a
crash at any moment leaves the last complete one. Restoring it into a freshly built scenario
continues the run bit for bit (on the same number of ranks).
"""

import os
from pathlib import Path

import h5py
import numpy as np
from mpi4py import MPI

from dolfin_mpm.core.particles import Particles

__all__ = ["FORMAT", "CheckpointError", "read", "restore", "write"]

#: Layout version, stored in the file.
FORMAT = 3


class CheckpointError(RuntimeError):
    """A checkpoint that cannot be written, read or applied; says which and why."""


def _local_state(sim) -> dict:
    s = sim.solver
    sinks = {
        name: {
            "mass": np.array(k.mass), "momentum": np.asarray(k.momentum), "count": np.array(k.count),
            "history": np.array(k.history, dtype=np.float64).reshape(-1, 2),
        }
        for name, k in s.sinks.items()
    }  # fmt: skip
    averaging = s.averaging.state() if s.averaging is not None else {}
    owned = s.grid.num_owned_nodes * s.grid.gdim
    R_changes = np.array(s.R_changes, dtype=np.float64).reshape(len(s.R_changes), owned)
    nodes = s.grid.node_x[: s.grid.num_owned_nodes]  # R's order: the same partition on resume
    return {
        "particles": dict(s.particles.arrays()), "sinks": sinks, "nonlocal": averaging,
        "solver": {"R_changes": R_changes, "nodes": nodes},
    }  # fmt: skip


def _write_tree(group: h5py.Group, tree: dict) -> None:
    for name, value in tree.items():
        if isinstance(value, dict):
            _write_tree(group.create_group(name), value)
        else:
            group.create_dataset(name, data=value)


def _read_tree(group: h5py.Group) -> dict:
    return {k: _read_tree(v) if isinstance(v, h5py.Group) else v[()] for k, v in group.items()}


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
    s, comm = sim.solver, sim.solver.comm
    parts = comm.gather(_local_state(sim), root=0)
    error = None
    if comm.rank == 0:
        path = Path(path)
        tmp = path.with_name(path.name + ".tmp")
        try:
            with h5py.File(tmp, "w") as f:
                f.attrs.update(
                    format=FORMAT, ranks=comm.size, time=s.time, step=s.step_count, dt=s.dt,
                    damping=s.damping, applied=np.array(sim.applied, dtype=np.int64),
                    fixed_point=np.array([s.fixed_point[k] for k in sorted(s.fixed_point)]),
                )  # fmt: skip
                for rank, part in enumerate(parts):
                    _write_tree(f.create_group(f"rank{rank}"), part)
                _write_tree(f.create_group("history"), history)
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
        ``{"attrs": ..., "history": ..., "particles": ..., "sinks": ..., "nonlocal": ...,
        "solver": ...}``.

    Raises:
        CheckpointError: missing or unreadable file, or written by another number of ranks.

    """
    parts, error = None, None
    if comm.rank == 0:
        try:
            with h5py.File(path, "r") as f:
                attrs = dict(f.attrs)
                if attrs.get("format") != FORMAT or attrs.get("ranks") != comm.size:
                    raise CheckpointError(
                        f"{path}: written by {attrs.get('ranks')} ranks (format {attrs.get('format')}); "
                        f"resume it on {attrs.get('ranks')} ranks with this version (format {FORMAT})"
                    )
                history = _read_tree(f["history"])
                parts = [
                    {"attrs": attrs, "history": history, **_read_tree(f[f"rank{r}"])}
                    for r in range(comm.size)
                ]
        except (OSError, KeyError, CheckpointError) as e:
            error = str(e) if isinstance(e, CheckpointError) else f"cannot read the checkpoint {path} ({e})"
    error = comm.bcast(error, root=0)
    if error:
        raise CheckpointError(error)
    return comm.scatter(parts, root=0)


def restore(sim, data: dict) -> None:
    """Put the checkpoint ``data`` (from :func:`read`) into a freshly built ``sim``.

    Raises:
        CheckpointError: the checkpoint does not fit the scenario (other fields, sinks or grid).

    """
    s, attrs = sim.solver, data["attrs"]
    P, arrays = s.particles, data["particles"]
    state = arrays.pop("state", {})
    if (
        set(arrays) != set(Particles._fields)
        or set(state) != set(P.state)
        or set(data["sinks"]) != set(s.sinks)
    ):
        raise CheckpointError("the checkpoint does not fit the scenario (particle fields or sinks differ)")
    R_changes = np.array(data["solver"]["R_changes"], dtype=np.float64)
    same_nodes = np.array_equal(data["solver"]["nodes"], s.grid.node_x[: s.grid.num_owned_nodes])
    if not s.comm.allreduce(same_nodes, MPI.LAND):  # on every rank
        raise CheckpointError(
            "the checkpoint does not fit the scenario (the grid's nodes, or their partition, differ)"
        )
    for name, a in arrays.items():
        setattr(P, name, np.ascontiguousarray(a))
    P.state = {name: np.ascontiguousarray(a) for name, a in state.items()}
    for name, rec in data["sinks"].items():
        sink = s.sinks[name]
        sink.mass, sink.count = float(rec["mass"]), int(rec["count"])
        sink.momentum = np.array(rec["momentum"], dtype=np.float64)
        sink.history = [(float(t), float(m)) for t, m in rec["history"]]
    if s.averaging is not None:
        s.averaging.restore(data["nonlocal"])
    s.R_changes = list(R_changes)
    sim.applied.clear()
    for k in attrs["applied"]:
        sim.apply_event(int(k))
    s.time, s.step_count, s.dt, s.damping = (
        float(attrs["time"]),
        int(attrs["step"]),
        float(attrs["dt"]),
        float(attrs["damping"]),
    )
    s.fixed_point.update(zip(sorted(s.fixed_point), (int(v) for v in attrs["fixed_point"])))
