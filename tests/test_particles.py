"""Particle arrays: removal, selection and appending keep every field aligned; the move finds unsound ones."""

import numpy as np
import pytest

import dolfin_mpm as dm
from dolfin_mpm.core.particles import move
from dolfin_mpm.materials.tensor import component_first, particle_first


def make(n, offset=0):
    x = np.zeros((n, 3))
    x[:, 0] = np.arange(n) + offset
    P = dm.Particles(x, np.ones((n, 2)) * np.arange(n)[:, None], np.arange(n) + 1.0, np.ones(n))
    P.id = np.arange(n) + offset
    P.state["eps_vp"] = np.arange(n) * 2.0
    return P


def test_keep_take_extend_keep_fields_aligned():
    P = make(6)
    P.keep(P.id % 2 == 0)
    assert list(P.id) == [0, 2, 4] and len(P) == 3
    for name, a in P.arrays():
        assert a.shape[0] == 3, name
    assert np.array_equal(P.x[:, 0], P.id) and np.array_equal(P.state["eps_vp"], 2.0 * P.id)
    Q = P.take(np.array([2, 0]))
    assert list(Q.id) == [4, 0] and np.array_equal(Q.state["eps_vp"], [8.0, 0.0])
    Q.mass[:] = -1.0  # a copy, not a view
    assert np.all(P.mass > 0)
    P.extend(make(2, offset=10))
    assert list(P.id) == [0, 2, 4, 10, 11]
    assert np.array_equal(P.state["eps_vp"], [0.0, 4.0, 8.0, 0.0, 2.0])
    assert P.sigma.shape == (5, 3, 3) and P.v.shape == (5, 2)


def test_stress_written_component_first_stays_so():
    """The kernels write the stress component-first; removing, taking and appending particles
    keeps that layout (a transposed copy would cost one at every use)."""
    from dolfin_mpm.materials.tensor import component_first, particle_first

    P, Q = make(6), make(3, offset=6)
    values = np.arange(9 * 9.0).reshape(9, 3, 3)
    P.sigma, Q.sigma = (particle_first(component_first(v)) for v in (values[:6], values[6:]))
    in_place = lambda a: np.shares_memory(component_first(a), a)  # noqa: E731
    P.keep(P.id != 1)
    assert np.array_equal(P.sigma, values[[0, 2, 3, 4, 5]]) and in_place(P.sigma)
    taken = P.take(np.array([3, 0]))
    assert np.array_equal(taken.sigma, values[[4, 0]]) and in_place(taken.sigma)
    P.extend(Q)
    assert np.array_equal(P.sigma, values[[0, 2, 3, 4, 5, 6, 7, 8]]) and in_place(P.sigma)
    assert np.array_equal(P.id, [0, 2, 3, 4, 5, 6, 7, 8])


def test_the_solver_numbers_particles_without_an_id_and_keeps_the_others():
    from conftest import rectangle

    grid = dm.Grid(rectangle((0, 0), (1, 1), (2, 2)))
    mat = dm.LinearElastic(E=1e3, nu=0.3, rho=1.0)
    P = dm.seed(grid, mat, ppc=1)
    assert np.all(P.id == -1)  # not numbered until a solver takes them
    P.id[:2] = [40, 7]
    dm.Solver(grid, P, mat)
    assert list(P.id[:2]) == [40, 7]
    assert list(P.id[2:]) == list(range(41, 41 + len(P) - 2))
    Q = dm.seed(grid, mat, ppc=1)
    Q.id[:2] = 5
    with pytest.raises(ValueError, match=r"particles\.id: .* repeat"):
        dm.Solver(grid, Q, mat)


@pytest.mark.parametrize("gdim", [2, 3])
@pytest.mark.parametrize(
    "spoil", ["none", "stress", "stress_component_first", "velocity", "position", "volume"]
)
def test_move_adds_the_displacements_and_finds_every_unsound_particle(gdim, spoil):
    """The move is ``x += dx`` in the first gdim columns; any non-finite stress component (in
    either layout), velocity or position, or a volume that is not > 0, makes the particles unsound."""
    rng = np.random.default_rng(3)
    n = 37
    P = dm.Particles(rng.random((n, 3)), rng.normal(size=(n, gdim)), np.ones(n), np.full(n, 0.1))
    P.sigma = rng.normal(size=(n, 3, 3))
    if spoil == "stress_component_first":
        P.sigma = particle_first(np.ascontiguousarray(component_first(P.sigma)))
    dx = rng.normal(size=(n, gdim))
    x = P.x.copy()
    x[:, :gdim] += dx
    k = 11
    if spoil.startswith("stress"):
        P.sigma[k, 2, 1] = np.nan
    elif spoil == "velocity":
        P.v[k, -1] = -np.inf
    elif spoil == "position":
        dx[k, 0] = np.inf
        x[k, 0] = np.inf
    elif spoil == "volume":
        P.volume[k] = 0.0
    assert move(P, dx) == (spoil == "none")
    assert np.array_equal(P.x, x)
