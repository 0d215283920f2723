"""The energies of a run: what the particles hold, what their plastic flow dissipates.

The balance a run keeps: the kinetic, strain and gravitational potential energy of the
particles, the (visco)plastic work of the returns, the energy carried into sinks, and what is
left: the work of walls and damping, what the transfers lose, the strain energy of points that
separate, and the time step's own error.
"""

import numpy as np

from dolfin_mpm.core.particles import Particles

__all__ = ["mechanical", "plastic_work"]


def mechanical(P: Particles, materials: list, gravity: np.ndarray, mask: np.ndarray | None = None) -> dict:
    """Kinetic, strain and gravitational potential energy [J] (per metre in 2D) of this rank's particles.

    Of those where ``mask`` (``shape=(n,)``) holds, if given; ``gravity`` [m/s^2] ``shape=(gdim,)``.
    """
    if mask is not None:
        P = _Subset(P, mask)
    g = len(gravity)
    strain = 0.0
    for k, material in enumerate(materials):
        idx = P.material == k
        strain += float(np.sum(P.volume[idx] * material.strain_energy_density(P.sigma[idx])))
    return {
        "kinetic": 0.5 * float(np.sum(P.mass[:, None] * P.v**2)),
        "strain": strain,
        "potential": -float(np.sum(P.mass * (P.x[:, :g] @ gravity))),
    }


def plastic_work(groups: list, trials: list, sigma: np.ndarray, volume: np.ndarray) -> float:
    """The (visco)plastic work [J] of the step's returns on this rank, ``sum V sigma : de_p``.

    ``groups``: the step's ``(material, particles, state)`` groups, ``trials`` their elastic
    predictors, ``sigma`` [Pa] ``shape=(n, 3, 3)`` and ``volume`` [m^3] ``shape=(n,)`` the
    stresses and volumes the step ends with (see ``Material.plastic_work_density``). Elastic
    materials do none.
    """
    total = 0.0
    for (material, idx, _), trial in zip(groups, trials):
        if material.plastic:
            total += float(volume[idx] @ material.plastic_work_density(trial, sigma[idx]))
    return total


class _Subset:
    """The fields :func:`mechanical` reads, of the particles where ``mask`` holds."""

    def __init__(self, P: Particles, mask: np.ndarray):
        for name in ("material", "volume", "sigma", "mass", "v", "x"):
            setattr(self, name, getattr(P, name)[mask])
