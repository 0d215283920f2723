"""How close each particle is to the explicit step's stability limit, light nodes included.

MUSL with FLIP advances the particle velocities, ``v_p += dt sum_I N_Ip (F_I - R_I) / m_I``,
with the stresses from the nodal velocities re-mapped from the particles. About an elastic
state the particle velocities follow the symplectic Euler step of ``d2v/dt2 = -A v`` with::

    A_pr = sum_I N_Ip / m_I  sum_J K_IJ  N_Jr m_r / m_J,

``K`` the stiffness of the particles' P-wave moduli ``M = lambda + 2G``; it is stable while
``dt^2 omega^2 <= 4`` for the largest eigenvalue ``omega^2`` of ``A``. Gershgorin's theorem on
the rows of ``A``, with ``sum_r N_Jr m_r = m_J`` and ``|K_IJ| <= sum_c S_c |grad N_I| |grad N_J|``
over the cells c they share (``S_c``: ``V_p M_p`` summed over the cell's points; the scalar
wave estimate), bounds each particle's row::

    omega_p^2 <= sum_I N_Ip k_I / m_I,   k_I = sum_c S_c |grad N_I|_c sum_J |grad N_J|_c.

:func:`stability_ratio` is ``e_p = dt^2 omega_p^2 / 4``; ``e_p <= 1`` at every particle is
sufficient for a stable step. A light node does not make it large, for ``N_Ip / m_I <= 1 / m_p``
whatever the node's mass: a point alone in its cell has the same ``e_p`` wherever it sits in it. Inside a
filled mesh of right triangles, ``e_p = (6 + 4 sqrt 2) / 8 courant^2`` (0.364 at Courant 0.5).
"""

import numpy as np
from mpi4py import MPI

from dolfin_mpm.core.locate import basis_at, locate
from dolfin_mpm.core.transfer import interpolate, scatter

__all__ = ["nodal_stiffness", "stability_ratio"]


def nodal_stiffness(grid, basis, modulus_volume: np.ndarray) -> np.ndarray:
    """Each node's Gershgorin row sum ``k_I`` [N/m] (assembled), ``shape=(num_nodes,)``.

    ``basis``: the P1 basis at the particles; ``modulus_volume``: each particle's ``V_p M_p``
    [N m] (0 for a stress-free point), ``shape=(n,)``.
    """
    S = np.bincount(basis.cells, modulus_volume, minlength=grid.num_cells)
    g = np.linalg.norm(grid.grad_N, axis=-1)  # |grad N| [1/m], (num_cells, gdim + 1)
    rows = g * (S * g.sum(axis=1))[:, None]
    local = np.bincount(grid.cell_dofs.ravel(), rows.ravel(), minlength=grid.num_nodes)
    return grid.assemble(grid.scratch, local).copy()


def stability_ratio(solver, dt: float | None = None) -> np.ndarray:
    """``e_p = dt^2 omega_p^2 / 4`` of each of this rank's particles (stable: all ``<= 1``), ``shape=(n,)``.

    For the solver's particles where they are, with their volumes (the particles' quadrature)
    and the P-wave modulus of each one's material, 0 for a point apart (stress free); ``dt``
    [s]: the solver's step by default. Nodes the step leaves at rest (``mass_tol``) are left out.
    """
    grid, P = solver.grid, solver.particles
    dt = solver.dt if dt is None else float(dt)
    cells, N = locate(grid, P.x, P.cell)
    if np.any(cells < 0):
        raise ValueError(f"stability_ratio: {np.count_nonzero(cells < 0)} particles are outside the grid")
    basis = basis_at(grid, cells, N)
    moduli = np.array([m.rho * m.p_wave_speed() ** 2 for m in solver.model.materials])
    modulus_volume = P.volume * moduli[P.material]
    if "free_volume" in P.state:
        modulus_volume[P.state["free_volume"] > 0.0] = 0.0
    k = nodal_stiffness(grid, basis, modulus_volume)
    m = grid.assemble(grid.scratch, scatter(basis, P.mass)).copy()
    m_max = grid.comm.allreduce(float(m.max(initial=0.0)), MPI.MAX)
    active = m > solver.model.options.mass_tol * m_max
    ratio = np.zeros_like(m)
    ratio[active] = k[active] / m[active]
    return 0.25 * dt * dt * interpolate(basis, ratio[:, None])[:, 0]
