"""The explicit step's stability estimate: exact inside a filled mesh, blind to light nodes."""

import numpy as np
from conftest import rectangle

import dolfin_mpm as dm
from dolfin_mpm.explicit.stability import stability_ratio

MAT = dm.LinearElastic(E=1e6, nu=0.3, rho=1500.0)


def test_inside_a_filled_mesh_the_estimate_is_the_right_triangles_value():
    grid = dm.Grid(rectangle((0, 0), (1, 1), (10, 10)))
    solver = dm.Solver(grid, dm.seed(grid, MAT, ppc=4), MAT, courant=0.5)
    e = stability_ratio(solver)
    # Points whose three nodes have full patches: k_I / m_I = (6 + 4 sqrt 2) c^2 / h^2, and the
    # step is courant h_min / c with h_min = h / sqrt 2 on right triangles.
    nodes = grid.cell_dofs[solver.particles.cell]
    x = grid.node_x[nodes][..., :2]
    inside = np.all((x > 1e-9) & (x < 1.0 - 1e-9), axis=(1, 2))
    assert inside.sum() > 200
    assert np.allclose(e[inside], (6 + 4 * np.sqrt(2)) / 8 * 0.5**2, rtol=1e-12)
    assert e.max() < 1.0  # the automatic step is stable by the bound, at the edges too
    assert np.allclose(stability_ratio(solver, 0.5 * solver.dt), 0.25 * e)


def test_a_point_alone_in_its_cell_has_the_same_estimate_wherever_it_sits():
    grid = dm.Grid(rectangle((0, 0), (1, 1), (4, 4)))
    volume = 1e-3
    P = dm.Particles(np.array([[0.3, 0.1, 0.0]]), np.zeros((1, 2)), np.array([MAT.rho * volume]), [volume])
    solver = dm.Solver(grid, P, MAT, dt=1e-4)
    cell = grid.cell_dofs[0]
    corners = grid.node_x[cell][:, :2]
    values = []
    for bary in ([1 / 3, 1 / 3, 1 / 3], [0.998, 0.001, 0.001], [0.5, 0.4999, 0.0001]):
        P.x[0, :2] = np.asarray(bary) @ corners  # near a vertex: two of its nodes are light
        P.cell[:] = -1
        values.append(stability_ratio(solver)[0])
    gsum = np.linalg.norm(grid.grad_N[0], axis=-1).sum()
    expected = 0.25 * solver.dt**2 * MAT.p_wave_speed() ** 2 * gsum**2  # V M (sum |grad N|)^2 / m
    assert np.allclose(values, expected, rtol=1e-9)
