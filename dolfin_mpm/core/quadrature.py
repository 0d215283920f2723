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

import ctypes
from pathlib import Path

import numpy as np

from dolfin_mpm import native
from dolfin_mpm.core.grid import Grid
from dolfin_mpm.core.locate import Basis
from dolfin_mpm.core.volumetric import nodal_volume

__all__ = ["FULL", "cell_weights"]

_INT, _REAL, _I64 = native.array(np.int32), native.array(np.float64), native.array(np.int64)
_kernels = native.kernels(
    Path(__file__).with_suffix(".c"),
    {
        "quadrature_sums": (ctypes.c_int64, _I64, _REAL, ctypes.c_int64, ctypes.c_int64, ctypes.c_int32,
                            _INT, _REAL, _REAL, _REAL),
        "quadrature_weights": (ctypes.c_int64, ctypes.c_int32, _INT, _I64, _REAL, _REAL, _REAL, _REAL,
                               ctypes.c_double, _REAL),
    },
)  # fmt: skip

#: Nodal volume fraction from which a node's patch counts as full: in a filled region the
#: points' 0.5 to 1.5 of a triangle's area average to about 0.8-1.2 over a patch; a node whose
#: patch a surface cuts sees the part filled.
FULL = 0.75


def cell_weights(
    grid: Grid, basis: Basis, cells: np.ndarray, volume: np.ndarray, lumped: np.ndarray | None = None
) -> np.ndarray:
    """Factor of each particle's volume in ``R``, ``shape=(n,)``.

    ``A_e / sum_(p in e) V_p`` in the cells whose nodes are all full, 1 elsewhere. Collective.

    Args:
        cells: each particle's local cell, ``shape=(n,)``.
        volume: particle volumes [m^3], ``shape=(n,)``.
        lumped: :func:`~dolfin_mpm.core.volumetric.nodal_volume` of ``volume`` (computed when
            not given).

    """
    if lumped is None:
        lumped = nodal_volume(grid, basis, volume)
    n, nn = len(volume), basis.dofs.shape[0]
    cells = np.ascontiguousarray(cells, dtype=np.int64)
    volume = np.ascontiguousarray(volume, dtype=np.float64)
    total, patch = np.zeros(grid.num_cells), np.zeros(basis.num_nodes)
    k = _kernels()
    k.quadrature_sums(n, cells, volume, grid.num_cells, grid.num_owned_cells, nn, grid.cell_dofs_T,
                      grid.cell_volume, total, patch)  # fmt: skip
    # int N_i over the cells that hold points: a wall's or a free surface's far side is no void
    patch = grid.assemble(grid.scratch, patch)
    w = np.empty(n)
    k.quadrature_weights(n, nn, basis.dofs, cells, lumped, patch, total, grid.cell_volume, FULL, w)
    return w
