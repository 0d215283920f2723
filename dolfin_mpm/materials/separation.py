"""Separation and re-compaction of granular material (Dunatunga & Kamrin, JFM 779, 2015).

A granular point whose density would fall below its critical density ``rho_c`` has lost
contact with its neighbours: it carries no stress, and what it gains in volume is void between
the grains, not material. Its volume stays at ``m / rho_c``, the loosest state in which it is
in contact, and the rest is kept as its free volume; compressed again, the free volume closes
first, and the point carries stress once it is gone. So a point that flew apart neither
inflates (the force it gives on return, ``V sigma``, would be its inflation times too large)
nor carries stress before it touches again.
"""

import numpy as np

__all__ = ["separate"]


def separate(volume: np.ndarray, free_volume: np.ndarray, J: np.ndarray, critical_volume) -> tuple:
    """Volume in contact and free volume after a step of volume ratio ``J = det(I + dt L)``.

    Args:
        volume: volume of material at the start of the step [m^3], ``shape=(n,)``.
        free_volume: void gained beyond ``critical_volume`` [m^3], ``shape=(n,)``, >= 0.
        J: volume ratio of the step [-], ``shape=(n,)``.
        critical_volume: ``m / rho_c`` [m^3], a number or ``shape=(n,)``; ``inf``: never apart.

    Returns:
        The volume ``min((V + V_free) J, m / rho_c)`` and the free volume, the rest; a point
        is apart (stress free) where its free volume is positive.

    """
    total = (volume + free_volume) * J
    volume = np.minimum(total, critical_volume)
    return volume, total - volume
