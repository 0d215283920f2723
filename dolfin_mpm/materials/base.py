"""The interface every constitutive model implements."""

from abc import ABC, abstractmethod

import numpy as np

__all__ = ["Material", "check_range"]


def check_range(name: str, value: float, low: float, high: float, *, closed=(False, False)) -> None:
    """Raise ``ValueError`` naming ``name`` unless ``value`` lies in the given interval."""
    lo_ok = value >= low if closed[0] else value > low
    hi_ok = value <= high if closed[1] else value < high
    if not (lo_ok and hi_ok):  # also catches NaN
        interval = ("[" if closed[0] else "(") + f"{low:g}, {high:g}" + ("]" if closed[1] else ")")
        raise ValueError(f"{name} must be in {interval}, got {value!r}")


class Material(ABC):
    """A constitutive model: parameters fixed at construction, a vectorised stress update.

    Materials know nothing of meshes, DOLFINx or PETSc: arrays in, arrays out.
    """

    rho: float  # mass density [kg/m^3]

    @abstractmethod
    def p_wave_speed(self) -> float:
        """Speed of elastic dilatational waves [m/s], for the explicit time step."""

    def state_fields(self) -> dict[str, tuple[int, ...]]:
        """Per-particle state arrays this material needs: name -> shape after the particle axis."""
        return {}

    @abstractmethod
    def update(self, sigma: np.ndarray, L: np.ndarray, dt: float, state: dict[str, np.ndarray]) -> np.ndarray:
        """Advance the stress over one step.

        Args:
            sigma: Cauchy stress at the start of the step [Pa], ``shape=(n, 3, 3)``.
            L: velocity gradient ``L_ij = dv_i/dx_j`` [1/s], ``shape=(n, gdim, gdim)``: rate of
                deformation ``d = sym L``, spin ``W = skew L`` (plane strain in 2D).
            dt: time step [s].
            state: this material's state arrays (updated in place), particle axis first.

        Returns:
            The stress at the end of the step, ``shape=(n, 3, 3)``.

        """

    @abstractmethod
    def strain_energy_density(self, sigma: np.ndarray) -> np.ndarray:
        """Recoverable elastic energy per unit volume [J/m^3] at stress ``sigma``, ``shape=(n,)``."""
