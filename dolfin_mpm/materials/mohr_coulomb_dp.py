"""Rate-independent Drucker–Prager matched to Mohr–Coulomb in plane strain, with dilatancy.

    f = q - M (p + c cot(phi)),   g = q - M_g p

A perfectly plastic cone whose plane-strain collapse loads are those of Mohr–Coulomb with
friction angle ``phi``, cohesion ``c`` and dilatancy angle ``psi`` (``psi = phi``: associated;
``psi = 0``: plastically incompressible, the flow rule of the paper's ``g = q``).

The match. In ``sqrt(J2) = alpha I1' + k`` form (``I1' = 3 p``, compression positive) with the
potential ``sqrt(J2) - alpha_g I1'``, plastic flow in plane strain needs ``de_zz^p = 0``, i.e.
``s_zz = -2 alpha_g sqrt(J2)`` (tension positive). With ``t = (sigma_1 - sigma_3) / 2`` and
``s = -(sigma_1 + sigma_3) / 2`` the in-plane radius and centre of Mohr's circle this gives
``J2 = t^2 / (1 - 3 alpha_g^2)`` and ``I1' = 3 s + 3 alpha_g t / sqrt(1 - 3 alpha_g^2)``, so
the cone reads ``t (1 - 3 alpha alpha_g) / sqrt(1 - 3 alpha_g^2) = 3 alpha s + k``. Equal to
Mohr–Coulomb, ``t = s sin(phi) + c cos(phi)``, and with the potential dilating like Mohr–
Coulomb's (``alpha_g = sin(psi) / sqrt(9 + 3 sin^2 psi)``):

    alpha = sin(phi) / (3 (sqrt(1 - 3 alpha_g^2) + alpha_g sin(phi))),   k = 3 alpha c cot(phi),

and in ``q``-``p`` form ``M = 3 sqrt(3) alpha``, ``M_g = 3 sqrt(3) alpha_g``. Associated
(``psi = phi``): ``alpha = tan(phi) / sqrt(9 + 12 tan^2 phi)``, ``M = 0.832`` at 30 deg;
``psi = 0``: ``M = sqrt(3) sin(phi)`` (0.866). The apex stays at ``p = -c cot(phi)``.

The return (closed form, exact for any step): on the cone
``dlam = f_trial / (3 G + K M M_g)``, ``q = q_trial - 3 G dlam``, ``p = p_trial + K M_g dlam``;
where that would give ``q < 0``, i.e. ``p_trial + c cot(phi) < -K M_g q_trial / (3 G)``, the
stress returns to the apex, ``sigma = c cot(phi) I``, where the consistent tangent is zero.
For ``psi = 0`` this is the rate-independent :class:`DruckerPragerViscoplastic` with slope
``M`` in place of its ``m``, apex included.
"""

from dataclasses import dataclass

import numpy as np

from dolfin_mpm.materials.base import check_range
from dolfin_mpm.materials.radial_return import IsochoricPlastic, Trial
from dolfin_mpm.materials.tensor import particle_first, to_mandel

__all__ = ["MohrCoulombDruckerPrager"]

_ONE = np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])


@dataclass(frozen=True)
class MohrCoulombDruckerPrager(IsochoricPlastic):
    """Perfectly plastic Drucker–Prager cone matched to Mohr–Coulomb in plane strain.

    Args:
        E, nu, rho: elasticity and density, as for :class:`LinearElastic`.
        phi: angle of internal friction [degrees], in (0, 90).
        c: cohesion [Pa], >= 0.
        psi: dilatancy angle [degrees], in [0, phi]; ``None`` is ``phi`` (associated flow).

    """

    phi: float
    c: float = 0.0
    psi: float | None = None

    def __post_init__(self):
        super().__post_init__()
        check_range("phi", self.phi, 0.0, 90.0)
        check_range("c", self.c, 0.0, np.inf, closed=(True, False))
        if self.psi is not None:
            check_range("psi", self.psi, 0.0, self.phi, closed=(True, True))

    @property
    def M_g(self) -> float:
        """Slope of the plastic potential ``g = q - M_g p`` (0: isochoric flow)."""
        s = np.sin(np.radians(self.phi if self.psi is None else self.psi))
        return 3.0 * np.sqrt(3.0) * s / np.sqrt(9.0 + 3.0 * s * s)

    @property
    def M(self) -> float:
        """Slope of the cone ``q = M (p + c cot(phi))``, the plane-strain match for ``psi``."""
        s, alpha_g = np.sin(np.radians(self.phi)), self.M_g / (3.0 * np.sqrt(3.0))
        return np.sqrt(3.0) * s / (np.sqrt(1.0 - 3.0 * alpha_g**2) + alpha_g * s)

    @property
    def tension_limit(self) -> float:
        """``c cot(phi)`` [Pa]: the cone's apex is at ``p = -c cot(phi)``."""
        return self.c / np.tan(np.radians(self.phi))

    def state_fields(self):
        return {"eps_p": ()}  # accumulated plastic multiplier, sqrt(2/3 e_p:e_p) of the deviator [-]

    def increment(self, trial: Trial) -> np.ndarray:
        """Plastic multiplier ``dlam`` of the return (``inf`` marks the apex), ``shape=(n,)``."""
        pt = trial.p + self.tension_limit
        dlam = np.maximum(trial.q - self.M * pt, 0.0) / (3.0 * self.G + self.K * self.M * self.M_g)
        dlam[3.0 * self.G * pt < -self.K * self.M_g * trial.q] = np.inf
        return dlam

    def stress(self, trial: Trial, dlam: np.ndarray) -> np.ndarray:
        """Stress after the return, ``shape=(n, 3, 3)``."""
        apex = np.isinf(dlam)
        d = np.where(apex, 0.0, dlam)
        q = np.where(apex, 0.0, trial.q - 3.0 * self.G * d)
        p = np.where(apex, -self.tension_limit, trial.p + self.K * self.M_g * d)
        return self.radial_stress(trial, q, p)

    def tangent(self, trial: Trial, dlam: np.ndarray) -> np.ndarray:
        """Consistent tangent of the return (Mandel), ``shape=(n, 6, 6)`` [Pa]; zero at the apex."""
        K, G, M, M_g = self.K, self.G, self.M, self.M_g
        H = 3.0 * G + K * M * M_g
        act = (dlam > 0.0) & np.isfinite(dlam)
        q = np.where(act, trial.q - 3.0 * G * np.where(act, dlam, 0.0), trial.q)
        dq_dqtrial = np.where(act, 1.0 - 3.0 * G / H, 1.0)
        dq_dp = np.where(act, 3.0 * G * M / H, 0.0)
        D = self.radial_tangent(trial, q, dq_dqtrial, dq_dp)
        if M_g > 0.0:  # the pressure moves too: dp = dp_trial + K M_g d(dlam)
            norm = np.sqrt(2.0 / 3.0) * trial.q
            n = to_mandel(particle_first(trial.s))[act] / norm[act, None]
            dlam_deps = (np.sqrt(6.0) * G * n + M * K * _ONE) / H
            D[act] -= K * M_g * _ONE[None, :, None] * dlam_deps[:, None, :]
        D[np.isinf(dlam)] = 0.0
        return D

    def small_strain_update(self, sigma, deps, state):
        """Implicit small-strain step from ``sigma`` by the strain increment ``deps`` (n, 3, 3).

        Returns the stress, the consistent tangent (Mandel, ``shape=(n, 6, 6)``) and the new
        state, leaving ``state`` untouched.
        """
        trial = self.trial(sigma, deps, 1.0)
        dlam = self.increment(trial)
        new = {"eps_p": state["eps_p"] + self._applied(trial, dlam)}
        return self.stress(trial, dlam), self.tangent(trial, dlam), new

    def update(self, sigma, L, dt, state):
        trial = self.trial(sigma, L, dt)
        dlam = self.increment(trial)
        state["eps_p"][:] += self._applied(trial, dlam)
        return self.stress(trial, dlam)

    def _applied(self, trial: Trial, dlam: np.ndarray) -> np.ndarray:
        """Deviatoric plastic strain of the return; ``q_trial / 3G`` at the apex."""
        return np.where(np.isinf(dlam), trial.q / (3.0 * self.G), dlam)
