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

The return (closed form, exact for any step): on the cone the plastic multiplier is
``dlam = f_trial / (3 G + K M M_g)``, ``q = q_trial - 3 G dlam``, ``p = p_trial + K M_g dlam``.
``dlam`` is the conventional equivalent plastic strain ``sqrt(2/3 de_p:de_p)`` of the
deviator (the state ``eps_p`` accumulates it); the increment of the protocol is the paper's
norm, ``de = 3/2 dlam``: ``q = q_trial - 2 G de``, ``p = p_trial + 2/3 K M_g de``. Where the
cone return would give ``q < 0``, i.e. ``3 G (p_trial + c cot(phi)) < -K M_g q_trial``
(:meth:`~MohrCoulombDruckerPrager.at_apex`), the stress returns to the apex,
``sigma = c cot(phi) I``, with ``de = q_trial / 2G``; the consistent tangent is zero there.
For ``psi = 0`` this is the rate-independent :class:`DruckerPragerViscoplastic` with slope
``M`` in place of its ``m``, apex included.
"""

from dataclasses import dataclass

import numpy as np

from dolfin_mpm.materials.base import Trial
from dolfin_mpm.materials.radial_return import RadialReturn, applied_increment
from dolfin_mpm.materials.tensor import MANDEL_IDENTITY, particle_first, to_mandel
from dolfin_mpm.params import Range, parameter

__all__ = ["MohrCoulombDruckerPrager"]


@dataclass(frozen=True)
class MohrCoulombDruckerPrager(RadialReturn):
    """Perfectly plastic Drucker–Prager cone matched to Mohr–Coulomb in plane strain.

    Args:
        E, nu, rho: elasticity and density, as for :class:`LinearElastic`.
        phi: angle of internal friction [degrees], in (0, 90).
        c: cohesion [Pa], >= 0.
        psi: dilatancy angle [degrees], in [0, phi]; ``None`` is ``phi`` (associated flow).

    """

    phi: float = parameter(0.0, 90.0, "degrees")
    c: float = parameter(0.0, np.inf, "Pa", closed=(True, False), default=0.0)
    psi: float | None = parameter(0.0, 90.0, "degrees", closed=(True, True), default=None)

    def __post_init__(self):
        super().__post_init__()
        if self.psi is not None:  # the field's range is [0, 90]; the flow may not outdilate phi
            Range(0.0, self.phi, "degrees", closed=(True, True)).check("psi", self.psi)

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

    def at_apex(self, trial: Trial) -> np.ndarray:
        """Points that return to the apex, ``3 G (p_trial + c cot(phi)) < -K M_g q_trial``, ``shape=(n,)``."""
        return 3.0 * self.G * (trial.p + self.tension_limit) < -self.K * self.M_g * trial.q

    def increment(self, trial: Trial, state: dict[str, np.ndarray], dt: float) -> np.ndarray:
        """Plastic strain increment ``de = 3/2 dlam`` [-] (paper's norm), ``shape=(n,)``.

        ``q_trial / 2G`` at the apex; ``state`` and ``dt`` are not needed.
        """
        pt = trial.p + self.tension_limit
        de = 1.5 * np.maximum(trial.q - self.M * pt, 0.0) / (3.0 * self.G + self.K * self.M * self.M_g)
        apex = self.at_apex(trial)
        de[apex] = trial.q[apex] / (2.0 * self.G)
        return de

    def stress(self, trial: Trial, de: np.ndarray, de_nonlocal: np.ndarray | None = None) -> np.ndarray:
        """Stress after the return [Pa], ``shape=(n, 3, 3)``.

        Applies ``d = max(de, de_nonlocal)``, capped at ``q_trial / 2G``: ``q = q_trial - 2 G d``,
        ``p = p_trial + 2/3 K M_g d``; at the apex ``sigma = c cot(phi) I``.
        """
        G = self.G
        d = np.minimum(applied_increment(de, de_nonlocal), trial.q / (2.0 * G))
        apex = self.at_apex(trial)
        q = np.where(apex, 0.0, np.maximum(trial.q - 2.0 * G * d, 0.0))
        p = np.where(apex, -self.tension_limit, trial.p + (2.0 / 3.0) * self.K * self.M_g * d)
        return self.radial_stress(trial, q, p)

    def record(self, state, de, de_nonlocal, dt, applied=None):
        """Accumulate ``eps_p += 2/3 applied`` (``q_trial / 3G`` at the apex)."""
        state["eps_p"][:] += (2.0 / 3.0) * applied_increment(de, de_nonlocal, applied)

    def tangent(self, trial: Trial, de: np.ndarray, dt: float) -> np.ndarray:
        """Consistent tangent of the return [Pa] (Mandel), ``shape=(n, 6, 6)``; zero at the apex."""
        K, G, M, M_g = self.K, self.G, self.M, self.M_g
        H = 3.0 * G + K * M * M_g
        apex = self.at_apex(trial)
        act = (de > 0.0) & ~apex
        q = np.where(act, trial.q - 2.0 * G * np.where(act, de, 0.0), trial.q)
        dq_dqtrial = np.where(act, 1.0 - 3.0 * G / H, 1.0)
        dq_dp = np.where(act, 3.0 * G * M / H, 0.0)
        D = self.radial_tangent(trial, q, dq_dqtrial, dq_dp)
        if M_g > 0.0:  # the pressure moves too: dp = dp_trial + K M_g d(dlam)
            norm = np.sqrt(2.0 / 3.0) * trial.q
            n = to_mandel(particle_first(trial.s))[act] / norm[act, None]
            dlam_deps = (np.sqrt(6.0) * G * n + M * K * MANDEL_IDENTITY) / H
            D[act] -= K * M_g * MANDEL_IDENTITY[None, :, None] * dlam_deps[:, None, :]
        D[apex] = 0.0
        return D
