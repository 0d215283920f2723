"""The energy balance: what the stress updates release, what the sinks carry away."""

import numpy as np
import pytest
from conftest import rectangle
from test_solver import falling_into_a_sink

import dolfin_mpm as dm


def test_a_perfectly_plastic_point_in_pure_shear_does_the_plastic_work_tau_y_gamma():
    """Past yield, ``s_xy`` stays at ``tau_y = sigma_y / sqrt 3``: each step's plastic work is
    ``tau_y`` times the plastic part of ``2 d_xy dt``; none before yield."""
    mat = dm.VonMises(E=1e6, nu=0.3, rho=1.0, sigma_y=1e3)
    a, dt, n = 0.5, 1e-4, 3
    L = np.zeros((n, 2, 2))
    L[:, 0, 1] = L[:, 1, 0] = a  # d_xy = a, no spin
    sigma, state = np.zeros((n, 3, 3)), {"eps_p": np.zeros(n)}
    tau_y, step = mat.sigma_y / np.sqrt(3.0), 2.0 * mat.G * a * dt  # s_xy's elastic rise per step
    work = []
    for _ in range(40):
        trial = mat.trial(sigma, L, dt)
        de = mat.increment(trial, state, dt)
        sigma = mat.stress(trial, de)
        mat.record(state, de, None, dt)
        work.append(mat.plastic_work_density(trial, sigma)[0])
    first = int(np.ceil(tau_y / step)) - 1  # the step that reaches yield
    assert np.all(np.array(work[:first]) == 0.0) and 0.0 < work[first] < tau_y * 2.0 * a * dt
    # at yield: the trial s_xy = tau_y + step is returned to tau_y, de_p,xy = step / 2G each side
    assert np.allclose(work[first + 1 :], tau_y * 2.0 * a * dt, rtol=1e-12)
    assert np.allclose(sigma[:, 0, 1], tau_y, rtol=1e-12)


def test_an_elastic_block_falling_into_a_sink_balances_its_energy():
    """Nothing dissipates in an elastic fall: the sink carries what the block loses, to the
    time-stepping error."""
    solver, sink = falling_into_a_sink()
    e0 = solver.energies()
    assert e0["dissipated"] == e0["sunk"] == 0.0
    solver.run(0.3, progress=False)
    e = solver.energies()
    assert e["dissipated"] == 0.0 and e["sunk"] == pytest.approx(sink.energy) and sink.count > 0
    lost = e0["total"] - e["total"]  # into the sink, and to the step
    assert lost == pytest.approx(e["sunk"], rel=2e-2) and abs(lost - e["sunk"]) > 0.0


def test_a_collapsing_sand_column_dissipates_most_of_what_it_loses():
    """Drucker-Prager sand slumping on a rough floor: plastic flow takes up the larger part of
    the potential energy lost, and never more than all of it."""
    grid = dm.Grid(rectangle((0, 0), (0.4, 0.2), (20, 10)))
    sand = dm.DruckerPragerViscoplastic(E=1e6, nu=0.3, rho=1500.0, phi=30.0, gamma=1e3)
    P = dm.seed(grid, sand, ppc=4, where=lambda x: (x[0] < 0.1) & (x[1] < 0.1))
    floor = dm.FrictionalWall(grid.nodes_where(lambda x: np.isclose(x[1], 0.0)), normal=(0, -1), mu=0.5)
    wall = dm.SlipBC(grid.nodes_where(lambda x: np.isclose(x[0], 0.0)), normal=(1, 0))
    solver = dm.Solver(grid, P, sand, bcs=[floor, wall], gravity=(0, -9.81))
    e0 = solver.energies()
    solver.run(0.15, progress=False)
    e = solver.energies()
    lost = e0["total"] - e["total"]
    assert lost > 0.0 and 0.5 * lost < e["dissipated"] <= lost
