"""Elastic–viscoplastic Drucker–Prager material of Więckowski & Kowalska-Kubisk (§2).

    f = q - m p,   m = 18 sin(phi) / (9 - sin^2 phi),   g = q (plastically isochoric)
    p' = -K d_kk,  e = s^J / (2G) + gamma <Phi> dg/ds,  Phi = ((q - m p) / (m p))^N

(The paper prints ``p' = K d_kk``; with ``p = -sigma_ii / 3`` compression must raise ``p``.)

The equivalent viscoplastic strain rate follows the paper's norm, ``e_vp = sqrt(3/2 e_vp:e_vp)
= 3/2 gamma <Phi>``. The viscoplastic part is integrated by backward Euler (radial return):
``q = q_trial - 2 G dt e_vp``, closed form for N = 1, safeguarded Newton otherwise; it is
stable for any ``dt`` and never overshoots the yield surface (``m p <= q <= q_trial``).

The update is split so that a non-local average can enter between its parts:
:meth:`trial` (elastic predictor with the Jaumann rotation) -> :meth:`increment` (local
viscoplastic strain increment ``de``) -> :meth:`stress` (deviator along the trial one,
``q = q_trial - 2 G max(de, de_bar)`` with the non-local increment ``de_bar``, kept >= 0).

How the non-local increment enters: the paper relaxes the stress by ``de_bar`` alone. Where a
point's own increment exceeds its neighbourhood average (band centres, points next to a free
surface) that leaves it far outside its yield cone: on a collapsing column, q / (m p) reached
173 (99th percentile 15) -- spurious strength of a cohesionless material -- and the
fixed-point loop cycled between the stress-free apex and this strength. The larger of the two
increments lets neighbours drag a point into flow (a band is at least ``r`` wide) while no
point ever carries more than its own law allows.

No tension: a cohesionless material point whose trial pressure is ``p <= 0`` loses contact
with its neighbours and becomes stress free (the apex of the cone); the deviatoric strain
absorbed there, ``q_trial / 2G``, is recorded as viscoplastic.
"""

from dataclasses import dataclass

import numpy as np

from dolfin_mpm.materials.base import check_range
from dolfin_mpm.materials.elastic import LinearElastic
from dolfin_mpm.tensor import component_first, deviator, equivalent_stress, particle_first

__all__ = ["DruckerPragerViscoplastic", "Trial"]


@dataclass
class Trial:
    """Elastic predictor of one step (component-first arrays).

    Attributes:
        p: pressure [Pa], ``shape=(n,)``.
        s: deviator [Pa], ``shape=(3, 3, n)``.
        q: equivalent stress of ``s`` [Pa], ``shape=(n,)``.

    """

    p: np.ndarray
    s: np.ndarray
    q: np.ndarray


@dataclass(frozen=True)
class DruckerPragerViscoplastic(LinearElastic):
    """Hypo-elastic, Perzyna-viscoplastic Drucker–Prager solid with g = q.

    Args:
        E, nu, rho: elasticity and density, as for :class:`LinearElastic`.
        phi: angle of internal friction [degrees], in (0, 90).
        gamma: viscosity parameter [1/s], > 0.
        N: exponent of the viscosity law, > 0.

    """

    phi: float
    gamma: float
    N: float = 1.0

    def __post_init__(self):
        super().__post_init__()
        check_range("phi", self.phi, 0.0, 90.0)
        check_range("gamma", self.gamma, 0.0, np.inf)
        check_range("N", self.N, 0.0, np.inf)

    @property
    def m(self) -> float:
        """Slope of the yield line ``q = m p`` (plane-strain match to Mohr–Coulomb)."""
        s = np.sin(np.radians(self.phi))
        return 18.0 * s / (9.0 - s * s)

    def state_fields(self):
        # Equivalent viscoplastic strain rate (local and non-local) [1/s], accumulated strain [-].
        return {"eps_vp_rate": (), "eps_vp_rate_nonlocal": (), "eps_vp": ()}

    # -- the three parts of the update ---------------------------------------------------------
    def trial(self, sigma: np.ndarray, d: np.ndarray, W: np.ndarray, dt: float) -> Trial:
        """Elastic predictor: the hypo-elastic update of :class:`LinearElastic`, split into p and s."""
        p, s = deviator(LinearElastic.update(self, sigma, d, W, dt, {}))
        return Trial(p=p, s=component_first(s), q=equivalent_stress(s))  # component_first: a view

    def increment(self, trial: Trial, dt: float) -> np.ndarray:
        """Local equivalent viscoplastic strain increment ``de = dt * e_vp`` (backward Euler).

        Solves ``de = dt 3/2 gamma <Phi(q)>`` with ``q = q_trial - 2 G de`` for ``de >= 0``;
        at the apex (``p <= 0``) ``de = q_trial / 2G``. ``shape=(n,)``.
        """
        G, mp = self.G, self.m * trial.p
        de = np.zeros_like(trial.q)
        apex = trial.p <= 0.0
        de[apex] = trial.q[apex] / (2.0 * G)
        act = ~apex & (trial.q > mp)
        mp_a = mp[act]
        x_tr = (trial.q[act] - mp_a) / mp_a  # relative overstress of the trial state
        a = 3.0 * G * self.gamma * dt / mp_a
        x = x_tr / (1.0 + a) if self.N == 1.0 else _solve_overstress(x_tr, a, self.N)
        de[act] = (x_tr - x) * mp_a / (2.0 * G)
        return de

    def stress(self, trial: Trial, de: np.ndarray, de_nonlocal: np.ndarray | None = None) -> np.ndarray:
        """Stress along the trial deviator, ``shape=(n, 3, 3)``.

        ``q = q_trial - 2 G de`` with the local increment ``de``; with a non-local increment
        ``de_nonlocal``, ``q = q_trial - 2 G max(de, de_nonlocal)``: neighbours can drag a
        point into viscoplastic flow but never give it more strength than its own law.
        """
        if de_nonlocal is not None:
            de = np.maximum(de, de_nonlocal)
        q = np.maximum(trial.q - 2.0 * self.G * de, 0.0)
        scale = np.divide(q, trial.q, out=np.zeros_like(q), where=trial.q > 0.0)
        scale[trial.p <= 0.0] = 0.0
        sig = trial.s * scale
        p = np.maximum(trial.p, 0.0)
        for i in range(3):
            sig[i, i] -= p
        return particle_first(sig)

    def update(self, sigma, d, W, dt, state):
        trial = self.trial(sigma, d, W, dt)
        de = self.increment(trial, dt)
        self.record(state, de, de, dt)
        return self.stress(trial, de)

    @staticmethod
    def record(state: dict[str, np.ndarray], de: np.ndarray, de_nonlocal: np.ndarray, dt: float) -> None:
        """Store the local and non-local rates and accumulate the applied equivalent strain."""
        state["eps_vp_rate"][:] = de / dt
        state["eps_vp_rate_nonlocal"][:] = de_nonlocal / dt
        state["eps_vp"][:] += np.maximum(de, de_nonlocal)


def _solve_overstress(x_tr: np.ndarray, a: np.ndarray, N: float, tol: float = 1e-13) -> np.ndarray:
    """Root ``x`` in ``[0, x_tr]`` of ``x + a x^N = x_tr`` (safeguarded Newton, vectorised)."""
    lo, hi = np.zeros_like(x_tr), x_tr.copy()
    x = np.minimum(x_tr, (x_tr / a) ** (1.0 / N))  # the root when a x^N dominates
    for _ in range(100):
        h = x + a * x**N - x_tr
        lo = np.where(h < 0.0, x, lo)
        hi = np.where(h > 0.0, x, hi)
        with np.errstate(divide="ignore", invalid="ignore"):
            x_new = x - h / (1.0 + a * N * x ** (N - 1.0))
        bad = ~((x_new > lo) & (x_new < hi))
        x_new[bad] = 0.5 * (lo[bad] + hi[bad])
        if np.all(np.abs(x_new - x) <= tol * np.maximum(x_tr, 1e-300)):
            return x_new
        x = x_new
    return x
