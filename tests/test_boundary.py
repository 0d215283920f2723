"""Nodal boundary conditions: prescribed velocities."""

import numpy as np
import pytest
from conftest import rectangle

import dolfin_mpm as dm


def test_velocity_bc_sets_components_and_leaves_nan_free():
    v = np.arange(12.0).reshape(6, 2)
    dm.VelocityBC([1, 4], (0.5, np.nan)).apply(v)
    assert np.array_equal(v[[1, 4]], [[0.5, 3.0], [0.5, 9.0]])
    dm.VelocityBC([0, 2], [[1.0, 2.0], [np.nan, 4.0]]).apply(v)
    assert np.array_equal(v[[0, 2]], [[1.0, 2.0], [4.0, 4.0]])
    assert np.array_equal(v[[3, 5]], [[6.0, 7.0], [10.0, 11.0]])  # other nodes untouched


def test_velocity_bc_bad_shape():
    with pytest.raises(ValueError, match=r"^velocity must have shape"):
        dm.VelocityBC([0, 1, 2], np.zeros((2, 2)))


def test_driven_grid_carries_the_particles_at_the_prescribed_speed():
    grid = dm.Grid(rectangle((0, 0), (1, 1), (8, 8)))
    mat = dm.LinearElastic(E=1e4, nu=0.3, rho=1000.0)
    P = dm.seed(grid, mat, ppc=4, where=lambda x: (abs(x[0] - 0.5) < 0.2) & (abs(x[1] - 0.5) < 0.2))
    x0 = P.x.copy()
    everywhere = dm.VelocityBC(grid.nodes_where(lambda x: np.full(x.shape[1], True)), (0.2, -0.1))
    solver = dm.Solver(grid, P, mat, bcs=[everywhere], gravity=(0, -9.81))
    for _ in range(50):
        solver.step()
    assert np.allclose(P.x[:, :2] - x0[:, :2], np.array([0.2, -0.1]) * solver.time, rtol=0, atol=1e-12)
    assert np.abs(P.sigma).max() < 1e-9 * mat.E  # rigid motion: no stress
