"""Elastic–viscoplastic Drucker–Prager material of Więckowski & Kowalska-Kubisk (§2).

    f = q - m p,   m = 18 sin(phi) / (9 - sin^2 phi),   g = q (plastically isochoric)
    p' = -K d_kk,  e = s^J / (2G) + gamma <Phi> dg/ds,  Phi = ((q - m p) / (m p))^N

(The paper prints ``p' = K d_kk``; with ``p = -sigma_ii / 3`` compression must raise ``p``.)

The equivalent viscoplastic strain rate follows the paper's norm, ``e_vp = sqrt(3/2 e_vp:e_vp)
= 3/2 gamma <Phi>``. The viscoplastic part is integrated by backward Euler (radial return):
``q = q_trial - 2 G dt e_vp``, closed form for N = 1, safeguarded Newton otherwise; it is
stable for any ``dt`` and never overshoots the yield surface (``m p <= q <= q_trial``).

The update is split so that a non-local average can enter between its parts (the protocol of
:mod:`dolfin_mpm.materials.base`): :meth:`trial` (elastic predictor with the Jaumann rotation)
-> :meth:`increment` (local viscoplastic strain increment ``de = dt e_vp``) -> :meth:`stress`
(deviator along the trial one, ``q = q_trial - 2 G max(de, de_bar)`` with the non-local
increment ``de_bar``, kept >= 0) -> :meth:`record`.

How the non-local increment enters: the paper relaxes the stress by ``de_bar`` alone. Where a
point's own increment exceeds its neighbourhood average (band centres, points next to a free
surface) that leaves it far outside its yield cone: on a collapsing column, q / (m p) reached
173 (99th percentile 15) -- spurious strength of a cohesionless material -- and the
fixed-point loop cycled between the stress-free apex and this strength. The larger of the two
increments lets neighbours drag a point into flow (a band is at least ``r`` wide) while no
point ever carries more than its own law allows.

No tension: a cohesionless material point whose trial pressure is ``p <= 0`` loses contact
with its neighbours and becomes stress free (the apex of the cone); the deviatoric strain
absorbed there, ``q_trial / 2G``, is recorded as viscoplastic. With a cohesion ``c`` the cone
and its apex shift to ``p = -c cot(phi)``, where the stress is ``c cot(phi) I``.

``gamma = inf`` is the rate-independent limit: the stress returns onto the cone. The implicit
FE solver uses that with :meth:`tangent`, the consistent tangent of the return mapping.
"""

import ctypes
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dolfin_mpm import native
from dolfin_mpm.materials.base import Trial
from dolfin_mpm.materials.radial_return import RadialReturn, applied_increment
from dolfin_mpm.params import parameter

__all__ = ["DruckerPragerViscoplastic"]

_REAL, _NUMBER = native.array(np.float64), ctypes.c_double
_SIGNATURES = {
    "dp_increment": (ctypes.c_int64, _REAL, _REAL, *[_NUMBER] * 5, _REAL),
    "dp_end_state": (ctypes.c_int64, _REAL, _REAL, _REAL, _REAL, _NUMBER, _NUMBER, _REAL, _REAL),
}
_kernels = native.kernels(Path(__file__).with_suffix(".c"), _SIGNATURES)


@dataclass(frozen=True)
class DruckerPragerViscoplastic(RadialReturn):
    """Hypo-elastic, Perzyna-viscoplastic Drucker–Prager solid with g = q.

    Args:
        E, nu, rho: elasticity and density, as for :class:`LinearElastic`.
        phi: angle of internal friction [degrees], in (0, 90).
        gamma: viscosity parameter [1/s], in (0, inf]; ``inf`` is the rate-independent limit
            (the stress returns onto the cone, ``q = m p``).
        N: exponent of the viscosity law [-], > 0.
        c: cohesion [Pa], >= 0: the cone ``q = m (p + c cot(phi))``; the paper's sand has
            none.
        rho_c: critical density [kg/m^3], in (0, rho]: below it a point is apart, stress free,
            and keeps its volume at ``m / rho_c`` (see :mod:`dolfin_mpm.materials.separation`);
            ``None``: the volume follows the flow whatever it becomes.

    """

    phi: float = parameter(0.0, 90.0, "degrees")
    gamma: float = parameter(0.0, np.inf, "1/s", closed=(False, True))
    N: float = parameter(0.0, np.inf, default=1.0)
    c: float = parameter(0.0, np.inf, "Pa", closed=(True, False), default=0.0)
    rho_c: float | None = parameter(0.0, np.inf, "kg/m^3", default=None)

    def __post_init__(self):
        super().__post_init__()
        if self.rho_c is not None and not self.rho_c <= self.rho:
            raise ValueError(f"rho_c must be in (0, rho] = (0, {self.rho:g}] kg/m^3, got {self.rho_c!r}")
        _kernels()  # compiled now, before any long work

    @property
    def m(self) -> float:
        """Slope of the yield line ``q = m p`` (plane-strain match to Mohr–Coulomb)."""
        s = np.sin(np.radians(self.phi))
        return 18.0 * s / (9.0 - s * s)

    @property
    def tension_limit(self) -> float:
        """``c cot(phi)`` [Pa]: the cone's apex is at ``p = -c cot(phi)``."""
        return self.c / np.tan(np.radians(self.phi))

    def state_fields(self):
        # Equivalent viscoplastic strain rate (local and non-local) [1/s], accumulated strain [-];
        # with a critical density, the free volume [m^3] of a point apart.
        fields = {"eps_vp_rate": (), "eps_vp_rate_nonlocal": (), "eps_vp": ()}
        return fields if self.rho_c is None else {**fields, "free_volume": ()}

    def at_apex(self, trial: Trial) -> np.ndarray:
        """Points whose trial pressure is beyond the apex, ``p_trial + c cot(phi) <= 0``, ``shape=(n,)``."""
        return trial.p + self.tension_limit <= 0.0

    # -- the parts of the update -----------------------------------------------------------
    def increment(self, trial: Trial, state: dict[str, np.ndarray], dt: float) -> np.ndarray:
        """Local equivalent viscoplastic strain increment ``de = dt e_vp`` [-] (backward Euler).

        Solves ``de = dt 3/2 gamma <Phi(q)>`` with ``q = q_trial - 2 G de`` for ``de >= 0``
        (closed form for N = 1, safeguarded Newton otherwise); at the apex
        (``p <= -c cot(phi)``) ``de = q_trial / 2G``. ``state`` is not needed. ``shape=(n,)``.
        """
        de = np.empty_like(trial.q)
        _kernels().dp_increment(
            len(de),
            trial.p,
            trial.q,
            self.m,
            self.tension_limit,
            self.G,
            3.0 * self.G * self.gamma * dt,
            self.N,
            de,
        )
        return de

    def stress(self, trial: Trial, de: np.ndarray, de_nonlocal: np.ndarray | None = None) -> np.ndarray:
        """Stress along the trial deviator [Pa], ``shape=(n, 3, 3)``.

        ``q = q_trial - 2 G de`` with the local increment ``de``; with a non-local increment
        ``de_nonlocal``, ``q = q_trial - 2 G max(de, de_nonlocal)``: neighbours can drag a
        point into viscoplastic flow but never give it more strength than its own law. ``q`` is
        kept >= 0; at the apex the stress is ``c cot(phi) I``.
        """
        de = np.ascontiguousarray(de, dtype=np.float64)
        de_nonlocal = de if de_nonlocal is None else np.ascontiguousarray(de_nonlocal, dtype=np.float64)
        p, q = np.empty_like(de), np.empty_like(de)
        _kernels().dp_end_state(len(de), trial.p, trial.q, de, de_nonlocal, self.G, self.tension_limit, p, q)
        return self.radial_stress(trial, q, p)

    def record(self, state, de, de_nonlocal, dt, applied=None):
        """Store the local and non-local rates [1/s] and accumulate the applied strain ``eps_vp``."""
        state["eps_vp_rate"][:] = de / dt
        state["eps_vp_rate_nonlocal"][:] = (de if de_nonlocal is None else de_nonlocal) / dt
        state["eps_vp"][:] += applied_increment(de, de_nonlocal, applied)

    def increment_of_rate(self, trial: Trial, u: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """The increment ``d`` [-] whose end state ``q = q_trial - 2 G d`` has the rate ``u`` [-].

        The inverse of the Perzyna law ``u = dt 3/2 gamma Phi(q)``: ``q = y (1 + (u / c)^(1/N))``,
        ``c = 3/2 gamma dt``, ``y`` the yield value; at the apex (``y <= 0``) the stress-free
        state, ``d = q_trial / 2G``, whatever ``u``. Also returns ``-dd/du >= 0``, taken at
        ``max(u, 1e-9 c)`` where ``N > 1`` makes it infinite at ``u = 0``. All ``shape=(n,)``;
        the non-local law's solver uses these (:mod:`dolfin_mpm.averaging.complementarity`).
        """
        y = np.maximum(self.yield_value(trial), 0.0)
        c = 1.5 * self.gamma * dt
        two_G = 2.0 * self.G
        if np.isinf(c):  # rate independent: the end state is on the cone whatever the rate
            return (trial.q - y) / two_G, np.zeros_like(u)
        if self.N == 1.0:
            x, dx_du = u / c, np.full_like(u, 1.0 / c)
        else:
            x = (u / c) ** (1.0 / self.N)
            w = np.maximum(u, 1e-9 * c) / c
            dx_du = w ** (1.0 / self.N - 1.0) / (self.N * c)
        return (trial.q - y * (1.0 + x)) / two_G, y * dx_du / two_G

    def perzyna(self, dt: float) -> tuple[float, float]:
        """``c = 3/2 gamma dt`` [-] and ``N`` of the Perzyna law ``u = c <q / y - 1>^N`` of a step.

        The overstress law's solver uses them (:mod:`dolfin_mpm.averaging.overstress`).
        """
        return 1.5 * self.gamma * dt, self.N

    def yield_value(self, trial: Trial) -> np.ndarray:
        """The yield value of ``q`` at the trial pressure, ``m (p + c cot(phi))`` [Pa], ``shape=(n,)``."""
        return self.m * (trial.p + self.tension_limit)

    def tangent(self, trial: Trial, de: np.ndarray, dt: float) -> np.ndarray:
        """Consistent tangent of the local update ``stress(trial, increment(trial, state, dt))``.

        Mandel, ``shape=(n, 6, 6)`` [Pa]; zero at the apex (the stress there is fixed).
        """
        pt = trial.p + self.tension_limit
        y = self.m * pt  # m (p + c cot phi): the yield value of q
        q = np.maximum(trial.q - 2.0 * self.G * de, 0.0)
        dq_dqtrial, dq_dp = np.ones_like(q), np.zeros_like(q)
        act = (de > 0.0) & (pt > 0.0)
        if np.isinf(self.gamma):
            dq_dqtrial[act], dq_dp[act] = 0.0, self.m
        else:  # implicit derivative of x + a x^N = x_tr, q = y (1 + x), a = 3 G gamma dt / y
            ya, x = y[act], q[act] / y[act] - 1.0
            a = 3.0 * self.G * self.gamma * dt / ya
            with np.errstate(divide="ignore"):
                slope = 1.0 + a * self.N * x ** (self.N - 1.0)
            dq_dqtrial[act] = 1.0 / slope
            dq_dp[act] = self.m * ((1.0 + x) + (a * x**self.N - trial.q[act] / ya) / slope)
        D = self.radial_tangent(trial, q, dq_dqtrial, dq_dp)
        D[pt <= 0.0] = 0.0
        return D
