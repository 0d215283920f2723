"""Linear hypo-elasticity with the Zaremba–Jaumann stress rate."""

from dataclasses import dataclass

import numpy as np

from dolfin_mpm.materials.base import Material, check_range
from dolfin_mpm.tensor import component_first, deviator, jaumann_rotate, particle_first

__all__ = ["LinearElastic"]


@dataclass(frozen=True)
class LinearElastic(Material):
    """Isotropic hypo-elastic solid, ``sigma^J = K tr(d) I + 2 G dev(d)``.

    Args:
        E: Young's modulus [Pa], > 0.
        nu: Poisson's ratio, in (-1, 0.5).
        rho: mass density [kg/m^3], > 0.

    """

    E: float
    nu: float
    rho: float

    def __post_init__(self):
        check_range("E", self.E, 0.0, np.inf)
        check_range("nu", self.nu, -1.0, 0.5)
        check_range("rho", self.rho, 0.0, np.inf)

    @property
    def K(self) -> float:
        """Bulk modulus [Pa]."""
        return self.E / (3.0 * (1.0 - 2.0 * self.nu))

    @property
    def G(self) -> float:
        """Shear modulus [Pa]."""
        return self.E / (2.0 * (1.0 + self.nu))

    def p_wave_speed(self) -> float:
        return float(np.sqrt((self.K + 4.0 * self.G / 3.0) / self.rho))

    def update(self, sigma, d, W, dt, state):
        sigma = component_first(jaumann_rotate(sigma, W, dt))
        d = component_first(d)
        sigma += (2.0 * self.G * dt) * d
        lam_dt = (self.K - 2.0 * self.G / 3.0) * dt * (d[0, 0] + d[1, 1] + d[2, 2])
        for i in range(3):
            sigma[i, i] += lam_dt
        return particle_first(sigma)

    def strain_energy_density(self, sigma):
        p, s = deviator(sigma)
        s = component_first(s)
        return p**2 / (2.0 * self.K) + (s * s).sum(axis=(0, 1)) / (4.0 * self.G)
