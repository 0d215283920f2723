"""Vectorised algebra on stacks of small tensors, ``shape=(n, 3, 3)`` (particle axis first).

Arguments may have any memory layout. The functions compute on component-first copies
(each component one contiguous array over the particles, several times faster in numpy
than strided access) and return particle-first *views* of component-first memory, so that
chained calls copy nothing.
"""

import numpy as np

__all__ = [
    "component_first",
    "det",
    "deviator",
    "equivalent_stress",
    "from_mandel",
    "invariants",
    "jaumann_rotate",
    "jaumann_rotation",
    "particle_first",
    "rotate",
    "split_velocity_gradient",
    "to_mandel",
]

# Mandel order: (xx, yy, zz, sqrt2 yz, sqrt2 xz, sqrt2 xy).
_MANDEL = ((0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1))
_SQRT2 = np.sqrt(2.0)


def component_first(a: np.ndarray) -> np.ndarray:
    """Contiguous ``shape=(..., n)`` array of ``a.shape=(n, ...)`` (no copy when already so)."""
    return np.ascontiguousarray(np.moveaxis(a, 0, -1))


def particle_first(c: np.ndarray) -> np.ndarray:
    """The ``shape=(n, ...)`` view of a component-first array."""
    return np.moveaxis(c, -1, 0)


def _mm(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Component-first product of ``(k, m, n)`` and ``(m, l, n)`` stacks."""
    C = np.empty((A.shape[0], B.shape[1], A.shape[2]))
    for i in range(A.shape[0]):
        for j in range(B.shape[1]):
            C[i, j] = sum(A[i, k] * B[k, j] for k in range(A.shape[1]))
    return C


def rotate(sigma: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """``Q sigma Q^T`` for stacks of 3x3 tensors."""
    Qc = component_first(Q)
    return particle_first(_mm(_mm(Qc, component_first(sigma)), Qc.transpose(1, 0, 2)))


def det(A: np.ndarray) -> np.ndarray:
    """Determinants of a stack of 2x2 or 3x3 matrices, ``shape=(n,)``."""
    a = component_first(A)
    if a.shape[0] == 2:
        return a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]
    return (
        a[0, 0] * (a[1, 1] * a[2, 2] - a[1, 2] * a[2, 1])
        - a[0, 1] * (a[1, 0] * a[2, 2] - a[1, 2] * a[2, 0])
        + a[0, 2] * (a[1, 0] * a[2, 1] - a[1, 1] * a[2, 0])
    )


def split_velocity_gradient(L: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rate of deformation ``d = sym L`` and spin ``W = skew L`` as 3x3 tensors.

    Args:
        L: velocity gradient ``L_ij = dv_i/dx_j`` [1/s], ``shape=(n, gdim, gdim)``.

    Returns:
        ``(d, W)``, each ``shape=(n, 3, 3)``; in 2D the out-of-plane rows are zero
        (plane strain). The paper's spin is ``omega = -W``.

    """
    Lc = component_first(L)
    g, n = Lc.shape[0], Lc.shape[2]
    d, W = np.zeros((3, 3, n)), np.zeros((3, 3, n))
    for i in range(g):
        d[i, i] = Lc[i, i]
        for j in range(i + 1, g):
            d[i, j] = d[j, i] = 0.5 * (Lc[i, j] + Lc[j, i])
            W[i, j] = 0.5 * (Lc[i, j] - Lc[j, i])
            W[j, i] = -W[i, j]
    return particle_first(d), particle_first(W)


def jaumann_rotation(W: np.ndarray, dt: float) -> np.ndarray:
    """Incremental rotation of the Hughes–Winget update, ``(I - dt W/2)^-1 (I + dt W/2)``.

    Rotating ``sigma`` by it (``Q sigma Q^T``) integrates the spin terms of the
    Zaremba–Jaumann rate incrementally objectively, for any size of ``dt W``.

    Args:
        W: spin [1/s], skew, ``shape=(n, 3, 3)``.
        dt: time step [s].

    Returns:
        Proper orthogonal ``Q``, ``shape=(n, 3, 3)``.

    """
    A = (0.5 * dt) * component_first(W)
    # Cayley transform in closed form: Q = I + 2 (A + A^2) / (1 + |a|^2), a = axial(A).
    a2 = A[0, 1] ** 2 + A[0, 2] ** 2 + A[1, 2] ** 2
    Q = A + _mm(A, A)
    Q *= 2.0 / (1.0 + a2)
    for i in range(3):
        Q[i, i] += 1.0
    return particle_first(Q)


def jaumann_rotate(sigma: np.ndarray, W: np.ndarray, dt: float) -> np.ndarray:
    """``Q sigma Q^T`` with ``Q = jaumann_rotation(W, dt)``, ``shape=(n, 3, 3)``.

    A spin in the xy-plane (``W_xz = W_yz = 0`` for all particles, as in plane strain) makes
    ``Q`` a rotation about z; the product then skips the terms with the zero entries of ``Q``,
    which changes nothing in the result but saves most of the work.
    """
    Wc = component_first(W)
    if np.any(Wc[0, 2]) or np.any(Wc[1, 2]):
        return rotate(sigma, jaumann_rotation(W, dt))
    S = component_first(sigma)
    # jaumann_rotation with A_xz = A_yz = 0: Q = I + 2 (A + A^2) / (1 + A_xy^2).
    a01, a10 = (0.5 * dt) * Wc[0, 1], (0.5 * dt) * Wc[1, 0]
    scale = 2.0 / (1.0 + a01**2)
    q00 = a01 * a10
    q00 *= scale
    q00 += 1.0  # = q11
    q01, q10 = a01 * scale, a10 * scale
    # T = Q S: its third row is S's.
    T = np.empty((2, 3, S.shape[2]))
    for j in range(3):
        T[0, j] = q00 * S[0, j] + q01 * S[1, j]
        T[1, j] = q10 * S[0, j] + q00 * S[1, j]
    # R = T Q^T
    R = np.empty_like(S)
    for i, t in enumerate((T[0], T[1], S[2])):
        R[i, 0] = t[0] * q00 + t[1] * q01
        R[i, 1] = t[0] * q10 + t[1] * q00
        R[i, 2] = t[2]
    return particle_first(R)


def deviator(sigma: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pressure ``p = -tr(sigma)/3`` [Pa] and deviator ``s = sigma + p I``, ``shape=(n, 3, 3)``."""
    s = component_first(sigma).copy()
    p = -(s[0, 0] + s[1, 1] + s[2, 2]) / 3.0
    for i in range(3):
        s[i, i] += p
    return p, particle_first(s)


def equivalent_stress(s: np.ndarray) -> np.ndarray:
    """``q = sqrt(3/2 s:s)`` [Pa] of deviators ``s`` (``shape=(n, 3, 3)``), ``shape=(n,)``."""
    c = component_first(s)
    return np.sqrt(1.5 * (c * c).sum(axis=(0, 1)))


def invariants(sigma: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pressure ``p`` and equivalent stress ``q = sqrt(3/2 s:s)`` [Pa], each ``shape=(n,)``."""
    p, s = deviator(sigma)
    return p, equivalent_stress(s)


def to_mandel(a: np.ndarray) -> np.ndarray:
    """Mandel 6-vectors of symmetric tensors ``shape=(n, 3, 3)``, ``shape=(n, 6)``.

    Double contraction becomes a dot product: ``a:b = to_mandel(a) @ to_mandel(b)``.
    """
    v = np.stack([a[:, i, j] for i, j in _MANDEL], axis=1)
    v[:, 3:] *= _SQRT2
    return v


def from_mandel(v: np.ndarray) -> np.ndarray:
    """Symmetric tensors ``shape=(n, 3, 3)`` of Mandel 6-vectors ``shape=(n, 6)``."""
    a = np.empty((v.shape[0], 3, 3))
    for k, (i, j) in enumerate(_MANDEL):
        a[:, i, j] = a[:, j, i] = v[:, k] / (_SQRT2 if k >= 3 else 1.0)
    return a
