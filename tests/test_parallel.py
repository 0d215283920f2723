"""Particles on DOLFINx's mesh partition; meaningful under ``mpirun -n 2`` (``make test-mpi``),
and true in serial too."""

import functools
import itertools
from contextlib import nullcontext

import dolfin_mpm as dm

# isort: split
import numpy as np
import pytest
from conftest import rectangle
from dolfinx import mesh
from mpi4py import MPI
from scipy.spatial import cKDTree
from test_demos import load

from dolfin_mpm.locate import locate
from dolfin_mpm.parallel import DistributedAverage, migrate

comm = MPI.COMM_WORLD


def test_migration_moves_particles_to_the_owner_and_keeps_totals():
    grid = dm.Grid(rectangle((0, 0), (1, 1), (8, 8), "crossed"))
    mat = dm.LinearElastic(E=1e6, nu=0.3, rho=1000.0)
    P = dm.seed(grid, mat, ppc=4)
    P.id = (comm.exscan(len(P)) or 0) + np.arange(len(P))
    P.v = np.random.default_rng(comm.rank).normal(size=P.v.shape)
    P.state["tag"] = P.id * 2.0  # state travels with its particle
    before = [comm.allreduce(a, MPI.SUM) for a in (len(P), P.mass.sum(), (P.mass[:, None] * P.v).sum(0))]
    # Shift every particle by up to ~3 cells: into ghost cells and beyond the local mesh.
    shift = np.random.default_rng(7 + comm.rank).uniform(-0.4, 0.4, (len(P), 2))
    P.x[:, :2] = np.mod(P.x[:, :2] + shift, 1.0)
    cells, _ = locate(grid, P.x, np.full(len(P), -1, dtype=np.int32))
    migrate(grid, P, cells)
    cells, _ = locate(grid, P.x, P.cell)
    owned = grid.mesh.topology.index_map(2).size_local
    assert np.all((cells >= 0) & (cells < owned)), "every particle in an owned cell of its rank"
    after = [comm.allreduce(a, MPI.SUM) for a in (len(P), P.mass.sum(), (P.mass[:, None] * P.v).sum(0))]
    assert after[0] == before[0]
    assert after[1] == pytest.approx(before[1], rel=1e-14)
    assert after[2] == pytest.approx(before[2], rel=1e-12, abs=1e-12)
    assert np.array_equal(P.state["tag"], P.id * 2.0)
    ids = np.concatenate(comm.allgather(P.id))
    assert np.array_equal(np.sort(ids), np.arange(before[0]))


# r = 0.06 in 3D: more than 8 cubes of side r per particle, the halo's path for sparse clouds.
@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("weight", ["cubic", "constant", "gaussian"])
@pytest.mark.parametrize("radius", [0.15, 0.06])
def test_average_with_halo_equals_the_serial_average(dim, weight, radius):
    rng = np.random.default_rng(3)  # the same cloud on every rank
    n = 600
    x, volume, e = rng.uniform(0.0, 1.0, (n, dim)), rng.uniform(0.5, 1.5, n), rng.normal(size=n)
    ids = np.arange(n)
    serial = dm.NonlocalAverage(radius, weight)
    serial.update(x, volume, ids)
    expected = serial(e)
    # This rank's share: a slab in x, an empty rank 1 of 3 when run on 3 ranks or more.
    slab = np.floor(x[:, 0] * comm.size).astype(int)
    if comm.size > 2:
        slab[slab == 1] = 0  # rank 1 holds none; rank 0 takes its slab
    mine = np.flatnonzero(slab == comm.rank)
    average = DistributedAverage(dm.NonlocalAverage(radius, weight), comm)
    average.update(x[mine], volume[mine], ids[mine])
    assert average(e[mine]) == pytest.approx(expected[mine], rel=1e-12, abs=1e-12)


def silo_run(comm, steps=200, strips=True):
    """Global measures of a short, coarse non-local silo discharge on ``comm``."""
    silo = load("demo_silo")
    solver, gate = silo.build(h=0.025, radius=0.025, comm=comm, strips=strips)
    solver.bcs = [bc for bc in solver.bcs if bc is not gate]  # open at once: particles cross ranks
    for _ in range(steps):
        solver.step()
    e_bar = solver.particles.state["eps_vp_rate_nonlocal"]
    return {
        "particles": solver.num_particles(),
        "discharged": silo.discharged_mass(solver),
        "kinetic": solver.energies()["kinetic"],
        "e_vp_bar_max": comm.allreduce(float(e_bar.max(initial=0.0)), MPI.MAX),
        "iterations": solver.fixed_point["iterations"],
        "migrated": solver.migrated,
    }


@functools.cache
def serial_silo_run():
    return silo_run(MPI.COMM_SELF)


@pytest.mark.parametrize("strips", [True, False])
def test_silo_on_all_ranks_equals_the_serial_run(strips):
    """Strips of equal fill; DOLFINx's partition, across which the particles fall."""
    parallel, serial = silo_run(comm, strips=strips), serial_silo_run()
    assert parallel["discharged"] > 0.0
    if strips:  # the flow is symmetric: (almost) no particle crosses the axis
        assert parallel["migrated"] < 0.01 * parallel["particles"]
    else:
        assert comm.size == 1 or parallel["migrated"] > 0
    assert parallel["particles"] == serial["particles"]
    assert parallel["iterations"] == serial["iterations"]
    for key in ("discharged", "kinetic", "e_vp_bar_max"):
        assert parallel[key] == pytest.approx(serial[key], rel=1e-8), key


def test_silo_demo_on_all_ranks_records_what_the_serial_run_does(tmp_path):
    run = load("demo_silo").run
    quick = dict(h=0.025, radius=0.02, t_end=0.05, t_settle=0.005, progress=False)
    output = comm.bcast(tmp_path, root=0)
    parallel, serial = run(**quick, output=output, comm=comm), run(**quick, comm=MPI.COMM_SELF)
    assert parallel["ranks"] == comm.size and parallel["particles"] == serial["particles"]
    assert abs(parallel["mass_final"] - parallel["mass_initial"]) < 1e-12 * parallel["mass_initial"]
    assert parallel["discharged"][-1] > 0.0
    for key in ("discharged", "profile_e_vp_bar", "profile_v_y", "e_vp_bar_max"):
        assert parallel[key] == pytest.approx(serial[key], rel=1e-8), key
    # All ranks' particles, in any order (ids follow the partition): each at a serial one's place.
    distance, match = cKDTree(serial["x"]).query(parallel["x"])
    assert np.unique(match).size == len(match) and distance.max() < 1e-9
    assert (output / "particles.xdmf").exists()


def test_bad_partition_weight_fails_on_every_rank():
    if comm.size == 1:
        pytest.skip("one rank takes every cell without weighing them")
    with pytest.raises(ValueError, match="weight must be finite and >= 0"):
        dm.partition.create_rectangle(comm, [(0, 0), (1, 1)], (4, 4), weight=lambda x: -x[0])


def test_strips_of_equal_fill_balance_the_silo():
    solver, _ = load("demo_silo").build(h=0.01, comm=comm)
    counts = comm.allgather(len(solver.particles))
    assert sum(counts) == 4800
    assert max(counts) - min(counts) <= 240  # a column: 30 squares, 2 triangles, 4 particles
    grid = solver.grid  # each rank owns one strip, with ghosts on its sides
    x = grid.node_x[grid.cell_dofs[: grid.num_owned_cells], 0].mean(axis=1)
    strips = comm.allgather((x.min(), x.max()))
    assert all(a[1] < b[0] for a, b in itertools.pairwise(strips))
    assert comm.size == 1 or grid.num_cells > grid.num_owned_cells


def falling_block(comm, steps=60, output=None):
    """Momentum and energy of a block falling in a corner of the grid (other ranks: empty)."""
    msh = mesh.create_rectangle(comm, [np.zeros(2), np.ones(2)], [10, 10], mesh.CellType.triangle)
    grid = dm.Grid(msh)
    mat = dm.LinearElastic(E=1e5, nu=0.3, rho=1000.0)
    P = dm.seed(grid, mat, ppc=4, where=lambda x: (x[0] < 0.2) & (x[1] > 0.6) & (x[1] < 0.8))
    floor = dm.FixedBC(grid.nodes_where(lambda x: np.isclose(x[1], 0.0)))
    solver = dm.Solver(grid, P, mat, bcs=[floor], gravity=(0.0, -9.81), dt=1e-3)
    empty = comm.allreduce(int(len(P) == 0))
    with dm.Output(output, comm) if output else nullcontext() as out:
        for _ in range(steps):
            solver.step()
        if out:
            out.write(solver)  # every rank's particles, none on some
    return solver.num_particles(), solver.total_momentum(), solver.energies()["total"], empty


def test_ranks_without_particles_take_part(tmp_path):
    output = comm.bcast(tmp_path, root=0)
    (n, p, e, empty), (n1, p1, e1, _) = falling_block(comm, output=output), falling_block(MPI.COMM_SELF)
    assert comm.size == 1 or empty > 0, "the block should leave a rank empty"
    assert n == n1 > 0
    assert p == pytest.approx(p1, rel=1e-12)
    assert e == pytest.approx(e1, rel=1e-12)


def test_run_with_progress_on_all_ranks(capsys):
    """The progress display counts particles on all ranks (a collective) and shows on rank 0."""
    msh = mesh.create_rectangle(comm, [np.zeros(2), np.ones(2)], [8, 8], mesh.CellType.triangle)
    grid = dm.Grid(msh)
    mat = dm.LinearElastic(E=1e5, nu=0.3, rho=1000.0)
    solver = dm.Solver(grid, dm.seed(grid, mat, ppc=1), mat, dt=1e-3)
    solver.run(0.02, progress=True)
    out, n = capsys.readouterr().out, solver.num_particles()
    assert solver.step_count == 20
    if comm.rank == 0:
        assert f"particles {n}" in out.splitlines()[-1]
    else:
        assert out == ""
