"""Radial return of isochoric plasticity, shared by the explicit MPM and the implicit FE solver.

Von Mises and the paper's Drucker–Prager with ``g = q`` both flow along the deviator and never
change the pressure. After an elastic predictor ``(p, s_trial, q_trial)`` the stress is

    sigma = (q / q_trial) s_trial - p I

with the equivalent stress ``q(q_trial, p)`` that the material's return mapping gives. Its
consistent tangent (``d sigma / d eps`` at fixed state, what Newton's method needs) is then

    D = K 1x1 + 2 G b I_dev + 2 G (q' - b) n x n - sqrt(2/3) K q_p n x 1,

``b = q / q_trial``, ``q' = dq/dq_trial``, ``q_p = dq/dp``, ``n = s_trial / |s_trial|``. Tensors
enter as Mandel 6-vectors ``(xx, yy, zz, sqrt2 yz, sqrt2 xz, sqrt2 xy)``, so that ``D`` acts on
strains by a plain matrix product.
"""

import ctypes
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dolfin_mpm import native
from dolfin_mpm.materials.elastic import LinearElastic
from dolfin_mpm.materials.tensor import particle_first, to_mandel

__all__ = ["IsochoricPlastic", "Trial"]

_REAL = native.array(np.float64)
_SIGNATURES = {"radial_stress": (ctypes.c_int64, *[_REAL] * 5)}
_kernels = native.kernels(Path(__file__).with_suffix(".c"), _SIGNATURES)


_ONE = np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])
_I_DEV = np.eye(6) - np.outer(_ONE, _ONE) / 3.0


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


class IsochoricPlastic(LinearElastic):
    """Hypo-elastic solid whose plastic flow is deviatoric: the parts every return mapping shares."""

    def __post_init__(self):
        super().__post_init__()
        _kernels()  # compiled now, before any long work

    def trial(self, sigma: np.ndarray, L: np.ndarray, dt: float) -> Trial:
        """Elastic predictor: the hypo-elastic update of :class:`LinearElastic`, split into p and s.

        An implicit small-strain caller passes the strain increment as ``L`` with ``dt = 1``.
        """
        p, s, q = self.predictor(sigma, L, dt)
        return Trial(p=p, s=s, q=q)

    @staticmethod
    def radial_stress(trial: Trial, q: np.ndarray, p: np.ndarray) -> np.ndarray:
        """``(q / q_trial) s_trial - p I``, ``shape=(n, 3, 3)``; no deviator where ``q_trial = 0``."""
        sigma = np.empty_like(trial.s)
        q, p = (np.ascontiguousarray(a, dtype=np.float64) for a in (q, p))
        _kernels().radial_stress(len(q), trial.s, trial.q, q, p, sigma)
        return particle_first(sigma)

    def radial_tangent(
        self, trial: Trial, q: np.ndarray, dq_dqtrial: np.ndarray, dq_dp: np.ndarray
    ) -> np.ndarray:
        """Consistent tangent of :meth:`radial_stress` (Mandel), ``shape=(n, 6, 6)`` [Pa]."""
        K, G = self.K, self.G
        norm = np.sqrt(2.0 / 3.0) * trial.q  # |s_trial|
        n = to_mandel(particle_first(trial.s)) / np.where(norm > 0.0, norm, 1.0)[:, None]
        b = np.divide(q, trial.q, out=np.ones_like(q), where=trial.q > 0.0)
        D = K * np.outer(_ONE, _ONE) + (2.0 * G * b)[:, None, None] * _I_DEV
        D += (2.0 * G * (dq_dqtrial - b))[:, None, None] * n[:, :, None] * n[:, None, :]
        D -= (np.sqrt(2.0 / 3.0) * K * dq_dp)[:, None, None] * n[:, :, None] * _ONE[None, None, :]
        return D
