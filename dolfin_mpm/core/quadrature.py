"""Where the material fills a cell, its internal force integrated over the cell, not the points.

MPM integrates ``R_i = int sigma : grad N_i`` by the points: ``sum_p V_p sigma_p grad N_i``. On
P1 simplices ``grad N_i`` is constant in a cell, so a cell contributes ``(sum_p V_p) sigma_e``
with ``sigma_e`` the volume-weighted mean stress of its points. Cell crossing leaves 2 to 6 of
4 seeded points in a triangle, so ``sum_p V_p`` is 0.5 to 1.5 times the area of a cell the
material fills, and a cell its points left must carry its neighbours' load with more stress
(``docs/numerics.md``). With ``quadrature = "cell"`` a cell
inside the material, one whose nodes all have full patches, is integrated over its area: its
points act with ``A_e / sum_p V_p`` times their volumes. A node's patch is full when its
volume fraction ``phi_i = sum_p N_i(x_p) V_p / int N_i`` is at least ``FULL``, the integral
taken over the cells that hold points (so that a wall or an empty cell beyond a free surface
on a mesh line is not counted as void). Cells that the material fills only in part keep the
points' quadrature, which follows the material there.
"""

import numpy as np

from dolfin_mpm.core.grid import Grid
from dolfin_mpm.core.locate import Basis
from dolfin_mpm.core.transfer import scatter

__all__ = ["FULL", "cell_weights"]

#: Nodal volume fraction from which a node's patch counts as full: in a filled region the
#: points' 0.5 to 1.5 of a triangle's area average to about 0.8-1.2 over a patch; a node whose
#: patch a surface cuts sees the part filled.
FULL = 0.75


def cell_weights(grid: Grid, basis: Basis, cells: np.ndarray, volume: np.ndarray) -> np.ndarray:
    """Factor of each particle's volume in ``R``, ``shape=(n,)``.

    ``A_e / sum_(p in e) V_p`` in the cells whose nodes are all full, 1 elsewhere.

    Args:
        cells: each particle's local cell, ``shape=(n,)``.
        volume: particle volumes [m^3], ``shape=(n,)``.

    """
    total = np.bincount(cells, volume, minlength=grid.num_cells)
    # int N_i over the cells that hold points: a wall's or a free surface's far side is no void
    owned = np.flatnonzero(total[: grid.num_owned_cells] > 0.0)
    d = grid.tdim + 1
    share = np.repeat(grid.cell_volume[owned] / d, d)
    patch = np.bincount(grid.cell_dofs[owned].ravel(), share, minlength=grid.num_nodes)
    patch = grid.assemble(grid.scratch, patch).copy()
    sums = grid.assemble(grid.scratch, scatter(basis, volume))
    phi = np.divide(sums, patch, out=np.zeros_like(patch), where=patch > 0.0)
    inside = phi[basis.dofs].min(axis=0) >= FULL
    return np.where(inside, grid.cell_volume[cells] / total[cells], 1.0)
