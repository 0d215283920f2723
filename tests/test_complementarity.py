"""The paper's law as a complementarity problem: GMRES, the semismooth Newton solve, the apex.

The point-level cases use the cloud of ``test_nonlocal_law``: a lattice with a band of
overstressed points around the cone.
"""

import numpy as np
import pytest
from dolfinx import mesh
from mpi4py import MPI
from test_nonlocal_law import DT, SAND, cloud

import dolfin_mpm as dm
from dolfin_mpm.averaging import NonlocalAverage
from dolfin_mpm.averaging.complementarity import gmres, solve_rates
from dolfin_mpm.materials import DruckerPragerViscoplastic
from dolfin_mpm.materials.base import Trial

COMM = MPI.COMM_SELF


def solve(trial, average, material=SAND, u0=None, tol=1e-13):
    u0 = np.zeros(len(trial.q)) if u0 is None else u0
    return solve_rates(average, lambda u: material.increment_of_rate(trial, u, DT), u0, COMM, tol)


def averaged(x, volume):
    average = NonlocalAverage(0.1, "wendland")
    average.update(x, volume, np.arange(len(x)))
    return average


def test_gmres_solves_a_nonsymmetric_system():
    rng = np.random.default_rng(3)
    A = np.eye(40) + 0.3 * rng.standard_normal((40, 40)) / np.sqrt(40)
    b = rng.standard_normal(40)
    x, k = gmres(lambda v: A @ v, b, COMM, rtol=1e-12)
    assert np.linalg.norm(A @ x - b) <= 1e-10 * np.linalg.norm(b) and k <= 40
    x, k_loose = gmres(lambda v: A @ v, b, COMM, rtol=1e-2)
    assert np.linalg.norm(A @ x - b) <= 1e-2 * np.linalg.norm(b) and k_loose < k


def test_rates_are_complementary_to_the_averaged_increments():
    x, volume, trial = cloud()
    average = averaged(x, volume)
    d, u, stats = solve(trial, average)
    delta, _ = SAND.increment_of_rate(trial, u, DT)
    r = d - delta
    assert stats["converged"]  # |min(u, s r)| <= 1e-13
    assert u.min() >= 0.0 and r.min() >= -1e-12 and np.abs(r[u > 0.0]).max() <= 1e-12
    assert 0 < np.count_nonzero(u) < len(u)  # some points flow, some do not


def test_the_solution_does_not_depend_on_the_first_guess():
    x, volume, trial = cloud(2)
    average = averaged(x, volume)
    d0, u0, _ = solve(trial, average)
    rng = np.random.default_rng(4)
    d1, u1, stats = solve(trial, average, u0=1e-3 * rng.random(len(x)))
    assert stats["converged"]
    assert np.abs(d1 - d0).max() <= 1e-9 * d0.max() and np.abs(u1 - u0).max() <= 1e-9 * u0.max()


def test_a_point_crossing_the_apex_changes_the_answer_continuously():
    """Points at the apex are stress free and take the rate their neighbourhood needs: the same
    answer as points an epsilon inside the cone, not a jump."""
    x, volume, trial = cloud(5)
    patch = np.hypot(x[:, 0] - 0.5, x[:, 1] - 0.5) < 0.08  # a few points in the band
    results = []
    for p_patch in (-1.0, 1e-3):  # just beyond and just inside the apex [Pa]
        p = trial.p.copy()
        p[patch] = p_patch
        t = Trial(p, trial.s, trial.q)
        d, u, stats = solve(t, averaged(x, volume))
        assert stats["converged"]
        results.append((d, u))
        q_end = np.maximum(trial.q - 2.0 * SAND.G * d, 0.0)
        assert np.all(q_end[patch] <= 1e-6 * trial.q.max())  # stress free (or as near as y allows)
    (d_out, u_out), (d_in, u_in) = results
    assert np.abs(d_in - d_out).max() <= 1e-5 * d_out.max()
    assert np.abs(u_in - u_out).max() <= 1e-3 * u_out.max()
    # The patch takes a rate well above what it absorbs (q_trial / 2G): its neighbours need it.
    assert u_out[patch].max() > 1.2 * (trial.q[patch] / (2.0 * SAND.G)).max()


@pytest.mark.parametrize("N", [0.5, 2.0])
def test_other_viscosity_exponents_reach_the_law(N):
    sand = DruckerPragerViscoplastic(E=1e6, nu=0.3, rho=1500.0, phi=30.0, gamma=1e3, N=N)
    x, volume, trial = cloud(1)
    average = averaged(x, volume)
    d, u, stats = solve(trial, average, material=sand, tol=1e-12)
    assert stats["converged"]
    y = sand.yield_value(trial)
    over = np.maximum(np.maximum(trial.q - 2.0 * sand.G * d, 0.0) / y - 1.0, 0.0)
    u_end = 1.5 * sand.gamma * DT * over**N  # the rates of the end states
    assert np.abs(u - u_end).max() <= 1e-6 * u.max()
    assert np.abs(d - average(u)).max() <= 1e-9 * d.max()


def test_the_law_without_a_viscous_rate_is_refused():
    grid = dm.Grid(mesh.create_unit_square(MPI.COMM_WORLD, 4, 4))
    soil = dm.VonMises(E=1e6, nu=0.3, rho=1.0, sigma_y=1e3)
    P = dm.seed(grid, soil, ppc=1)
    with pytest.raises(ValueError, match=r"the paper law needs the increment of a given rate.*VonMises"):
        dm.Solver(grid, P, soil, averaging=dm.NonlocalAverage(0.3, "wendland", law="paper"))


def test_the_rate_independent_limit_puts_the_flowing_points_on_their_cone():
    sand = DruckerPragerViscoplastic(E=1e6, nu=0.3, rho=1500.0, phi=30.0, gamma=np.inf, N=2.0)
    x, volume, trial = cloud(1)
    d, u, stats = solve(trial, averaged(x, volume), material=sand, tol=1e-12)
    assert stats["converged"] and np.all(np.isfinite(u))
    q_end = trial.q - 2.0 * sand.G * d
    y = sand.yield_value(trial)
    assert np.abs(q_end - y)[u > 0.0].max() <= 1e-6 * y.max()  # flowing: on the cone
    assert np.all(q_end[u == 0.0] <= y[u == 0.0] * (1 + 1e-9))  # still: inside it
