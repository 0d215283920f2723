"""Vectorised tensor kinematics on stacks of 3x3 tensors (particle axis first)."""

import numpy as np

__all__ = ["deviator", "invariants", "jaumann_rotation", "split_velocity_gradient"]


def split_velocity_gradient(L: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rate of deformation ``d = sym L`` and spin ``W = skew L`` as 3x3 tensors.

    Args:
        L: velocity gradient ``L_ij = dv_i/dx_j`` [1/s], ``shape=(n, gdim, gdim)``.

    Returns:
        ``(d, W)``, each ``shape=(n, 3, 3)``; in 2D the out-of-plane rows are zero
        (plane strain). The paper's spin is ``omega = -W``.
    """
    n, g, _ = L.shape
    L3 = np.zeros((n, 3, 3))
    L3[:, :g, :g] = L
    Lt = np.swapaxes(L3, 1, 2)
    return 0.5 * (L3 + Lt), 0.5 * (L3 - Lt)


def jaumann_rotation(W: np.ndarray, dt: float) -> np.ndarray:
    """Incremental rotation of the Hughes–Winget update, ``(I - dt W/2)^-1 (I + dt W/2)``.

    Rotating ``sigma`` by it (``Q sigma Q^T``) integrates the spin terms of the
    Zaremba–Jaumann rate exactly objectively, for any size of ``dt W``.

    Args:
        W: spin [1/s], skew, ``shape=(n, 3, 3)``.
        dt: time step [s].

    Returns:
        Proper orthogonal ``Q``, ``shape=(n, 3, 3)``.
    """
    A = 0.5 * dt * W
    # Cayley transform in closed form: Q = I + 2 (A + A^2) / (1 + |a|^2), a = axial(A).
    a2 = A[:, 0, 1] ** 2 + A[:, 0, 2] ** 2 + A[:, 1, 2] ** 2
    Q = A + A @ A
    Q *= (2.0 / (1.0 + a2))[:, None, None]
    Q[:, 0, 0] += 1.0
    Q[:, 1, 1] += 1.0
    Q[:, 2, 2] += 1.0
    return Q


def deviator(sigma: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pressure ``p = -tr(sigma)/3`` [Pa] and deviator ``s = sigma + p I``, ``shape=(n, 3, 3)``."""
    p = -np.trace(sigma, axis1=1, axis2=2) / 3.0
    s = sigma.copy()
    for i in range(3):
        s[:, i, i] += p
    return p, s


def invariants(sigma: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pressure ``p`` and equivalent stress ``q = sqrt(3/2 s:s)`` [Pa], each ``shape=(n,)``."""
    p, s = deviator(sigma)
    return p, np.sqrt(1.5 * np.einsum("nij,nij->n", s, s))
