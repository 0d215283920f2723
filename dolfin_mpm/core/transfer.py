"""Particle-to-grid and grid-to-particle transfers through the P1 basis.

Nodal arrays are ``shape=(num_nodes, k)``; per-particle arrays have the particle axis first;
the basis is component-first (:class:`dolfin_mpm.core.locate.Basis`). The loops over the particles
are compiled C (``transfer.c``), one pass per call: a particle's few nodes and components are
gathered or scattered where numpy built a sparse matrix per step and streamed each component
through it separately.
"""

import ctypes
from pathlib import Path

import numpy as np

from dolfin_mpm import native
from dolfin_mpm.core.locate import Basis
from dolfin_mpm.materials.tensor import component_first, particle_first

__all__ = [
    "gradient",
    "grid_to_particles",
    "internal_force",
    "interpolate",
    "particles_to_grid",
    "replace_volumetric",
    "scatter",
    "volume_ratio",
    "volumetric_sums",
]

_INT, _NODES, _REAL = ctypes.c_int32, native.array(np.int32), native.array(np.float64)
_SIGNATURES = {
    name: (ctypes.c_int64, _INT, _NODES, _REAL, *extra, _REAL, _REAL)
    for name, extra in (
        ("scatter", (_INT,)),
        ("interpolate", (_INT,)),
    )
}
_SIGNATURES["internal_force"] = (ctypes.c_int64, _INT, _NODES, _NODES, _REAL, _REAL, _REAL, _REAL)
_SIGNATURES["gradient"] = (ctypes.c_int64, _INT, _NODES, _NODES, _REAL, _INT, _REAL, _REAL)
_SIGNATURES["volume_ratio"] = (ctypes.c_int64, _INT, _REAL, ctypes.c_double, _REAL)
_SIGNATURES["g2p"] = (
    ctypes.c_int64, _INT, _NODES, _REAL, _REAL, _REAL, _REAL, ctypes.c_double, ctypes.c_double, _INT,
    _REAL, _REAL, _REAL, _REAL,
)  # fmt: skip
_SIGNATURES["volumetric_sums"] = (ctypes.c_int64, _INT, _NODES, *[_REAL] * 6)
_SIGNATURES["volumetric_correct"] = (ctypes.c_int64, _INT, _NODES, *[_REAL] * 4)
_SIGNATURES["p2g"] = (ctypes.c_int64, _INT, _NODES, _REAL, _NODES, *[_REAL] * 8)
_kernels = native.kernels(Path(__file__).with_suffix(".c"), _SIGNATURES)
_UNUSED = np.zeros(1)  # what a kernel is given for an array it does not read


def _as_real(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64)


def scatter(basis: Basis, values: np.ndarray, particles: np.ndarray | None = None) -> np.ndarray:
    """Local nodal sums ``sum_p N_a(x_p) values_p``.

    Args:
        values: ``shape=(n,)`` or ``(n, k)``.
        particles: the indices of the ``n`` particles of ``basis`` that ``values`` belong to,
            ascending (the others' terms are left out); ``None``: all of them.

    Returns:
        ``shape=(num_nodes,)`` or ``(num_nodes, k)``.

    """
    values = _as_real(values)
    k = 1 if values.ndim == 1 else values.shape[1]
    out = np.zeros((basis.num_nodes, *values.shape[1:]))
    dofs, N = basis.dofs, basis.N
    if particles is not None:
        dofs, N = np.take(dofs, particles, axis=1), np.take(N, particles, axis=1)
    _kernels().scatter(N.shape[1], N.shape[0], dofs, N, k, values, out)
    return out


def internal_force(basis: Basis, sigma: np.ndarray, volume: np.ndarray) -> np.ndarray:
    """Nodal internal forces ``R_a = sum_p V_p sigma_p grad N_a(x_p)``, ``shape=(num_nodes, gdim)``.

    Args:
        sigma: Cauchy stress [Pa], ``shape=(n, 3, 3)``.
        volume: particle volumes, ``shape=(n,)``.

    """
    gdim = basis.grad_N.shape[2]
    out = np.zeros((basis.num_nodes, gdim))
    sigma = component_first(np.asarray(sigma, dtype=np.float64))  # no copy of component-first memory
    _kernels().internal_force(
        len(volume), gdim, basis.dofs, basis.cells, basis.grad_N, sigma, _as_real(volume), out
    )
    return out


def particles_to_grid(
    basis: Basis, mass: np.ndarray, v: np.ndarray, sigma: np.ndarray, volume: np.ndarray
) -> tuple[np.ndarray, ...]:
    """Local nodal sums of mass, momentum and internal force, in one pass over the particles.

    Args:
        mass: particle masses [kg], ``shape=(n,)``.
        v: velocities [m/s], ``shape=(n, gdim)``.
        sigma: Cauchy stress [Pa], ``shape=(n, 3, 3)``.
        volume: particle volumes, ``shape=(n,)``.

    Returns:
        ``scatter(basis, mass)``, ``scatter(basis, mass v)`` and ``internal_force(basis, sigma,
        volume)``, term for term: ``shape=(num_nodes,)``, ``(num_nodes, gdim)`` twice.

    """
    gdim = basis.grad_N.shape[2]
    m, p, f = np.zeros(basis.num_nodes), np.zeros((basis.num_nodes, gdim)), np.zeros((basis.num_nodes, gdim))
    sigma = component_first(np.asarray(sigma, dtype=np.float64))
    _kernels().p2g(
        len(mass), gdim, basis.dofs, basis.N, basis.cells, basis.grad_N, _as_real(mass), _as_real(v), sigma,
        _as_real(volume), m, p, f,
    )  # fmt: skip
    return m, p, f


def grid_to_particles(
    basis: Basis,
    v_node: np.ndarray,
    a_node: np.ndarray,
    v_p: np.ndarray,
    dt: float,
    flip: float,
    mass: np.ndarray | None = None,
) -> tuple[np.ndarray, ...]:
    """New particle velocities and displacements from the grid, in one pass over the particles.

    Args:
        v_node, a_node: nodal velocities [m/s] and accelerations [m/s^2], ``shape=(num_nodes, gdim)``.
        v_p: the particles' velocities at the start of the step, ``shape=(n, gdim)``.
        dt: time step [s].
        flip: FLIP fraction in [0, 1]: ``v = flip (v_p + dt a) + (1 - flip) v_grid``.
        mass: particle masses [kg] ``shape=(n,)`` to also return the local nodal sums of the new
            momenta (MUSL's re-map), or ``None``.

    Returns:
        ``v`` and the displacement ``dt v_grid`` with the grid velocity at the particles,
        ``shape=(n, gdim)``, and the nodal momenta ``shape=(num_nodes, gdim)`` (or ``None``).

    """
    n, gdim = v_p.shape
    v, dx = np.empty((n, gdim)), np.empty((n, gdim))
    musl = mass is not None
    momenta = np.zeros((basis.num_nodes, gdim)) if musl else _UNUSED
    _kernels().g2p(
        n, gdim, basis.dofs, basis.N, _as_real(v_node), _as_real(a_node), _as_real(v_p), dt, flip, int(musl),
        _as_real(mass) if musl else _UNUSED, v, dx, momenta,
    )  # fmt: skip
    return v, dx, momenta if musl else None


def interpolate(basis: Basis, nodal: np.ndarray) -> np.ndarray:
    """Values ``sum_a N_a(x_p) nodal_a`` at the particles, ``nodal.shape=(num_nodes, k)`` -> ``(n, k)``."""
    (nn, n), k = basis.N.shape, nodal.shape[1]
    out = np.empty((n, k))
    _kernels().interpolate(n, nn, basis.dofs, basis.N, k, _as_real(nodal), out)
    return out


def gradient(basis: Basis, nodal: np.ndarray) -> np.ndarray:
    """Gradient ``L_ij = sum_a nodal_a,i dN_a/dx_j`` at the particles, ``shape=(n, k, gdim)``.

    The result is a particle-first view of component-first memory; ``k <= 9``.
    """
    if nodal.shape[1] > 9:
        raise ValueError(f"gradient: at most 9 components, got {nodal.shape[1]}")
    gdim, n = basis.grad_N.shape[2], len(basis.cells)
    out = np.empty((nodal.shape[1], gdim, n))
    _kernels().gradient(n, gdim, basis.dofs, basis.cells, basis.grad_N, nodal.shape[1], _as_real(nodal), out)
    return particle_first(out)


def volume_ratio(L: np.ndarray, dt: float) -> np.ndarray:
    """The volume ratio of a step, ``det(I + dt L)``, of velocity gradients ``L`` [1/s].

    ``L.shape=(n, gdim, gdim)`` (as :func:`gradient` gives it: no copy), ``dt`` [s]; ``shape=(n,)``.
    """
    n, gdim = L.shape[:2]
    J = np.empty(n)
    _kernels().volume_ratio(n, gdim, component_first(np.asarray(L, dtype=np.float64)), dt, J)
    return J


def volumetric_sums(basis: Basis, L: np.ndarray, volume: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The traces ``tr L_p`` (``shape=(n,)``) and their local nodal sums ``sum_p N_a V_p tr L_p``.

    ``L``: velocity gradients [1/s] component-first, ``shape=(gdim, gdim, n)``; ``volume``: the
    weights ``V_p``, ``shape=(n,)``. The sums have ``shape=(num_nodes,)``.
    """
    gdim, n = L.shape[0], L.shape[-1]
    tr, vtr, out = np.empty(n), np.empty(n), np.zeros(basis.num_nodes)
    _kernels().volumetric_sums(n, gdim, basis.dofs, basis.N, L, _as_real(volume), tr, vtr, out)
    return tr, out


def replace_volumetric(basis: Basis, tr_node: np.ndarray, tr: np.ndarray, L: np.ndarray) -> None:
    """``L_ii += (sum_a N_a tr_node_a - tr) / gdim`` in place: ``tr L`` becomes ``tr_node`` interpolated.

    ``tr``: the traces of :func:`volumetric_sums`; ``tr_node``: nodal, ``shape=(num_nodes,)``;
    ``L`` component-first, ``shape=(gdim, gdim, n)``, as :func:`volumetric_sums` takes it.
    """
    gdim, n = L.shape[0], L.shape[-1]
    _kernels().volumetric_correct(n, gdim, basis.dofs, basis.N, _as_real(tr_node), tr, L)
