"""Cell partitions that balance particles rather than cells, for DOLFINx's mesh creation.

DOLFINx's graph partitioners give every rank about as many cells; an MPM step costs per
particle. Where the particles fill only part of the mesh (a silo above its free-fall zone)
ranks then hold very different numbers of them. :func:`bisection` deals cells to ranks by
recursive coordinate bisection of a per-cell weight (the particles a cell will hold), and
:func:`destinations` adds the ghost ranks, in the form DOLFINx's partitioner hook returns;
:func:`create_rectangle` and :func:`create_box` build a mesh so. The partition is fixed at mesh
creation: choose cuts that particles do not cross in bulk as the run goes on (a symmetric silo:
across its width). Unlike DOLFINx's graph partitioners, which may cut a mesh differently from
one run to the next, the bisection is the same in every run, so a checkpoint of the run can be
resumed on as many ranks.
"""

from collections.abc import Callable

import numpy as np
import scipy.sparse as sp
from dolfinx import mesh as dmesh
from mpi4py import MPI

from dolfin_mpm.core import compat

__all__ = ["bisection", "create_box", "create_rectangle", "destinations"]


def bisection(points: np.ndarray, weight: np.ndarray, nparts: int, axes=None) -> np.ndarray:
    """The part of each point, ``0 <= part < nparts``, the parts of nearly equal total weight.

    Recursive coordinate bisection: a set of points meant for ``k`` parts is cut across one
    axis where ``k // 2`` parts' share of its weight lies below the cut (of its count, where
    the set weighs nothing). Points with the same coordinate stay on the same side.

    Args:
        points: ``shape=(n, gdim)``.
        weight: ``shape=(n,)``, >= 0.
        nparts: number of parts, >= 1.
        axes: the axis of the cut at each level of the recursion, cycled; default: the
            longest extent of the set being cut.

    """
    weight = np.asarray(weight, dtype=np.float64)
    if np.any(weight < 0.0) or not np.all(np.isfinite(weight)):
        raise ValueError("weight must be finite and >= 0")
    part = np.zeros(len(points), dtype=np.int32)
    todo = [(np.arange(len(points)), 0, nparts, 0)]  # (points, first part, parts, level)
    while todo:
        index, first, k, level = todo.pop()
        if k == 1 or len(index) == 0:
            part[index] = first
            continue
        p = points[index]
        axis = np.argmax(np.ptp(p, axis=0)) if axes is None else axes[level % len(axes)]
        order = np.argsort(p[:, axis], kind="stable")
        w = weight[index][order]
        coord, below = p[order, axis], np.cumsum(w if w.sum() > 0.0 else np.ones_like(w))
        target = below[-1] * (k // 2) / k
        # The cut between two distinct coordinates closest to the target share.
        ends = np.flatnonzero(np.r_[coord[1:] != coord[:-1], True])  # last point of each coordinate
        cut = ends[np.argmin(np.abs(below[ends] - target))] + 1
        half = k // 2
        todo.append((index[order[:cut]], first, half, level + 1))
        todo.append((index[order[cut:]], first + half, k - half, level + 1))
    return part


def destinations(cells: np.ndarray, part: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The ranks of each cell for DOLFINx, as ``(data, offsets)`` (int32).

    Cell ``c``'s are ``data[offsets[c]:offsets[c + 1]]``: its owner ``part[c]`` first, then
    the owners of the cells that share a vertex with it (it is a ghost there). ``cells``:
    vertex numbers, ``shape=(num_cells, nodes)``.
    """
    n, nparts = len(cells), int(part.max(initial=0)) + 1
    rows = np.repeat(np.arange(n), cells.shape[1])
    num_vertices = cells.max(initial=0) + 1
    cell_vertex = sp.csr_matrix((np.ones(rows.size), (rows, cells.ravel())), shape=(n, num_vertices))
    owned = sp.csr_matrix((np.ones(n), (np.arange(n), part)), shape=(n, nparts))
    near = (cell_vertex @ (cell_vertex.T @ owned)).tocsr()  # cells x ranks: shared vertices
    near.data[:] = 1.0
    near = (near - owned).tocoo()  # the ranks other than the owner
    keep = near.data > 0
    cell = np.r_[np.arange(n), near.row[keep]]
    rank = np.r_[part, near.col[keep]].astype(np.int32)
    order = np.lexsort((np.arange(len(cell)) >= n, cell))  # by cell, its owner first
    offsets = np.r_[0, np.cumsum(np.bincount(cell, minlength=n))].astype(np.int32)
    data = rank[order]
    return data, offsets


def create_rectangle(comm, corners, n, weight: Callable | None = None, axes=None, diagonal="right"):
    """DOLFINx's rectangle of ``n = (nx, ny)`` squares of two triangles between ``corners``.

    Without ``weight`` (or on one rank) it is ``dolfinx.mesh.create_rectangle``. With it, the
    same mesh's cells go to the ranks by :func:`bisection` of ``weight(centroids)``
    (``shape=(3, m)`` -> ``(m,)``, e.g. the particles a cell will hold; called on rank 0 only)
    along ``axes``; the partition is then the same in every run.

    Raises:
        ValueError: on every rank, for a bad weight or a rank left without cells.

    """
    corners = [np.asarray(c, dtype=np.float64) for c in corners]
    diagonal = getattr(dmesh.DiagonalType, diagonal.replace("/", "_"))
    create = lambda comm: dmesh.create_rectangle(  # noqa: E731
        comm, corners, list(n), dmesh.CellType.triangle, diagonal=diagonal
    )
    return _create(comm, create, weight, axes)


def create_box(comm, corners, n, weight: Callable | None = None, axes=None):
    """DOLFINx's box of ``n = (nx, ny, nz)`` cubes of six tetrahedra.

    Partitioned as :func:`create_rectangle` partitions a rectangle.
    """
    corners = [np.asarray(c, dtype=np.float64) for c in corners]
    return _create(
        comm, lambda comm: dmesh.create_box(comm, corners, list(n), dmesh.CellType.tetrahedron), weight, axes
    )


def _create(comm, create: Callable, weight: Callable | None, axes):
    """The mesh ``create(comm)``, its cells dealt to the ranks by :func:`bisection` of ``weight``."""
    if weight is None or comm.size == 1:
        return create(comm)
    cells, dest, error = None, None, None
    if comm.rank == 0:
        serial = create(MPI.COMM_SELF)
        gdim = serial.geometry.dim
        cells, x = compat.geometry_dofmap(serial).astype(np.int64), serial.geometry.x[:, :gdim].copy()
        centroids = np.zeros((3, len(cells)))
        centroids[:gdim] = x[cells].mean(axis=1).T
        try:
            w = np.asarray(weight(centroids), dtype=np.float64)
            part = bisection(centroids[:gdim].T, w, comm.size, axes)
            if np.bincount(part, minlength=comm.size).min() == 0:
                raise ValueError(f"axes={axes}: {comm.size} ranks cannot all get cells of these {len(cells)}")
            dest = destinations(cells, part)
        except ValueError as e:
            error = str(e)
    error, gdim = comm.bcast((error, gdim if comm.rank == 0 else None), root=0)
    if error:
        raise ValueError(error)
    if comm.rank != 0:
        cells, x = np.zeros((0, gdim + 1), np.int64), np.zeros((0, gdim))
    return compat.create_mesh(comm, cells, x, dest)
