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
from dolfin_mpm.core.transfer import replace_volumetric, scatter, volumetric_sums
from dolfin_mpm.materials.tensor import component_view, particle_first

__all__ = ["nodal_volume", "nodal_volumetric"]


def nodal_volume(grid: Grid, basis: Basis, volume: np.ndarray) -> np.ndarray:
    """The particles' volume lumped at the nodes, ``sum_p N_i V_p`` (assembled), ``shape=(num_nodes,)``.

    The weights of the nodal average and what the cell quadrature compares with the nodes'
    patches; they hold for a whole step: its iterates move neither the particles nor their volumes.
    """
    return grid.assemble(grid.scratch, scatter(basis, volume)).copy()


def nodal_volumetric(
    grid: Grid, basis: Basis, L: np.ndarray, volume: np.ndarray, weight: np.ndarray | None = None
) -> np.ndarray:
    """``L`` with its volumetric part replaced by the nodal average of ``tr L``.

    Args:
        L: velocity gradients [1/s], ``shape=(n, gdim, gdim)``; changed in place and returned.
        volume: particle volumes, the weights of the average, ``shape=(n,)``.
        weight: :func:`nodal_volume` of ``volume`` (computed when not given).

    Returns:
        ``L + (tr_bar - tr L) / gdim * I``, where ``tr_bar = sum_i N_i(x_p) <tr L>_i`` and
        ``<tr L>_i = sum_p N_i V_p tr L_p / sum_p N_i V_p``.

    """
    if weight is None:
        weight = nodal_volume(grid, basis, volume)
    Lc = component_view(L)  # component-first: what gradient() gives, viewed particle-first
    copied = not Lc.flags.c_contiguous
    if copied:
        Lc = np.ascontiguousarray(Lc)
    tr, sums = volumetric_sums(basis, Lc, volume)
    total = grid.assemble(grid.scratch, sums)
    with np.errstate(divide="ignore", invalid="ignore"):
        tr_node = np.where(weight > 0.0, total / weight, 0.0)
    replace_volumetric(basis, tr_node, tr, Lc)
    if copied:
        L[...] = particle_first(Lc)
    return L
