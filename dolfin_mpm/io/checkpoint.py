"""Checkpoints: everything a run carries from one step to the next, in one HDF5 file.

The solver's :class:`~dolfin_mpm.explicit.state.State` (per rank: every particle array, ``cell``
and the material state included, the sinks' records, the non-local average's reference
positions and on several ranks its halo, the last changes of the internal forces; for the run:
time, step, time step and the fixed-point counters) and the scenario's own: the events applied
and the recorded history. The owned nodes' coordinates are stored to refuse a checkpoint of
another grid or partition. Rank 0 gathers and writes it under
a temporary name, flushes it to disk and renames it over the previous checkpoint, so that a
crash at any moment leaves the last complete one. Restoring it into a freshly built scenario
continues the run bit for bit (on the same number of ranks).
"""

import os
from pathlib import Path

import h5py
import numpy as np
from mpi4py import MPI

__all__ = ["FORMAT", "CheckpointError", "read", "restore", "write"]

#: Layout version, stored in the file.
FORMAT = 4


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
    error = None
    if comm.rank == 0:
        path = Path(path)
        tmp = path.with_name(path.name + ".tmp")
        try:
            with h5py.File(tmp, "w") as f:
                f.attrs.update(
                    format=FORMAT,
                    ranks=comm.size,
                    applied=np.array(sim.applied, dtype=np.int64),
                    **sim.solver.state.scalars(),
                )
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
        ``{"attrs": ..., "history": ..., "nodes": ...}`` and this rank's part of the state
        (see :meth:`State.tree <dolfin_mpm.explicit.state.State.tree>`).

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
    s = sim.solver
    if not s.state.fits(data):
        raise CheckpointError("the checkpoint does not fit the scenario (particle fields or sinks differ)")
    same_nodes = np.array_equal(data["nodes"], s.grid.node_x[: s.grid.num_owned_nodes])
    if not s.comm.allreduce(same_nodes, MPI.LAND):  # on every rank
        raise CheckpointError(
            "the checkpoint does not fit the scenario (the grid's nodes, or their partition, differ)"
        )
    sim.applied.clear()
    for k in data["attrs"]["applied"]:
        sim.apply_event(int(k))  # walls and damping as they were
    s.state.restore(data["attrs"], data)
