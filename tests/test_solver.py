"""The explicit step against analytical solutions, and its failure modes."""

import numpy as np
import pytest
from conftest import rectangle
from dolfinx import mesh
from mpi4py import MPI

import dolfin_mpm as dm


def test_free_fall_and_translation_are_exact():
    grid = dm.Grid(rectangle((0, 0), (1, 1), (10, 10)))
    mat = dm.LinearElastic(E=1e4, nu=0.3, rho=1000.0)
    v0, g = np.array([0.3, 0.2]), np.array([0.0, -9.81])
    P = dm.seed(
        grid, mat, ppc=4, where=lambda x: (abs(x[0] - 0.3) < 0.1) & (abs(x[1] - 0.6) < 0.1), velocity=v0
    )
    x0 = P.x.copy()
    solver = dm.Solver(grid, P, mat, gravity=g, dt=1e-3)
    n = 150
    for _ in range(n):
        solver.step()
    # Semi-implicit Euler: v_n = v0 + n dt g, x_n = x0 + n dt v0 + dt^2 g n (n + 1) / 2.
    dt = solver.dt
    assert np.max(np.abs(P.v - (v0 + n * dt * g))) < 1e-10
    assert np.max(np.abs(P.x[:, :2] - (x0[:, :2] + n * dt * v0 + dt**2 * g * n * (n + 1) / 2))) < 1e-10
    assert np.max(np.abs(P.sigma)) < 1e-10 * mat.E  # rigid motion: no stress
    assert np.allclose(P.volume * len(P), 0.04)


def test_column_under_self_weight_k0():
    H, W, rho, g, nu = 1.0, 0.2, 1000.0, 10.0, 0.3
    grid = dm.Grid(rectangle((0, 0), (W, 1.1 * H), (4, 22)))
    mat = dm.LinearElastic(E=1e6, nu=nu, rho=rho)
    P = dm.seed(grid, mat, ppc=4, where=lambda x: x[1] < H)
    bcs = [
        dm.SlipBC(grid.nodes_where(lambda x: np.isclose(x[0], 0.0) | np.isclose(x[0], W)), normal=(1, 0)),
        dm.FixedBC(grid.nodes_where(lambda x: np.isclose(x[1], 0.0))),
    ]
    solver = dm.Solver(grid, P, mat, bcs=bcs, gravity=(0, -g), damping=0.2)
    solver.run(1.0, progress=False)
    assert solver.energies()["kinetic"] < 1e-8 * rho * g * H * H * W
    y, syy, sxx = P.x[:, 1], P.sigma[:, 1, 1], P.sigma[:, 0, 0]
    _, base = np.polyfit(y, syy, 1)
    assert base == pytest.approx(-rho * g * H, rel=0.03)
    interior = y < 0.8 * H
    assert np.mean(sxx[interior] / syy[interior]) == pytest.approx(nu / (1 - nu), rel=0.03)
    # The base reaction carries the weight, damping or not (damping acts on the out-of-balance
    # force only); averaged over steps, as each step's contact force is an impulse / dt.
    base_nodes = grid.nodes_where(lambda x: np.isclose(x[1], 0.0))
    reaction = []
    for _ in range(100):
        solver.step()
        reaction.append(solver.reaction(base_nodes))
    assert np.mean(reaction, axis=0) == pytest.approx([0.0, rho * g * H * W], abs=0.01 * rho * g * H * W)


def test_3d_block_under_gravity():
    msh = mesh.create_box(
        MPI.COMM_WORLD, [np.zeros(3), np.array([0.2, 0.2, 0.4])], [3, 3, 6], mesh.CellType.tetrahedron
    )
    grid = dm.Grid(msh)
    mat = dm.LinearElastic(E=1e5, nu=0.25, rho=1000.0)
    P = dm.seed(grid, mat, ppc=4, where=lambda x: x[2] < 0.2)
    bottom = dm.FixedBC(grid.nodes_where(lambda x: np.isclose(x[2], 0.0)))
    solver = dm.Solver(grid, P, mat, bcs=[bottom], gravity=(0, 0, -9.81))
    m0 = solver.total_mass()
    assert m0 == pytest.approx(1000.0 * 0.2 * 0.2 * 0.2, rel=1e-12)
    solver.run(0.02, progress=False)
    assert solver.total_mass() == pytest.approx(m0, rel=1e-14)
    assert np.all(np.isfinite(P.sigma)) and P.sigma[:, 2, 2].min() < 0.0
    # Impulse: the base can only push, so gravity's -m g t bounds the falling momentum.
    pz = solver.total_momentum()[2]
    assert -m0 * 9.81 * solver.time * (1 + 1e-12) <= pz < 0.0


@pytest.mark.filterwarnings("ignore:dt = .* the stable step:RuntimeWarning")  # free flight, on purpose
def test_particles_leaving_the_grid():
    grid = dm.Grid(rectangle((0, 0), (1, 1), (5, 5)))
    mat = dm.LinearElastic(E=1e3, nu=0.3, rho=1.0)
    make = lambda: dm.seed(grid, mat, ppc=1, where=lambda x: x[1] < 0.3, velocity=(0.0, -1.0))  # noqa: E731
    with pytest.raises(dm.SimulationError, match=r"step \d+, t = .* particle \d+ left the grid"):
        dm.Solver(grid, make(), mat, dt=0.01).run(1.0, progress=False)
    out = dm.Sink("outlet")
    P = make()
    m0, n0 = P.mass.sum(), len(P)
    solver = dm.Solver(grid, P, mat, dt=0.01, sinks=[out], on_exit="outlet")
    solver.run(0.5, progress=False)
    assert out.count == n0 and len(P) == 0
    assert out.mass == pytest.approx(m0, rel=1e-14)
    assert out.momentum[1] == pytest.approx(-m0, rel=1e-12)


def falling_into_a_sink() -> tuple[dm.Solver, dm.Sink]:
    """An elastic block in the upper half of a unit square, falling into a sink below y = 0.4."""
    grid = dm.Grid(rectangle((0, 0), (1, 1), (5, 5)))
    mat = dm.LinearElastic(E=1e3, nu=0.3, rho=1.0)
    P = dm.seed(grid, mat, ppc=4, where=lambda x: x[1] > 0.5)
    sink = dm.Sink("catch", region=lambda x: x[1] < 0.4)
    return dm.Solver(grid, P, mat, gravity=(0, -10.0), dt=1e-3, sinks=[sink]), sink


def test_region_sink_records_history():
    solver, sink = falling_into_a_sink()
    m0 = solver.total_mass()
    solver.run(0.3, progress=False)
    assert 0 < sink.mass < m0
    assert solver.total_mass() + sink.mass == pytest.approx(m0, rel=1e-14)
    times, masses = np.array(sink.history).T
    assert np.all(np.diff(times) > 0) and np.all(np.diff(masses) > 0)


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
def test_non_finite_state_stops_with_step_and_particle():
    grid = dm.Grid(rectangle((0, 0), (1, 1), (5, 5)))
    mat = dm.LinearElastic(E=1e3, nu=0.3, rho=1.0)
    P = dm.seed(grid, mat, ppc=1)
    P.sigma[7, 0, 0] = np.nan
    with pytest.raises(dm.SimulationError, match=r"step 1, .*particle \d+ at x = .* has a non-finite stress"):
        dm.Solver(grid, P, mat).step()


@pytest.mark.parametrize(
    "kwargs, name",
    [({"dt": 0.0}, "dt"), ({"dt": -1.0}, "dt"), ({"courant": 1.5}, "courant"), ({"flip": 1.2}, "flip"),
     ({"damping": 1.0}, "damping"), ({"damping_mean_time": 0.0}, "damping_mean_time"),
     ({"damping_mean_time": float("nan")}, "damping_mean_time"), ({"scheme": "USF"}, "scheme"),
     ({"on_exit": "drain"}, "on_exit"),
     ({"gravity": (0, 0, 1)}, "gravity")],
)  # fmt: skip
def test_bad_solver_input(kwargs, name):
    grid = dm.Grid(rectangle((0, 0), (1, 1), (2, 2)))
    mat = dm.LinearElastic(E=1e3, nu=0.3, rho=1.0)
    with pytest.raises(ValueError, match=rf"^{name} must"):
        dm.Solver(grid, dm.seed(grid, mat, ppc=1), mat, **kwargs)


def test_automatic_time_step():
    grid = dm.Grid(rectangle((0, 0), (1, 1), (4, 4)))
    mat = dm.LinearElastic(E=1e6, nu=0.3, rho=1500.0)
    solver = dm.Solver(grid, dm.seed(grid, mat, ppc=1), mat, courant=0.4)
    h = 0.25 / np.sqrt(2)  # height of a right isosceles triangle with legs 0.25
    assert solver.dt == pytest.approx(0.4 * h / mat.p_wave_speed(), rel=1e-12)


def test_the_step_fits_an_interval_and_only_before_the_first_step():
    grid = dm.Grid(rectangle((0, 0), (1, 1), (4, 4)))
    mat = dm.LinearElastic(E=1e6, nu=0.3, rho=1500.0)
    solver = dm.Solver(grid, dm.seed(grid, mat, ppc=1), mat, courant=0.4)
    stable = solver.dt
    solver.fit_step(0.01)
    k = round(0.01 / solver.dt)
    assert solver.dt == 0.01 / k and stable * k / (k + 1) < solver.dt <= stable  # the longest that fits
    solver.fit_step(0.01)
    assert solver.dt == 0.01 / k  # fits already: unchanged
    solver.fit_step(0.5 * stable)
    assert solver.dt == 0.5 * stable  # an interval below the step: one step each
    with pytest.raises(ValueError, match="interval"):
        solver.fit_step(-1.0)
    solver.step()
    with pytest.raises(RuntimeError, match="at step 1; fit the step before the first"):
        solver.fit_step(0.01)


@pytest.mark.parametrize("mu", [0.2, 0.5])
def test_block_sliding_on_a_frictional_floor_decelerates_at_mu_g(mu):
    grid = dm.Grid(rectangle((0, 0), (1.0, 0.1), (40, 4)))
    mat = dm.LinearElastic(E=1e6, nu=0.3, rho=1000.0)
    P = dm.seed(grid, mat, ppc=4, where=lambda x: (x[0] < 0.3) & (x[1] < 0.05), velocity=(1.0, 0.0))
    floor = dm.FrictionalWall(grid.nodes_where(lambda x: np.isclose(x[1], 0.0)), normal=(0, -1), mu=mu)
    g = 9.81
    # Start from the geostatic state so that the normal force is the weight from the first step.
    P.sigma[:, 1, 1] = -mat.rho * g * (0.05 - P.x[:, 1])
    P.sigma[:, 0, 0] = P.sigma[:, 2, 2] = P.sigma[:, 1, 1] * mat.nu / (1 - mat.nu)
    solver = dm.Solver(grid, P, mat, bcs=[floor], gravity=(0, -g))
    m = solver.total_mass()
    times, speeds = [], []
    while solver.time < 0.15:
        solver.step()
        times.append(solver.time)
        speeds.append(solver.total_momentum()[0] / m)
    deceleration = -np.polyfit(times, speeds, 1)[0]
    assert deceleration == pytest.approx(mu * g, rel=0.03)


def test_stage_times_do_not_overlap_and_add_up_to_the_step(monkeypatch):
    """Each instant of a step is charged to exactly one stage: with a clock that ticks once per
    reading, the stages sum to the readings after the first, and only known stages appear."""
    from dolfin_mpm.explicit import timer
    from dolfin_mpm.explicit.step import STAGES

    grid = dm.Grid(rectangle((0, 0), (1, 1), (4, 4)))
    mat = dm.DruckerPragerViscoplastic(E=1e6, nu=0.3, rho=1500.0, phi=30.0, gamma=1e3)
    solver = dm.Solver(
        grid, dm.seed(grid, mat, ppc=4), mat, gravity=(0, -9.81), averaging=dm.NonlocalAverage(0.3)
    )
    ticks = iter(range(10**6))
    monkeypatch.setattr(timer.time, "perf_counter", lambda: float(next(ticks)))
    solver.step()
    readings = next(ticks)
    assert set(solver.timings) <= set(STAGES) and {"neighbours", "averaging", "convergence"} <= set(
        solver.timings
    )
    assert solver.timer.total == readings - 1
