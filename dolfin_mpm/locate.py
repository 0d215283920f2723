"""Particle location in the background mesh and P1 basis values and gradients at particles."""

from dataclasses import dataclass

import numpy as np

from dolfin_mpm import compat
from dolfin_mpm.grid import Grid

__all__ = ["Basis", "barycentric", "basis_at", "locate"]

#: A point counts as inside a cell when all its barycentric coordinates are >= -TOL.
TOL = 1e-12


@dataclass
class Basis:
    """P1 basis at the particles, computed once per step and used by every stage.

    Attributes:
        dofs: nodes of each particle's cell, ``shape=(n, gdim + 1)``.
        N: basis values, ``shape=(n, gdim + 1)``.
        dN: basis gradients [1/m], ``shape=(n, gdim + 1, gdim)``.
    """

    dofs: np.ndarray
    N: np.ndarray
    dN: np.ndarray


def barycentric(grid: Grid, x: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Barycentric coordinates of points ``x`` (``(n, 3)``) in ``cells``, ``shape=(n, gdim+1)``."""
    xi = np.einsum("nij,nj->ni", grid.K[cells], x[:, : grid.gdim] - grid.x0[cells])
    return np.concatenate([1.0 - xi.sum(axis=1, keepdims=True), xi], axis=1)


def locate(grid: Grid, x: np.ndarray, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Find the cell of each point, trying its previous cell first.

    Args:
        grid: the background grid.
        x: points, ``shape=(n, 3)``.
        cells: previous cells (``-1`` where unknown), ``shape=(n,)``.

    Returns:
        ``(cells, N)``: the cell of each point (``-1`` if outside the local mesh) and the
        barycentric coordinates there (the P1 basis values; undefined where ``cells == -1``).
    """
    n = x.shape[0]
    cells = cells.astype(np.int32, copy=True)
    N = np.empty((n, grid.gdim + 1))
    known = cells >= 0
    N[known] = barycentric(grid, x[known], cells[known])
    inside = known.copy()
    inside[known] = N[known].min(axis=1) >= -TOL
    search = np.flatnonzero(~inside)
    cells[search] = -1
    if search.size:
        offsets, candidates = compat.candidate_cells(grid.tree, x[search])
        counts = np.diff(offsets)
        owner = np.repeat(np.arange(search.size), counts)
        lam = barycentric(grid, x[search][owner], candidates)
        score = lam.min(axis=1)
        # Per point, the candidate with the largest smallest barycentric coordinate.
        order = np.lexsort((-score, owner))
        first = order[np.r_[0, np.flatnonzero(np.diff(owner[order])) + 1]] if order.size else order
        found = first[score[first] >= -TOL]
        cells[search[owner[found]]] = candidates[found]
        N[search[owner[found]]] = lam[found]
    return cells, N


def basis_at(grid: Grid, cells: np.ndarray, N: np.ndarray) -> Basis:
    """Gather the nodes and the (cell-constant) basis gradients of located particles."""
    return Basis(dofs=grid.cell_dofs[cells], N=N, dN=grid.grad_N[cells])
