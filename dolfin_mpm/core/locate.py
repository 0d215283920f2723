"""Particle location in the background mesh and P1 basis values and gradients at particles.

For speed the basis arrays are component-first (particle axis last): each component is one
contiguous array over the particles.
"""

from dataclasses import dataclass

import numpy as np

from dolfin_mpm.core import compat
from dolfin_mpm.core.grid import Grid

__all__ = ["Basis", "barycentric", "basis_at", "locate"]

#: A point counts as inside a cell when all its barycentric coordinates are >= -TOL.
TOL = 1e-12


@dataclass
class Basis:
    """P1 basis at the particles, computed once per step and used by every stage.

    C-contiguous arrays, read by the compiled transfers.

    Attributes:
        dofs: nodes of each particle's cell, ``shape=(gdim + 1, n)``.
        N: basis values, ``shape=(gdim + 1, n)``.
        dN: basis gradients [1/m], ``shape=(gdim + 1, gdim, n)``.
        num_nodes: nodes of the grid (owned and ghosts).

    """

    dofs: np.ndarray
    N: np.ndarray
    dN: np.ndarray
    num_nodes: int


def barycentric(grid: Grid, x: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Barycentric coordinates of points ``x`` (``(n, 3)``) in ``cells``, ``shape=(gdim+1, n)``."""
    g = grid.gdim
    dx = [x[:, j] - grid.x0_T[j].take(cells) for j in range(g)]
    lam = np.empty((g + 1, len(cells)))
    for i in range(g):
        lam[i + 1] = sum(grid.K[i, j].take(cells) * dx[j] for j in range(g))
    lam[0] = 1.0 - lam[1:].sum(axis=0)
    return lam


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
    known = cells >= 0
    cells = np.where(known, cells, 0).astype(np.int32)
    N = barycentric(grid, x, cells)
    inside = (N.min(axis=0) >= -TOL) & known
    search = np.flatnonzero(~inside)
    cells[search] = -1
    if search.size:
        offsets, candidates = compat.candidate_cells(grid.tree, x[search])
        owner = np.repeat(np.arange(search.size), np.diff(offsets))
        lam = barycentric(grid, x[search][owner], candidates)
        score = lam.min(axis=0)
        # Per point, the candidate with the largest smallest barycentric coordinate.
        order = np.lexsort((-score, owner))
        first = order[np.r_[0, np.flatnonzero(np.diff(owner[order])) + 1]] if order.size else order
        found = first[score[first] >= -TOL]
        cells[search[owner[found]]] = candidates[found]
        N[:, search[owner[found]]] = lam[:, found]
    return cells, N


def basis_at(grid: Grid, cells: np.ndarray, N: np.ndarray) -> Basis:
    """Gather the nodes and the (cell-constant) basis gradients of located particles."""
    dofs = grid.cell_dofs_T.take(cells, axis=1)
    dN = grid.grad_N.take(cells, axis=2)
    return Basis(dofs=dofs, N=np.ascontiguousarray(N), dN=dN, num_nodes=grid.num_nodes)
