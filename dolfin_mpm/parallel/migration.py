"""Particles on DOLFINx's mesh partition: each rank holds the particles of the cells it owns.

After the particles move, :func:`migrate` sends every particle that entered a ghost cell to
that cell's owner (the cell index map knows it) and asks all ranks for the owner of a particle
that left the local part of the mesh altogether (rare: particles move less than a cell per
step). Every per-particle array travels, material state included.

Everything here is collective over the grid's communicator.
"""

import numpy as np

from dolfin_mpm.core.grid import Grid
from dolfin_mpm.core.locate import locate
from dolfin_mpm.core.particles import Particles

__all__ = ["exchange", "migrate"]


def exchange(comm, particles: Particles, dest: np.ndarray) -> int:
    """Send particle ``k`` to rank ``dest[k]`` (it stays where ``dest[k]`` is this rank).

    Received particles are appended with an unknown cell (``-1``). Returns the number of
    particles sent from all ranks.
    """
    leave = dest != comm.rank
    total = comm.allreduce(int(leave.sum()))
    if total == 0:
        return 0
    index = np.flatnonzero(leave)
    send = [None] * comm.size
    for rank in np.unique(dest[index]):
        send[rank] = particles.take(index[dest[index] == rank])
    received = comm.alltoall(send)
    particles.keep(~leave)
    for batch in received:
        if batch is not None:
            batch.cell[:] = -1
            particles.extend(batch)
    return total


def _owners_elsewhere(grid: Grid, x: np.ndarray) -> np.ndarray:
    """Rank whose owned cells hold each point of ``x`` (``(n, 3)``, this rank's), -1 for none."""
    comm = grid.comm
    claims = []
    for points in comm.allgather(x):
        cells, _ = locate(grid, points, np.full(len(points), -1, dtype=np.int32))
        claims.append((cells >= 0) & (cells < grid.num_owned_cells))
    claimed = np.array(comm.alltoall(claims), dtype=bool).reshape(comm.size, len(x))
    return np.where(claimed.any(axis=0), np.argmax(claimed, axis=0), -1)


def migrate(grid: Grid, particles: Particles, cells: np.ndarray) -> int:
    """Move every particle to the rank owning its cell.

    Args:
        grid: the background grid.
        particles: this rank's particles; changed in place (order, count). Their ``cell``
            becomes ``cells`` for those that stay and -1 for those received.
        cells: each particle's local cell from :func:`~dolfin_mpm.core.locate.locate`, -1 where
            it is outside the local mesh, ``shape=(n,)``.

    Returns:
        The number of particles moved on all ranks. A particle no rank owns (outside the
        grid) stays where it is, with cell -1.

    """
    comm = grid.comm
    dest = np.full(len(cells), comm.rank, dtype=np.int32)
    found = cells >= 0
    dest[found] = grid.cell_owner[cells[found]]
    lost = np.flatnonzero(~found)
    if comm.allreduce(lost.size):
        owner = _owners_elsewhere(grid, particles.x[lost])
        dest[lost] = np.where(owner >= 0, owner, comm.rank)
    particles.cell = cells
    return exchange(comm, particles, dest)
