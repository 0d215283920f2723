"""Vectorised algebra on stacks of small tensors, ``shape=(n, 3, 3)`` (particle axis first).

Arguments may have any memory layout. The functions compute on component-first copies
(each component one contiguous array over the particles, several times faster in numpy
than strided access) and return particle-first *views* of component-first memory, so that
chained calls copy nothing.
"""

import numpy as np

__all__ = [
    "MANDEL_DEVIATORIC",
    "MANDEL_IDENTITY",
    "component_first",
    "component_view",
    "deviator",
    "equivalent_stress",
    "from_mandel",
    "invariants",
    "particle_first",
    "to_mandel",
]

# Mandel order: (xx, yy, zz, sqrt2 yz, sqrt2 xz, sqrt2 xy).
_MANDEL = ((0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1))
_SQRT2 = np.sqrt(2.0)
#: The identity as a Mandel vector and the deviatoric projector as a Mandel matrix.
MANDEL_IDENTITY = np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])
MANDEL_DEVIATORIC = np.eye(6) - np.outer(MANDEL_IDENTITY, MANDEL_IDENTITY) / 3.0


def component_first(a: np.ndarray) -> np.ndarray:
    """Contiguous ``shape=(..., n)`` array of ``a.shape=(n, ...)`` (no copy when already so)."""
    return np.ascontiguousarray(component_view(a))


def component_view(a: np.ndarray) -> np.ndarray:
    """The ``shape=(..., n)`` view of ``a.shape=(n, ...)``, contiguous or not."""
    return a.transpose(_ROLL_BACK[a.ndim])


def particle_first(c: np.ndarray) -> np.ndarray:
    """The ``shape=(n, ...)`` view of a component-first array."""
    return c.transpose(_ROLL_FRONT[c.ndim])


# The axes of both moves by the array's rank (np.moveaxis's checks cost more than these views).
_ROLL_BACK = {d: (*range(1, d), 0) for d in range(1, 6)}
_ROLL_FRONT = {d: (d - 1, *range(d - 1)) for d in range(1, 6)}


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
