"""The solver's fixed-point loop with non-local averaging, on a small granular column collapse."""

import numpy as np
import pytest
from conftest import rectangle

import dolfin_mpm as dm

SAND = {"E": 1e6, "nu": 0.3, "rho": 1500.0, "phi": 30.0, "gamma": 1e3}


def collapse(averaging, steps=150, halves=False, **kwargs):
    grid = dm.Grid(rectangle((0, 0), (0.3, 0.15), (30, 15)))
    sand = dm.DruckerPragerViscoplastic(**SAND)
    P = dm.seed(grid, sand, ppc=4, where=lambda x: (x[0] < 0.1) & (x[1] < 0.1))
    floor = grid.nodes_where(lambda x: np.isclose(x[1], 0.0))
    wall = grid.nodes_where(lambda x: np.isclose(x[0], 0.0))
    bcs = [dm.FrictionalWall(floor, normal=(0, -1), mu=0.4), dm.SlipBC(wall, normal=(1, 0))]
    materials = sand
    if halves:  # the same sand as two materials, the upper half the second
        materials = [sand, dm.DruckerPragerViscoplastic(**SAND)]
        P.material[P.x[:, 1] > 0.05] = 1
    solver = dm.Solver(grid, P, materials, bcs=bcs, gravity=(0, -9.81), averaging=averaging, **kwargs)
    for _ in range(steps):
        solver.step()
    return solver


def test_zero_radius_is_the_local_model():
    local = collapse(None, steps=60)
    zero = collapse(dm.NonlocalAverage(0.0), steps=60)
    assert np.array_equal(local.particles.sigma, zero.particles.sigma)
    assert zero.fixed_point["steps"] == 0  # r = 0 switches the loop off


def test_averaging_over_several_materials_is_that_of_one():
    """The step groups particles by material for the return mapping and averages over all: the
    same sand declared as two materials takes the single material's steps bit for bit."""
    one = collapse(dm.NonlocalAverage(0.02), steps=40)
    two = collapse(dm.NonlocalAverage(0.02), steps=40, halves=True)
    assert 0 < two.particles.material.sum() < len(two.particles)
    assert two.fixed_point == one.fixed_point and one.fixed_point["iterations"] > 40
    for name in ("x", "v", "sigma", "volume"):
        assert np.array_equal(getattr(two.particles, name), getattr(one.particles, name))
    for name, a in one.particles.state.items():
        assert np.array_equal(two.particles.state[name], a)


def test_first_iterate_is_the_explicit_step():
    # A radius below the particle spacing averages nothing; one iterate is the local step.
    local = collapse(None, steps=40)
    one = collapse(dm.NonlocalAverage(1e-4), steps=40, fixed_point_max_iter=1, extrapolation=0)
    assert one.fixed_point["unconverged"] == 40
    for name in ("x", "v", "sigma", "volume"):
        a, b = getattr(one.particles, name), getattr(local.particles, name)
        assert np.abs(a - b).max() <= 1e-12 * np.abs(b).max()


def test_fixed_point_converges_to_the_non_local_law():
    solver = collapse(dm.NonlocalAverage(0.02, "cubic"))
    P, mat, avg = solver.particles, solver.materials[0], solver.averaging
    stats = solver.fixed_point
    assert stats["unconverged"] == 0 and stats["max_iterations"] <= 5
    assert stats["iterations"] > stats["steps"]  # the loop did iterate
    de = P.state["eps_vp_rate"] * solver.dt
    de_bar = P.state["eps_vp_rate_nonlocal"] * solver.dt
    assert de.max() > 0.0  # the column is flowing
    # The stored non-local increment is the average of the local ones ...
    assert np.allclose(avg(de), de_bar, rtol=1e-12, atol=0)
    # ... no tension, no point stronger than its own law q <= m p (1 + 2/3 e_vp / gamma) ...
    assert np.all(np.isfinite(P.sigma))
    p, q = dm.materials.tensor.invariants(P.sigma)
    strength = mat.m * p * (1.0 + (2.0 / 3.0) * P.state["eps_vp_rate"] / mat.gamma)
    assert np.all(p >= 0.0) and np.all(q <= strength * (1 + 1e-9) + 1e-9)
    # ... and points dragged into flow by their neighbours sit below it.
    dragged = (de_bar > 1.5 * de) & (p > 0.0)
    assert dragged.sum() > 10 and np.all(q[dragged] < strength[dragged])


def test_extrapolated_first_iterate_reaches_the_same_fixed_point_sooner():
    runs = {
        (order, tol): collapse(dm.NonlocalAverage(0.02), steps=80, extrapolation=order, fixed_point_tol=tol)
        for order in (0, 1, 2)
        for tol in (1e-3, 1e-8)
    }
    its = {key: s.fixed_point["iterations"] for key, s in runs.items()}
    assert its[2, 1e-3] < its[1, 1e-3] < its[0, 1e-3]
    for order in (1, 2):  # a tight loop: the same stresses and positions whatever the start
        for name in ("sigma", "x"):
            a, b = getattr(runs[order, 1e-8].particles, name), getattr(runs[0, 1e-8].particles, name)
            assert np.abs(a - b).max() <= 1e-7 * np.abs(b).max()


@pytest.mark.parametrize(
    "kwargs, name",
    [({"fixed_point_tol": 0.0}, "fixed_point_tol"), ({"fixed_point_max_iter": 0}, "fixed_point_max_iter"),
     ({"relaxation": 0.0}, "relaxation"), ({"anderson_depth": -1}, "anderson_depth"),
     ({"extrapolation": 3}, "extrapolation"), ({"extrapolation": 1.5}, "extrapolation")],
)  # fmt: skip
def test_bad_loop_settings(kwargs, name):
    with pytest.raises(ValueError, match=rf"^{name} must"):
        collapse(dm.NonlocalAverage(0.02), steps=0, **kwargs)


def test_averaging_needs_a_split_material():
    grid = dm.Grid(rectangle((0, 0), (1, 1), (2, 2)))
    mat = dm.LinearElastic(1e3, 0.3, 1.0)
    with pytest.raises(ValueError, match="averaging needs"):
        dm.Solver(grid, dm.seed(grid, mat, ppc=1), mat, averaging=dm.NonlocalAverage(0.1))


def test_overnonlocal_mix_beyond_its_bound_stops_naming_the_point():
    """r = 20 mm spans ~6 spacings: a point's own share A_ii ~ 0.02, so m = 3 gives it a negative
    own weight in the mix; the first step stops, naming the point and the bound."""
    law = dm.NonlocalLaw("overnonlocal", 3.0)
    expected = (
        r"step 0, .*law 'overnonlocal' with m = 3 may have no unique solution.*particle \d+ at x = .*"
        r"m must be below 1 / \(1 - A_ii\) = 1\.0"
    )
    with pytest.raises(dm.SimulationError, match=expected):
        collapse(dm.NonlocalAverage(0.02, "wendland", law=law), steps=1)
