"""The volumetric strain rate averaged over the nodes' patches: linear simplices without locking.

Isochoric flow (``g = q``) on P1 triangles and tetrahedra locks: a velocity field that keeps
every cell's volume has too few degrees of freedom, the flow is too stiff and the pressure
checkers. The remedy of the average nodal pressure / nodal B-bar family (Bonet & Burton 1998;
for MPM, Coombs et al. 2018 and the volumetric smoothing of CB-Geo) takes the volumetric part
of the rate of deformation from the nodes instead of the cell: the particles' ``tr L`` is
projected onto the P1 nodes (volume-weighted, lumped) and interpolated back, which leaves one
volume constraint per node instead of one per cell.
"""

import numpy as np

from dolfin_mpm.core.grid import Grid
from dolfin_mpm.core.locate import Basis
from dolfin_mpm.core.transfer import interpolate, scatter

__all__ = ["nodal_volumetric"]


def nodal_volumetric(grid: Grid, basis: Basis, L: np.ndarray, volume: np.ndarray) -> np.ndarray:
    """``L`` with its volumetric part replaced by the nodal average of ``tr L``.

    Args:
        L: velocity gradients [1/s], ``shape=(n, gdim, gdim)``; changed in place and returned.
        volume: particle volumes, the weights of the average, ``shape=(n,)``.

    Returns:
        ``L + (tr_bar - tr L) / gdim * I``, where ``tr_bar = sum_i N_i(x_p) <tr L>_i`` and
        ``<tr L>_i = sum_p N_i V_p tr L_p / sum_p N_i V_p``.

    """
    g = grid.gdim
    tr = np.einsum("pii->p", L)
    weight = grid.assemble(grid.scratch, scatter(basis, volume)).copy()
    total = grid.assemble(grid.scratch, scatter(basis, volume * tr))
    with np.errstate(divide="ignore", invalid="ignore"):
        tr_node = np.where(weight > 0.0, total / weight, 0.0)
    delta = (interpolate(basis, tr_node[:, None])[:, 0] - tr) / g
    for i in range(g):
        L[:, i, i] += delta
    return L
