"""Radial return: plastic flow whose deviatoric part is along the trial deviator.

Von Mises, the paper's Drucker–Prager (``g = q``) and the dilatant Drucker–Prager cone
(``g = q - M_g p``) all return along the trial deviator. After an elastic predictor
``(p_trial, s_trial, q_trial)`` the stress is

    sigma = (q / q_trial) s_trial - p I,   q = q_trial - 2 G de,

with the plastic strain increment ``de`` (paper's norm, see :mod:`dolfin_mpm.materials.base`)
that the material's return mapping gives, and ``p = p_trial`` unless the flow dilates. Its
consistent tangent (``d sigma / d eps`` at fixed state, what Newton's method needs) is then

    D = K 1x1 + 2 G b I_dev + 2 G (q' - b) n x n - sqrt(2/3) K q_p n x 1,

``b = q / q_trial``, ``q' = dq/dq_trial``, ``q_p = dq/dp``, ``n = s_trial / |s_trial|``. Tensors
enter as Mandel 6-vectors ``(xx, yy, zz, sqrt2 yz, sqrt2 xz, sqrt2 xy)``, so that ``D`` acts on
strains by a plain matrix product.
"""

import ctypes
from pathlib import Path

import numpy as np

from dolfin_mpm import native
from dolfin_mpm.materials.base import Trial
from dolfin_mpm.materials.elastic import LinearElastic
from dolfin_mpm.materials.tensor import (
    MANDEL_DEVIATORIC,
    MANDEL_IDENTITY,
    component_first,
    particle_first,
    to_mandel,
)

__all__ = ["RadialReturn", "applied_increment"]

_REAL = native.array(np.float64)
_SIGNATURES = {
    "radial_stress": (ctypes.c_int64, *[_REAL] * 5),
    "plastic_work": (ctypes.c_int64, _REAL, _REAL, _REAL, ctypes.c_double, ctypes.c_double, _REAL),
}
_kernels = native.kernels(Path(__file__).with_suffix(".c"), _SIGNATURES)


def applied_increment(de: np.ndarray, de_nonlocal: np.ndarray | None, applied: np.ndarray | None = None):
    """``applied`` if given, else ``max(de, de_nonlocal)``, or ``de`` itself without a non-local increment."""
    if applied is not None:
        return applied
    return de if de_nonlocal is None else np.maximum(de, de_nonlocal)


class RadialReturn(LinearElastic):
    """Hypo-elastic solid returning along the trial deviator: the parts every such return shares.

    Subclasses give :meth:`increment`, :meth:`record` and :meth:`tangent`; the stress here
    keeps the trial pressure (isochoric flow) and applies ``max(de, de_nonlocal)``, capped at
    ``q = 0``.
    """

    plastic = True

    def __post_init__(self):
        super().__post_init__()
        _kernels()  # compiled now, before any long work

    def stress(self, trial: Trial, de: np.ndarray, de_nonlocal: np.ndarray | None = None) -> np.ndarray:
        """``sigma = (q / q_trial) s_trial - p_trial I`` with ``q = max(q_trial - 2 G de, 0)``.

        ``de`` [-] ``shape=(n,)``, or the larger of it and ``de_nonlocal``. ``shape=(n, 3, 3)`` [Pa].
        """
        q = np.maximum(trial.q - 2.0 * self.G * applied_increment(de, de_nonlocal), 0.0)
        return self.radial_stress(trial, q, trial.p)

    def plastic_work_density(self, trial: Trial, sigma: np.ndarray) -> np.ndarray:
        """``sigma : C^-1 (sigma_trial - sigma) = p (p_trial - p) / K + s : (s_trial - s) / 2G`` [J/m^3].

        ``sigma`` [Pa] ``shape=(n, 3, 3)``, the stress of :meth:`stress`; ``shape=(n,)``.
        """
        w = np.empty(len(trial.q))
        sigma = component_first(np.asarray(sigma, dtype=np.float64))
        _kernels().plastic_work(len(w), sigma, trial.p, trial.s, self.K, self.G, w)
        return w

    @staticmethod
    def radial_stress(trial: Trial, q: np.ndarray, p: np.ndarray) -> np.ndarray:
        """``(q / q_trial) s_trial - p I`` [Pa], ``shape=(n, 3, 3)``; no deviator where ``q_trial = 0``."""
        sigma = np.empty_like(trial.s)
        q, p = (np.ascontiguousarray(a, dtype=np.float64) for a in (q, p))
        _kernels().radial_stress(len(q), trial.s, trial.q, q, p, sigma)
        return particle_first(sigma)

    def radial_tangent(
        self, trial: Trial, q: np.ndarray, dq_dqtrial: np.ndarray, dq_dp: np.ndarray
    ) -> np.ndarray:
        """Consistent tangent of :meth:`radial_stress` [Pa] (Mandel), ``shape=(n, 6, 6)``."""
        K, G = self.K, self.G
        norm = np.sqrt(2.0 / 3.0) * trial.q  # |s_trial|
        n = to_mandel(particle_first(trial.s)) / np.where(norm > 0.0, norm, 1.0)[:, None]
        b = np.divide(q, trial.q, out=np.ones_like(q), where=trial.q > 0.0)
        D = K * np.outer(MANDEL_IDENTITY, MANDEL_IDENTITY) + (2.0 * G * b)[:, None, None] * MANDEL_DEVIATORIC
        D += (2.0 * G * (dq_dqtrial - b))[:, None, None] * n[:, :, None] * n[:, None, :]
        D -= (np.sqrt(2.0 / 3.0) * K * dq_dp)[:, None, None] * n[:, :, None] * MANDEL_IDENTITY[None, None, :]
        return D
