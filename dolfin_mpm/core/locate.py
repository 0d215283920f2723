"""Particle location in the background mesh and the P1 basis at the particles.

For speed the basis arrays are component-first (particle axis last): each component is one
contiguous array over the particles; the gradients, constant in a cell, stay in the grid's
table by cell. The loops over the particles are compiled C (``locate.c``): the barycentric
coordinates in each particle's previous cell, and the gather of its cell's nodes, one pass each.
"""

import ctypes
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dolfin_mpm import native
from dolfin_mpm.core import compat
from dolfin_mpm.core.grid import Grid

__all__ = ["Basis", "barycentric", "basis_at", "locate"]

#: A point counts as inside a cell when all its barycentric coordinates are >= -TOL.
TOL = 1e-12

_INT, _INDEX, _REAL = ctypes.c_int32, native.array(np.int32), native.array(np.float64)
_kernels = native.kernels(
    Path(__file__).with_suffix(".c"),
    {
        "barycentric": (
            ctypes.c_int64, _INT, _REAL, _INDEX, ctypes.c_int64, _REAL, _REAL, ctypes.c_double, _REAL,
            native.array(np.int8),
        ),
        "gather_nodes": (ctypes.c_int64, _INT, _INDEX, ctypes.c_int64, _INDEX, _INDEX),
    },
)  # fmt: skip


@dataclass
class Basis:
    """P1 basis at the particles, computed once per step and used by every stage.

    C-contiguous arrays, read by the compiled transfers. The gradients are constant in a cell:
    the transfers read them from the grid's table by each particle's cell, not from a copy per
    particle (48 bytes a particle in 2D, written and read back by every pass).

    Attributes:
        cells: each particle's local cell, int32, ``shape=(n,)``.
        dofs: nodes of each particle's cell, int32, ``shape=(gdim + 1, n)``.
        N: basis values, ``shape=(gdim + 1, n)``.
        grad_N: the grid's basis gradients by cell [1/m], ``shape=(num_cells, gdim + 1, gdim)``.
        num_nodes: nodes of the grid (owned and ghosts).

    """

    cells: np.ndarray
    dofs: np.ndarray
    N: np.ndarray
    grad_N: np.ndarray
    num_nodes: int

    @property
    def dN(self) -> np.ndarray:
        """Basis gradients at the particles [1/m], ``shape=(gdim + 1, gdim, n)`` (a new array)."""
        return np.ascontiguousarray(np.moveaxis(self.grad_N[self.cells], 0, -1))


def barycentric(grid: Grid, x: np.ndarray, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Barycentric coordinates of points ``x`` (``(n, 3)``) in ``cells`` (``(n,)``, -1: unknown).

    Returns:
        The coordinates, ``shape=(gdim+1, n)`` (those in cell 0 where the cell is unknown), and
        whether each point lies in its cell (all coordinates ``>= -TOL``), ``shape=(n,)``.

    """
    n = len(cells)
    x, cells = np.ascontiguousarray(x, dtype=np.float64).reshape(n, 3), np.ascontiguousarray(cells, np.int32)
    lam, inside = np.empty((grid.gdim + 1, n)), np.empty(n, dtype=np.int8)
    _kernels().barycentric(n, grid.gdim, x, cells, grid.num_cells, grid.x0_T, grid.K, TOL, lam, inside)
    return lam, inside.view(bool)


def locate(grid: Grid, x: np.ndarray, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Find the cell of each point, trying its previous cell first.

    Args:
        grid: the background grid.
        x: points, ``shape=(n, 3)``.
        cells: previous cells (``-1`` where unknown), ``shape=(n,)``.

    Returns:
        ``(cells, N)``: the cell of each point (``-1`` if outside the local mesh) and the
        barycentric coordinates there, ``shape=(gdim+1, n)`` (the P1 basis values;
        undefined where ``cells == -1``).

    """
    cells = np.array(cells, dtype=np.int32)
    N, inside = barycentric(grid, x, cells)
    search = np.flatnonzero(~inside)
    cells[search] = -1
    if search.size:
        offsets, candidates = compat.candidate_cells(grid.tree, x[search])
        owner = np.repeat(np.arange(search.size), np.diff(offsets))
        lam, _ = barycentric(grid, x[search][owner], candidates)
        score = lam.min(axis=0)
        # Per point, the candidate with the largest smallest barycentric coordinate.
        order = np.lexsort((-score, owner))
        first = order[np.r_[0, np.flatnonzero(np.diff(owner[order])) + 1]] if order.size else order
        found = first[score[first] >= -TOL]
        cells[search[owner[found]]] = candidates[found]
        N[:, search[owner[found]]] = lam[:, found]
    return cells, N


def basis_at(grid: Grid, cells: np.ndarray, N: np.ndarray) -> Basis:
    """Gather the nodes of located particles' cells; the basis of them and of ``N``."""
    n, g = len(cells), grid.gdim
    dofs = np.empty((g + 1, n), dtype=np.int32)
    cells = np.ascontiguousarray(cells, dtype=np.int32)
    _kernels().gather_nodes(n, g, cells, grid.num_cells, grid.cell_dofs_T, dofs)
    return Basis(cells, dofs, np.ascontiguousarray(N), grid.grad_N, grid.num_nodes)
