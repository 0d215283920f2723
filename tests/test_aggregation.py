"""Light nodes tied to their neighbours (``light_nodes = "aggregate"``, core/aggregation.py)."""

import numpy as np
import pytest
from conftest import rectangle
from dolfinx import mesh
from mpi4py import MPI
from test_grid import random_points

import dolfin_mpm as dm
from dolfin_mpm.core.locate import basis_at, locate
from dolfin_mpm.explicit.step import p2g


def scattered(grid, n=60, seed=5):
    """A sparse cloud of stressed, moving points: many nodes hold a sliver of a point's mass."""
    rng = np.random.default_rng(seed)
    g = grid.gdim
    inner = np.r_[[1.0] * g, [0.0] * (3 - g)]  # the cloud keeps off the boundary
    x = random_points(grid, n, seed=seed) * 0.8 * inner + 0.1 * inner
    P = dm.Particles(x, rng.normal(size=(n, g)), np.full(n, 0.1), np.full(n, 1e-4))
    sigma = rng.normal(scale=1e3, size=(n, 3, 3))
    P.sigma = sigma + sigma.transpose(0, 2, 1)
    cells, _ = locate(grid, P.x, P.cell)
    P.keep(cells >= 0)  # this rank's (under MPI the cloud spans its part's bounding box)
    return P


def test_light_nodes_move_their_mass_and_momentum_to_masters_in_shares(unit_grid):
    P = scattered(unit_grid)
    solver = dm.Solver(unit_grid, P, dm.LinearElastic(1e6, 0.3, 1000.0), courant=0.5, light_nodes="aggregate")
    cells, N = locate(unit_grid, P.x, P.cell)
    nodal = p2g(solver.model, P, basis_at(unit_grid, cells, N), dt=solver.state.dt)
    agg, comm = nodal.aggregation, unit_grid.comm
    assert agg is not None and comm.allreduce(len(agg.light), MPI.SUM) > 0
    owned = slice(0, unit_grid.num_owned_nodes)
    lumped = unit_grid.mass.x.array  # as assembled, before the ties
    total = lambda a: comm.allreduce(a[owned].sum(axis=0), MPI.SUM)  # noqa: E731
    assert np.isclose(total(nodal.mass), total(lumped), rtol=1e-13)
    assert np.allclose(total(nodal.momentum), total(unit_grid.momentum.x.array.reshape(-1, 2)), rtol=1e-12)
    assert np.all(nodal.mass[agg.light] == 0.0) and np.all(nodal.inv_mass[agg.light] == 0.0)
    sums = np.bincount(agg.rows, weights=agg.shares, minlength=len(agg.light))
    assert np.allclose(sums, 1.0, rtol=1e-14) and np.all(agg.shares > 0.0)
    assert not np.isin(agg.masters, agg.light).any()  # a master is no light node
    v = np.tile([0.3, -0.7], (unit_grid.num_nodes, 1))
    agg.extend(v)  # a uniform velocity stays uniform
    assert np.allclose(v, [0.3, -0.7], rtol=1e-14)


@pytest.mark.parametrize("gdim", [2, 3])
def test_aggregated_steps_conserve_momentum(unit_grid, gdim):
    if gdim == 3:
        unit_grid = dm.Grid(mesh.create_unit_cube(MPI.COMM_WORLD, 4, 4, 4))
    P = scattered(unit_grid)
    solver = dm.Solver(unit_grid, P, dm.LinearElastic(1e6, 0.3, 1000.0), courant=0.5, light_nodes="aggregate")
    cells, N = locate(unit_grid, P.x, P.cell)
    tied = p2g(solver.model, P, basis_at(unit_grid, cells, N), dt=solver.state.dt).aggregation
    assert solver.comm.allreduce(0 if tied is None else len(tied.light), MPI.SUM) > 0
    p0 = solver.total_momentum()
    for _ in range(20):
        solver.step()
    scale = solver.comm.allreduce(np.abs(solver.particles.mass[:, None] * solver.particles.v).sum(), MPI.SUM)
    assert np.allclose(solver.total_momentum(), p0, rtol=0, atol=1e-12 * scale)


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="a group whose nodes two ranks own is tied on each")
def test_a_group_with_no_master_moves_rigidly():
    """Two stressed points beside one vertex, alone on the grid: every node of their cell is
    light, and the group moves with its heaviest node, unstrained, where the solve of each
    node changes their stress."""
    grid = dm.Grid(rectangle((0, 0), (1, 1), (4, 4)))

    def run(light_nodes):
        x = np.array([[0.254, 0.503, 0.0], [0.258, 0.506, 0.0]])
        n = len(x)
        P = dm.Particles(x, np.zeros((n, 2)), np.full(n, 10.0), np.full(n, 0.01), id=np.arange(n))
        P.sigma = np.tile(-1e3 * np.eye(3), (n, 1, 1))
        solver = dm.Solver(grid, P, dm.LinearElastic(1e6, 0.3, 1000.0), courant=0.5, light_nodes=light_nodes)
        for _ in range(50):
            solver.step()
        return solver.particles

    own, tied = run("own"), run("aggregate")
    assert np.all(tied.sigma[:, :2, :2] == -1e3 * np.eye(2)) and np.all(tied.v == 0.0)
    assert not np.allclose(own.sigma, tied.sigma, rtol=0.1)  # solved node by node, the points strain


def test_without_light_nodes_the_run_is_the_same(unit_grid):
    def run(light_nodes):
        material = dm.LinearElastic(1e6, 0.3, 1000.0)
        P = dm.seed(unit_grid, material, ppc=4, where=lambda x: x[1] < 0.5 + 1e-9)
        bottom = unit_grid.nodes_where(lambda x: np.isclose(x[1], 0.0))
        solver = dm.Solver(
            unit_grid, P, material, bcs=[dm.FixedBC(bottom)], gravity=(0, -9.81), light_nodes=light_nodes
        )
        for _ in range(20):
            solver.step()
        return solver.particles

    own, tied = run("own"), run("aggregate")
    for name in ("x", "v", "sigma", "volume"):
        assert np.array_equal(getattr(own, name), getattr(tied, name))


def test_light_nodes_option_is_checked():
    with pytest.raises(ValueError, match="light_nodes must be 'own' or 'aggregate'"):
        dm.Solver(dm.Grid(rectangle((0, 0), (1, 1), (2, 2))), dm.Particles(np.zeros((0, 3)), np.zeros((0, 2)),
                  np.zeros(0), np.zeros(0)), dm.LinearElastic(1e6, 0.3, 1.0), light_nodes="tied")  # fmt: skip
