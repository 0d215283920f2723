"""Von Mises plasticity with linear isotropic hardening (radial return).

    f = q - (sigma_y + H eps_p),   q = sqrt(3/2 s:s),   associated flow along s

``eps_p = sqrt(2/3 e_p:e_p)`` is the accumulated equivalent plastic strain. The return is
closed form, ``eps_p += (q_trial - sigma_y - H eps_p) / (3 G + H)``, exact for any step; its
consistent tangent serves the implicit FE solver.
"""

from dataclasses import dataclass

import numpy as np

from dolfin_mpm.materials.base import check_range
from dolfin_mpm.materials.radial_return import IsochoricPlastic, Trial

__all__ = ["VonMises"]


@dataclass(frozen=True)
class VonMises(IsochoricPlastic):
    """Hypo-elastic, rate-independent von Mises solid.

    Args:
        E, nu, rho: elasticity and density, as for :class:`LinearElastic`.
        sigma_y: initial yield stress in uniaxial tension [Pa], > 0.
        H: linear isotropic hardening modulus [Pa], >= 0 (0: perfectly plastic).

    """

    sigma_y: float
    H: float = 0.0

    def __post_init__(self):
        super().__post_init__()
        check_range("sigma_y", self.sigma_y, 0.0, np.inf)
        check_range("H", self.H, 0.0, np.inf, closed=(True, False))

    def state_fields(self):
        return {"eps_p": ()}  # accumulated equivalent plastic strain [-]

    def increment(self, trial: Trial, eps_p: np.ndarray) -> np.ndarray:
        """Equivalent plastic strain increment of the return, ``shape=(n,)``, >= 0."""
        overstress = trial.q - (self.sigma_y + self.H * eps_p)
        return np.maximum(overstress, 0.0) / (3.0 * self.G + self.H)

    def stress(self, trial: Trial, deps_p: np.ndarray) -> np.ndarray:
        """Stress after the return, ``shape=(n, 3, 3)``."""
        return self.radial_stress(trial, trial.q - 3.0 * self.G * deps_p, trial.p)

    def tangent(self, trial: Trial, deps_p: np.ndarray) -> np.ndarray:
        """Consistent tangent of the return (Mandel), ``shape=(n, 6, 6)`` [Pa]."""
        dq_dqtrial = np.where(deps_p > 0.0, self.H / (3.0 * self.G + self.H), 1.0)
        q = trial.q - 3.0 * self.G * deps_p
        return self.radial_tangent(trial, q, dq_dqtrial, np.zeros_like(q))

    def small_strain_update(self, sigma, deps, state):
        """Implicit small-strain step from ``sigma`` by the strain increment ``deps`` (n, 3, 3).

        Returns the stress, the consistent tangent (Mandel, ``shape=(n, 6, 6)``) and the new
        state, leaving ``state`` untouched.
        """
        trial = self.trial(sigma, deps, 1.0)
        deps_p = self.increment(trial, state["eps_p"])
        return self.stress(trial, deps_p), self.tangent(trial, deps_p), {"eps_p": state["eps_p"] + deps_p}

    def update(self, sigma, L, dt, state):
        trial = self.trial(sigma, L, dt)
        deps_p = self.increment(trial, state["eps_p"])
        state["eps_p"][:] += deps_p
        return self.stress(trial, deps_p)
