"""Particle-to-grid and grid-to-particle transfers through the P1 basis (vectorised).

Nodal arrays are ``shape=(num_nodes, k)``; per-particle arrays have the particle axis first;
the basis is component-first (:class:`dolfin_mpm.locate.Basis`), with the sparse matrices of
its values built once per step. Loops run over the few nodes of a cell and the
vector components, never over particles.
"""

import numpy as np

from dolfin_mpm.locate import Basis
from dolfin_mpm.tensor import particle_first

__all__ = ["gradient", "internal_force", "interpolate", "scatter"]


def scatter(basis: Basis, values: np.ndarray) -> np.ndarray:
    """Local nodal sums ``sum_p N_a(x_p) values_p``.

    Args:
        values: ``shape=(n,)`` or ``(n, k)``.

    Returns:
        ``shape=(num_nodes,)`` or ``(num_nodes, k)``.

    """
    if values.ndim == 1:
        return basis.to_nodes @ values
    return np.stack([basis.to_nodes @ values[:, c] for c in range(values.shape[1])], axis=1)


def internal_force(basis: Basis, sigma: np.ndarray, volume: np.ndarray) -> np.ndarray:
    """Nodal internal forces ``R_a = sum_p V_p sigma_p grad N_a(x_p)``, ``shape=(num_nodes, gdim)``.

    Args:
        sigma: Cauchy stress [Pa], ``shape=(n, 3, 3)``.
        volume: particle volumes, ``shape=(n,)``.

    """
    idx = basis.dofs.ravel()
    g = basis.dN.shape[1]
    cols = []
    for i in range(g):
        s = [sigma[:, i, j] * volume for j in range(g)]
        w = sum(s[j] * basis.dN[:, j, :] for j in range(g))  # (gdim+1, n)
        cols.append(np.bincount(idx, w.ravel(), minlength=basis.num_nodes))
    return np.stack(cols, axis=1)


def interpolate(basis: Basis, nodal: np.ndarray) -> np.ndarray:
    """Values ``sum_a N_a(x_p) nodal_a`` at the particles, ``nodal.shape=(num_nodes, k)`` -> ``(n, k)``."""
    out = np.empty((basis.N.shape[1], nodal.shape[1]))
    for c in range(nodal.shape[1]):
        out[:, c] = basis.to_particles @ np.ascontiguousarray(nodal[:, c])
    return out


def gradient(basis: Basis, nodal: np.ndarray) -> np.ndarray:
    """Gradient ``L_ij = sum_a nodal_a,i dN_a/dx_j`` at the particles, ``shape=(n, k, gdim)``.

    The result is a particle-first view of component-first memory.
    """
    g = basis.dN.shape[1]
    L = np.empty((nodal.shape[1], g, basis.N.shape[1]))
    for i in range(nodal.shape[1]):
        vi = np.ascontiguousarray(nodal[:, i]).take(basis.dofs)  # (gdim+1, n)
        for j in range(g):
            L[i, j] = (vi * basis.dN[:, j, :]).sum(axis=0)
    return particle_first(L)
