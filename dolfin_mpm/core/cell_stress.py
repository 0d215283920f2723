"""Each particle's stress replaced by its cell's mean: the part of the stresses P1 forces see.

On P1 simplices the basis gradients are constant in a cell, so the internal force
``R_i = sum_p V_p sigma_p grad N_i`` depends on the stresses only through each cell's
volume-weighted sum. The differences between the points of one cell are in the null space of
``R``: nothing in the discrete equations acts on them, and they build up from the points'
different histories (cells crossed, the apex reached) into noise that the grid never sees.
Replacing every stress by the volume-weighted mean of its cell's points of the same material
removes that part alone: ``R`` is unchanged to round-off, and the mean of states inside a
convex yield surface (the Drucker-Prager cone) is inside it.
"""

import ctypes
from pathlib import Path

import numpy as np

from dolfin_mpm import native
from dolfin_mpm.materials.tensor import component_first, particle_first

__all__ = ["cell_mean_stress"]

_REAL, _INDEX = native.array(np.float64), native.array(np.int32)
_kernels = native.kernels(
    Path(__file__).with_suffix(".c"),
    {"cell_mean": (ctypes.c_int64, ctypes.c_int64, ctypes.c_int32, _INDEX, _INDEX, *[_REAL] * 5)},
)


def cell_mean_stress(
    sigma: np.ndarray, volume: np.ndarray, cells: np.ndarray, material: np.ndarray, num_cells: int,
    keep: np.ndarray | None = None, in_place: bool = False,
) -> np.ndarray:  # fmt: skip
    """The volume-weighted mean stress of each particle's (cell, material) group.

    Args:
        sigma: stresses [Pa], ``shape=(n, 3, 3)``, symmetric (the upper triangle is read).
        volume: particle volumes, the weights, ``shape=(n,)``.
        cells: each particle's local cell, in ``[0, num_cells)``, ``shape=(n,)``.
        material: each particle's material index, ``shape=(n,)``.
        keep: points left as they are and out of the means (e.g. apart, stress free),
            ``shape=(n,)`` bool; ``None``: none.
        in_place: write the means into ``sigma`` where it is component-first memory (the step's
            stresses are): no new array of 72 bytes a particle to fill.

    Returns:
        ``shape=(n, 3, 3)``, a particle-first view of component-first memory: a new array, or
        ``sigma`` itself.

    """
    n = len(volume)
    sigma = component_first(np.asarray(sigma, dtype=np.float64))  # (3, 3, n); no copy if already so
    out = sigma if in_place else np.empty_like(sigma)
    if n == 0:
        return particle_first(out)
    groups = int(material.max()) + 1
    w = np.ascontiguousarray(volume if keep is None else np.where(keep, 0.0, volume), dtype=np.float64)
    size = num_cells * groups
    cells, material = (np.ascontiguousarray(a, dtype=np.int32) for a in (cells, material))
    total, sums = np.zeros(size), np.zeros(6 * size)  # scratch
    _kernels().cell_mean(n, num_cells, groups, cells, material, w, sigma, out, total, sums)
    return particle_first(out)
