"""Linear hypo-elasticity with the Zaremba–Jaumann stress rate.

The rate is integrated incrementally objectively (Hughes–Winget): the stress is rotated by
``Q = (I - dt W/2)^-1 (I + dt W/2)``, exactly orthogonal for any ``dt W``, then the elastic
increment is added. The predictor is one compiled pass over the particles
(``hypoelastic.c``): in numpy its ~100 flops per particle streamed a dozen temporary
arrays through memory, a quarter of the paper's step. It is the :meth:`~LinearElastic.trial`
of every material here; the elastic solid takes it as the end state (no plastic increment).
"""

import ctypes
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dolfin_mpm import native
from dolfin_mpm.materials.base import Material, Trial
from dolfin_mpm.materials.tensor import (
    MANDEL_DEVIATORIC,
    MANDEL_IDENTITY,
    component_first,
    deviator,
    particle_first,
)
from dolfin_mpm.params import parameter

__all__ = ["LinearElastic"]

_REAL = native.array(np.float64)
_SIGNATURES = {
    "hypoelastic_trial": (
        ctypes.c_int64, ctypes.c_int32, _REAL, _REAL, ctypes.c_double, ctypes.c_double, ctypes.c_double,
        _REAL, _REAL, _REAL,
    ),
}  # fmt: skip
_kernels = native.kernels(Path(__file__).with_name("hypoelastic.c"), _SIGNATURES)


@dataclass(frozen=True)
class LinearElastic(Material):
    """Isotropic hypo-elastic solid, ``sigma^J = K tr(d) I + 2 G dev(d)``.

    Args:
        E: Young's modulus [Pa], > 0.
        nu: Poisson's ratio [-], in (-1, 0.5).
        rho: mass density [kg/m^3], > 0.

    """

    E: float = parameter(0.0, np.inf, "Pa")
    nu: float = parameter(-1.0, 0.5)
    rho: float = parameter(0.0, np.inf, "kg/m^3")

    def __post_init__(self):
        super().__post_init__()
        _kernels()  # compiled now, before any long work

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

    def trial(self, sigma, L, dt) -> Trial:
        """The elastic update of ``sigma`` split into pressure, deviator and equivalent stress.

        Args:
            sigma: stress [Pa], ``shape=(n, 3, 3)``, symmetric (its upper triangle is read).
            L: velocity gradient [1/s], ``shape=(n, gdim, gdim)``; rate of deformation
                ``d = sym L``, spin ``W = skew L``, zero out of the plane in 2D (plane strain).
                An implicit small-strain caller passes the strain increment with ``dt = 1``.
            dt: time step [s].

        Returns:
            ``Trial(p, s, q)``: ``p`` [Pa] ``shape=(n,)``, the deviator ``s`` [Pa]
            ``shape=(3, 3, n)`` (component-first), ``q = sqrt(3/2 s:s)`` [Pa] ``shape=(n,)``.

        """
        sigma, L = (component_first(np.asarray(a, dtype=np.float64)) for a in (sigma, L))
        n = sigma.shape[-1]
        p, s, q = np.empty(n), np.empty((3, 3, n)), np.empty(n)
        _kernels().hypoelastic_trial(n, L.shape[0], sigma, L, dt, self.K, self.G, p, s, q)
        return Trial(p=p, s=s, q=q)

    def increment(self, trial, state, dt):
        """No plastic strain: zeros, ``shape=(n,)``."""
        return np.zeros_like(trial.q)

    def stress(self, trial, de, de_nonlocal=None):
        """The trial stress ``s - p I`` [Pa], ``shape=(n, 3, 3)``, built in ``trial.s`` (no copy)."""
        sigma = trial.s
        for i in range(3):
            sigma[i, i] -= trial.p
        return particle_first(sigma)

    def record(self, state, de, de_nonlocal, dt, applied=None):
        """No state."""

    def tangent(self, trial, de, dt):
        """Elastic stiffness ``K 1x1 + 2 G I_dev`` [Pa], Mandel, ``shape=(n, 6, 6)``."""
        D = self.K * np.outer(MANDEL_IDENTITY, MANDEL_IDENTITY) + 2.0 * self.G * MANDEL_DEVIATORIC
        return np.broadcast_to(D, (len(trial.q), 6, 6)).copy()

    def plastic_work_density(self, trial, sigma):
        """None: the stress is the trial's (zeros, ``shape=(n,)``)."""
        return np.zeros(len(trial.q))

    def strain_energy_density(self, sigma):
        p, s = deviator(sigma)
        s = component_first(s)
        return p**2 / (2.0 * self.K) + (s * s).sum(axis=(0, 1)) / (4.0 * self.G)
