"""Von Mises plasticity with linear isotropic hardening (radial return).

    f = q - (sigma_y + H eps_p),   q = sqrt(3/2 s:s),   associated flow along s

``eps_p = sqrt(2/3 e_p:e_p)`` is the accumulated equivalent plastic strain in its conventional
measure (the state); the increment of the protocol is the paper's norm of the same strain,
``de = sqrt(3/2 de_p:de_p) = 3/2 d eps_p``, so that ``q = q_trial - 2 G de = q_trial - 3 G
d eps_p``. The return is closed form, ``d eps_p = (q_trial - sigma_y - H eps_p) / (3 G + H)``,
exact for any step; its consistent tangent serves the implicit FE solver.
"""

from dataclasses import dataclass

import numpy as np

from dolfin_mpm.materials.base import Trial
from dolfin_mpm.materials.radial_return import RadialReturn, applied_increment
from dolfin_mpm.params import parameter

__all__ = ["VonMises"]


@dataclass(frozen=True)
class VonMises(RadialReturn):
    """Hypo-elastic, rate-independent von Mises solid.

    Args:
        E, nu, rho: elasticity and density, as for :class:`LinearElastic`.
        sigma_y: initial yield stress in uniaxial tension [Pa], > 0.
        H: linear isotropic hardening modulus [Pa], >= 0 (0: perfectly plastic).

    """

    sigma_y: float = parameter(0.0, np.inf, "Pa")
    H: float = parameter(0.0, np.inf, "Pa", closed=(True, False), default=0.0)

    def state_fields(self):
        return {"eps_p": ()}  # accumulated equivalent plastic strain sqrt(2/3 e_p:e_p) [-]

    def increment(self, trial: Trial, state: dict[str, np.ndarray], dt: float) -> np.ndarray:
        """Plastic strain increment ``de`` [-] (paper's norm) of the return, ``shape=(n,)``, >= 0.

        Reads the hardening from ``state["eps_p"]``; ``dt`` is not needed.
        """
        overstress = trial.q - (self.sigma_y + self.H * state["eps_p"])
        return 1.5 * np.maximum(overstress, 0.0) / (3.0 * self.G + self.H)

    def record(self, state, de, de_nonlocal, dt, applied=None):
        """Accumulate ``eps_p += 2/3 applied`` (the conventional measure)."""
        state["eps_p"][:] += (2.0 / 3.0) * applied_increment(de, de_nonlocal, applied)

    def tangent(self, trial: Trial, de: np.ndarray, dt: float) -> np.ndarray:
        """Consistent tangent of the return [Pa] (Mandel), ``shape=(n, 6, 6)``."""
        dq_dqtrial = np.where(de > 0.0, self.H / (3.0 * self.G + self.H), 1.0)
        q = np.maximum(trial.q - 2.0 * self.G * de, 0.0)
        return self.radial_tangent(trial, q, dq_dqtrial, np.zeros_like(q))
