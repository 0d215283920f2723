"""Rebalancing during a run: the same mesh dealt to the ranks anew by the particles it holds.

:func:`repartition` gathers the mesh's cells and nodes in their input numbering on rank 0,
deals the cells by :func:`~dolfin_mpm.parallel.partition.bisection` of each cell's particle
count, and has DOLFINx create the mesh on that partition (its partitioner hook, as at the
start; :func:`deal`). :func:`move_to` then hands every particle, with its whole state, to the
new owner of its cell, and carries the grid's nodal fields and the fixed-point loop's changes of
``R`` over by the nodes' input numbers; :func:`renumber` does so for the nodal boundary
conditions' nodes and values.
The non-local average's halo and pair list see the arrivals and are built anew at the next
step.

Everything here is collective over the grid's communicator.
"""

import numpy as np

from dolfin_mpm.core import compat
from dolfin_mpm.core.boundary import BoundaryCondition
from dolfin_mpm.core.grid import Grid
from dolfin_mpm.core.locate import locate
from dolfin_mpm.core.particles import Particles
from dolfin_mpm.parallel.migration import exchange, migrate
from dolfin_mpm.parallel.partition import bisection, destinations

__all__ = ["NODAL_FIELDS", "deal", "move_to", "renumber", "repartition"]


def deal(grid: Grid, cells: np.ndarray, ranks: np.ndarray) -> Grid:
    """The grid of ``grid``'s mesh with its cells on ``ranks``.

    ``cells`` (each cell's vertices by their input numbers, ``shape=(num_cells, gdim + 1)``)
    and ``ranks`` (``shape=(num_cells,)``) on rank 0, empty arrays on the others: DOLFINx
    creates the mesh from them, the same mesh for the same arrays.
    """
    comm, msh, gdim = grid.comm, grid.mesh, grid.gdim
    local = msh.geometry.index_map().size_local
    inputs = np.asarray(msh.geometry.input_global_indices, dtype=np.int64)[:local]
    gathered = comm.gather((inputs, msh.geometry.x[:local, :gdim]), root=0)
    x, dest = np.zeros((0, gdim)), None
    if comm.rank == 0:
        x = np.empty((sum(len(g[0]) for g in gathered), gdim))
        for index, coordinates in gathered:
            x[index] = coordinates
        dest = destinations(cells, ranks)
    return grid.repartitioned(compat.create_mesh(comm, cells, x, dest), (cells, ranks))


def repartition(grid: Grid, particles: Particles, axes=None) -> tuple[Grid | None, np.ndarray]:
    """The grid of the same mesh with its cells dealt to the ranks by their particle counts.

    Args:
        grid: the grid now.
        particles: this rank's particles; their ``cell`` (owned cells) gives the weights.
        axes: the axes of the bisection's cuts, cycled (``None``: each set's longest extent).

    Returns:
        ``(grid, owner)``: the new grid, and the new owner rank of each of this rank's owned
        cells (``shape=(num_owned_cells,)``). ``(None, owner)`` where some rank would get no
        cells: the grid stays.

    """
    comm, msh = grid.comm, grid.mesh
    owned = grid.num_owned_cells
    cell = particles.cell
    counts = np.bincount(cell[(cell >= 0) & (cell < owned)], minlength=owned)[:owned]
    inputs = np.asarray(msh.geometry.input_global_indices, dtype=np.int64)
    geometry = compat.geometry_dofmap(msh)
    centroids = msh.geometry.x[geometry[:owned], : grid.gdim].mean(axis=1)
    gathered = comm.gather((inputs[geometry[:owned]], counts, centroids), root=0)
    cells, ranks, split, usable = np.zeros((0, grid.gdim + 1), np.int64), np.zeros(0, np.int32), None, None
    if comm.rank == 0:
        cells = np.concatenate([g[0] for g in gathered])
        weight = np.concatenate([g[1] for g in gathered]).astype(np.float64)
        ranks = bisection(np.concatenate([g[2] for g in gathered]), weight, comm.size, axes)
        usable = bool(np.bincount(ranks, minlength=comm.size).min() > 0)
        split = np.split(ranks, np.cumsum([len(g[0]) for g in gathered])[:-1])
    owner = comm.scatter(split, root=0)
    if not comm.bcast(usable, root=0):
        return None, owner
    return deal(grid, cells, ranks), owner


def renumber(old: Grid, new: Grid, bcs: list) -> None:
    """Give the nodal boundary conditions in ``bcs`` their nodes (and values) on ``new``, in place."""
    comm = old.comm
    was, now = old.node_inputs(), new.node_inputs()
    for bc in bcs:
        if isinstance(bc, BoundaryCondition):  # rigid walls are geometry: nothing to renumber
            keys = np.concatenate(comm.allgather(was[bc.nodes]))
            values = {k: np.concatenate(comm.allgather(v)) for k, v in bc.node_values().items()}
            keys, first = np.unique(keys, return_index=True)
            nodes = np.flatnonzero(np.isin(now, keys))
            rows = first[np.searchsorted(keys, now[nodes])]
            bc.renumber(nodes, {k: v[rows] for k, v in values.items()})


#: The grid's nodal Functions a step leaves for the output and the reactions to read.
NODAL_FIELDS = ("mass", "momentum", "f_ext", "f_int", "f_contact", "velocity", "acceleration")


def move_to(
    old: Grid, new: Grid, owner: np.ndarray, particles: Particles, R_changes: list, v_mean: np.ndarray | None
) -> tuple[list, np.ndarray | None]:
    """Carry a run's state from grid ``old`` to grid ``new`` of :func:`repartition`.

    The particles go to ``owner`` of their cells, then to the owners of the cells they are in
    on ``new``; the last step's :data:`NODAL_FIELDS` are copied node for node; ``R_changes``
    and ``v_mean`` (each ``shape=(owned nodes * gdim,)`` of ``old``, or ``None``) are returned
    for ``new``'s owned nodes.
    """
    comm = old.comm
    cell = particles.cell
    dest = np.full(len(particles), comm.rank, dtype=np.int32)
    known = (cell >= 0) & (cell < old.num_owned_cells)
    dest[known] = owner[cell[known]]
    exchange(comm, particles, dest)
    migrate(new, particles, locate(new, particles.x, np.full(len(particles), -1, dtype=np.int32))[0])
    rows = _owned_rows(old, new)
    for name in NODAL_FIELDS:
        was, now = getattr(old, name), getattr(new, name)
        width = was.x.array.size // old.num_nodes
        values = was.x.array[: old.num_owned_nodes * width].reshape(old.num_owned_nodes, width)
        new.refresh_ghosts(now, np.concatenate(comm.allgather(values))[rows].ravel())

    def moved(arrays: list) -> list:  # rows of owned nodal values, node for node
        if not arrays:
            return []
        a = np.array(arrays).reshape(len(arrays), old.num_owned_nodes, old.gdim)
        return list(np.concatenate(comm.allgather(a), axis=1)[:, rows].reshape(len(arrays), -1))

    return moved(R_changes), (None if v_mean is None else moved([v_mean])[0])


def _owned_rows(old: Grid, new: Grid) -> np.ndarray:
    """Where ``new``'s owned nodes sit among all ranks' owned nodes of ``old``, in rank order."""
    was = np.concatenate(old.comm.allgather(old.node_inputs()[: old.num_owned_nodes]))
    order = np.argsort(was)
    return order[np.searchsorted(was, new.node_inputs()[: new.num_owned_nodes], sorter=order)]
