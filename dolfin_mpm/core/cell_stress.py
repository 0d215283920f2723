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

import numpy as np

__all__ = ["cell_mean_stress"]


def cell_mean_stress(
    sigma: np.ndarray, volume: np.ndarray, cells: np.ndarray, material: np.ndarray, num_cells: int,
    keep: np.ndarray | None = None,
) -> np.ndarray:  # fmt: skip
    """The volume-weighted mean stress of each particle's (cell, material) group.

    Args:
        sigma: stresses [Pa], ``shape=(n, 3, 3)``.
        volume: particle volumes, the weights, ``shape=(n,)``.
        cells: each particle's local cell, in ``[0, num_cells)``, ``shape=(n,)``.
        material: each particle's material index, ``shape=(n,)``.
        keep: points left as they are and out of the means (e.g. apart, stress free),
            ``shape=(n,)`` bool; ``None``: none.

    Returns:
        A new array, ``shape=(n, 3, 3)``.

    """
    n = len(volume)
    if n == 0:
        return sigma.copy()
    groups = int(material.max()) + 1
    key = cells.astype(np.int64) * groups + material
    w = volume if keep is None else np.where(keep, 0.0, volume)
    size = num_cells * groups
    total = np.bincount(key, w, size)
    flat = sigma.reshape(n, 9)
    mean = np.empty((n, 9))
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = np.where(total > 0.0, 1.0 / total, 0.0)
        for j in range(9):
            mean[:, j] = (np.bincount(key, w * flat[:, j], size) * inv)[key]
    if keep is not None:
        mean[keep] = flat[keep]
    return mean.reshape(n, 3, 3)
