"""Particles on DOLFINx's mesh partition; meaningful under ``mpirun -n 2`` (``make test-mpi``),
and true in serial too."""

import csv
import functools
import itertools
from contextlib import nullcontext
from pathlib import Path
from types import SimpleNamespace

import dolfin_mpm as dm

# isort: split
import h5py
import numpy as np
import pytest
from conftest import rectangle
from dolfinx import mesh
from mpi4py import MPI
from scipy.spatial import cKDTree
from test_checkpoint import SCENARIO, same
from test_demos import load

from dolfin_mpm.app.cli import main
from dolfin_mpm.core.locate import locate
from dolfin_mpm.explicit.step import _check_mix
from dolfin_mpm.parallel.halo import DistributedAverage
from dolfin_mpm.parallel.migration import migrate
from dolfin_mpm.parallel.reduce import max_over_ranks, sum_over_ranks

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


def test_halo_is_kept_while_particles_move_less_than_half_the_skin():
    """Moves, removals and an arrival: always the serial average; the state restores it exactly."""
    rng = np.random.default_rng(4)  # the same cloud and moves on every rank
    n, radius, skin = 800, 0.1, 0.04
    x, volume, e = rng.uniform(0.0, 1.0, (n, 2)), rng.uniform(0.5, 1.5, n), rng.normal(size=n)
    ids = np.arange(n)
    present = np.ones(n, dtype=bool)
    owner = np.minimum((x[:, 0] * comm.size).astype(int), comm.size - 1)
    new_average = lambda: DistributedAverage(dm.NonlocalAverage(radius, "cubic", skin=skin), comm)  # noqa: E731
    average = new_average()

    def step(average):
        mine = np.flatnonzero(present & (owner == comm.rank))
        average.update(x[mine], volume[mine], ids[mine])
        serial = dm.NonlocalAverage(radius, "cubic", skin=0.0)
        serial.update(x[present], volume[present], ids[present])
        expected = np.zeros(n)
        expected[present] = serial(e[present])
        result = average(e[mine])
        assert result == pytest.approx(expected[mine], rel=1e-12, abs=1e-12)
        return result

    step(average)
    for _ in range(4):  # 4 x 0.004 < skin / 2 in all; some particles leave (a sink)
        x += rng.uniform(-0.004, 0.004, x.shape)
        present &= rng.random(n) > 0.02
        step(average)
    assert average.halo_builds == 1
    restored = new_average()
    restored.restore(average.state())
    x += rng.uniform(-0.002, 0.002, x.shape)
    assert np.array_equal(step(restored), step(average))
    assert (average.halo_builds, restored.halo_builds) == (1, 0)  # both kept their halo
    x += 0.03  # more than half the skin: a new halo
    step(average)
    assert average.halo_builds == 2
    # A particle that moves to another rank: a new halo on every rank.
    k = np.flatnonzero(present)[0]
    owner[k] = (owner[k] + 1) % comm.size
    step(average)
    assert average.halo_builds == (3 if comm.size > 1 else 2)
    assert average.rebuilds == average.halo_builds  # the pair list with the halo, not in between


def silo_run(comm, steps=200, partition="strips", law="max", quadrature="particle"):
    """Global measures of a short, coarse non-local silo discharge on ``comm``."""
    silo = load("demo_silo")
    weight = "cubic" if law == "max" else "wendland"
    solver, gate = silo.build(
        h=0.025,
        radius=0.025,
        weight=weight,
        comm=comm,
        partition=partition,
        law=law,
        quadrature=quadrature,
        rebalance=1.0,  # with partition "rebalance": at every check (20 steps)
    )
    solver.bcs = [bc for bc in solver.bcs if bc is not gate]  # open at once: particles cross ranks
    solver.run_until(0.0, steps=steps)  # the run loop: it deals the cells anew where asked
    e_bar = solver.particles.state["eps_vp_rate_nonlocal"]
    return {
        "particles": solver.num_particles(),
        "discharged": silo.discharged_mass(solver),
        "kinetic": solver.energies()["kinetic"],
        "e_vp_bar_max": comm.allreduce(float(e_bar.max(initial=0.0)), MPI.MAX),
        "iterations": solver.fixed_point["iterations"],
        "migrated": solver.migrated,
        "repartitions": solver.repartitions,
    }


@functools.cache
def serial_silo_run(law="max", quadrature="particle"):
    return silo_run(MPI.COMM_SELF, law=law, quadrature=quadrature)


@pytest.mark.parametrize(
    "partition, law, quadrature",
    [
        ("strips", "max", "particle"),
        ("dolfinx", "max", "particle"),
        ("dolfinx", "paper", "particle"),
        ("dolfinx", "overstress", "particle"),
        ("dolfinx", "max", "cell"),
        ("rebalance", "max", "particle"),
    ],
)
def test_silo_on_all_ranks_equals_the_serial_run(partition, law, quadrature):
    """Strips of equal fill; DOLFINx's partition, across which the particles fall; cells dealt
    anew by the particles as they fall."""
    parallel = silo_run(comm, partition=partition, law=law, quadrature=quadrature)
    serial = serial_silo_run(law, quadrature)
    assert parallel["discharged"] > 0.0
    if partition != "dolfinx" and comm.size == 2:  # cut at the axis of a symmetric flow: (almost) no crossing
        assert parallel["migrated"] < 0.01 * parallel["particles"]
    else:
        assert comm.size == 1 or parallel["migrated"] > 0
    if partition == "rebalance" and comm.size > 2:  # the inner strips empty faster: dealt anew
        assert parallel["repartitions"] > 0
    elif partition != "rebalance":
        assert parallel["repartitions"] == 0
    assert parallel["particles"] == serial["particles"]
    assert parallel["iterations"] == serial["iterations"]
    for key in ("discharged", "kinetic", "e_vp_bar_max"):
        assert parallel[key] == pytest.approx(serial[key], rel=1e-8), key


def test_an_inadmissible_over_non_local_mix_stops_every_rank():
    """A point's own weight m A_ii + 1 - m < 0 on some rank: every rank stops, none waits."""
    solver, _ = load("demo_silo").build(
        h=0.025, radius=0.025, weight="wendland", comm=comm, partition="dolfinx", law="overnonlocal", m=5.0
    )
    with pytest.raises(
        dm.SimulationError, match="law 'overnonlocal' with m = 5 may have no unique solution"
    ) as info:
        solver.step()
    assert comm.allreduce(int("m must be below 1 / (1 - A_ii)" in str(info.value))) >= 1  # the point named


def test_the_mix_check_names_the_point_on_its_rank_alone():
    """Only rank 0 holds a point with a negative own weight: every rank stops, rank 0 names it."""
    own = [0.9, 0.1] if comm.rank == 0 else [0.9]  # A_ii: 2 * 0.1 + 1 - 2 < 0 on rank 0 alone
    P = SimpleNamespace(id=np.arange(len(own)) + 10 * comm.rank, x=np.zeros((len(own), 3)))
    state = SimpleNamespace(particles=P, step=7, time=0.1)
    average = SimpleNamespace(own_weight=np.array(own))
    with pytest.raises(dm.SimulationError, match=r"step 7, .*m = 2 may have no unique solution") as info:
        _check_mix(state, dm.NonlocalLaw("overnonlocal", 2.0), average, comm)
    named = "particle 1 at x" in str(info.value)
    assert named == (comm.rank == 0) and comm.allreduce(int(named)) == 1


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


def test_sums_and_maxima_over_ranks_give_every_rank_the_same():
    values = [comm.rank + 1.0, -2.0 * comm.rank]
    total = sum_over_ranks(comm, values)
    n = comm.size
    assert np.array_equal(total, [n * (n + 1) / 2, -float(n * (n - 1))])
    assert total is not values and sum_over_ranks(comm, 2.5).shape == ()
    assert max_over_ranks(comm, float(comm.rank)) == n - 1.0
    assert comm.allgather(total.tolist()) == [total.tolist()] * n


def test_assembly_sums_the_ranks_shares_into_the_owners_and_back():
    """Each rank puts 1 on every node it holds: a node then holds the number of ranks that hold it."""
    grid = dm.Grid(rectangle((0, 0), (1, 1), (4, 4)))
    index_map = grid.V.dofmap.index_map
    glob = index_map.local_to_global(np.arange(grid.num_nodes, dtype=np.int32))
    holders = np.bincount(np.concatenate(comm.allgather(glob)))
    assembled = grid.assemble(grid.scratch, np.ones(grid.num_nodes))
    assert np.array_equal(assembled, holders[glob])
    assert comm.size == 1 or comm.allreduce(int(holders.max()), MPI.MAX) > 1  # some node is shared


def test_bad_partition_weight_fails_on_every_rank():
    if comm.size == 1:
        pytest.skip("one rank takes every cell without weighing them")
    with pytest.raises(ValueError, match="weight must be finite and >= 0"):
        dm.partition.create_rectangle(comm, [(0, 0), (1, 1)], (4, 4), weight=lambda x: -x[0])


@pytest.mark.parametrize("dim", [2, 3])
def test_bisection_by_count_gives_the_same_balanced_partition_each_time(dim):
    """What a scenario's mesh gets on several ranks, so that a checkpoint fits the next run."""
    count = lambda c: np.ones(c.shape[1])  # noqa: E731
    if dim == 2:
        create = lambda: dm.partition.create_rectangle(comm, [(0, 0), (1, 2)], (6, 9), count, diagonal="left")  # noqa: E731
    else:
        create = lambda: dm.partition.create_box(comm, [(0, 0, 0), (1, 1, 2)], (3, 3, 4), count)  # noqa: E731
    grids = [dm.Grid(create()) for _ in range(3)]
    nodes = [g.node_x[: g.num_owned_nodes] for g in grids]
    assert all(np.array_equal(nodes[0], n) for n in nodes[1:])
    owned = comm.allgather(grids[0].num_owned_cells)
    assert sum(owned) == (108 if dim == 2 else 216) and max(owned) - min(owned) <= 6 * dim - 6


def test_strips_of_equal_fill_balance_the_silo():
    solver, _ = load("demo_silo").build(h=0.01, comm=comm, partition="strips")
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


def test_physical_groups_on_all_ranks_are_those_of_one(tmp_path):
    """A body and walls named by gmsh tags: each rank's cells and nodes from DOLFINx's input numbers."""
    from test_scenario import TAGGED, write_tagged_square

    from dolfin_mpm.app import scenario

    folder = comm.bcast(tmp_path, root=0)
    if comm.rank == 0:
        write_tagged_square(folder / "square.msh", n=8)
        (folder / "s.toml").write_text(TAGGED)
    comm.barrier()
    sim = scenario.build(scenario.load(folder / "s.toml"), comm)
    s = sim.solver
    assert s.num_particles() == 4 * 64 and np.all(s.particles.x[:, 1] < 0.5)  # the 64 cells of "sand"
    node_x = s.grid.node_x
    for name, on in (("floor", np.isclose(node_x[:, 1], 0.0)), ("left", np.isclose(node_x[:, 0], 0.0))):
        (bc,) = sim.walls[name]
        assert np.array_equal(np.sort(bc.nodes), np.flatnonzero(on)), name  # owned and ghost nodes


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


def run_and_resume(tmp_path, text: str) -> Path:
    """``text`` run in ``reference`` to its end, and in ``run`` to 0.023 s, then resumed to 0.04 s."""
    folder = comm.bcast(tmp_path, root=0)
    scenario = folder / "fall.toml"
    if comm.rank == 0:
        scenario.write_text(text)
    comm.Barrier()
    quiet = ["--quiet", "--output"]
    assert main(["run", str(scenario), *quiet, str(folder / "reference")]) == 0
    assert main(["run", str(scenario), *quiet, str(folder / "run"), "--set", "time.end=0.023"]) == 0
    assert main(["resume", str(folder / "run"), "--quiet", "--set", "time.end=0.04"]) == 0
    return folder


def test_resume_on_all_ranks_ends_where_the_uninterrupted_run_ends(tmp_path):
    """Each rank's checkpoint carries its halo and pair list: the resumed run is bit-identical."""
    folder = run_and_resume(tmp_path, SCENARIO)
    if comm.rank == 0:
        reference, resumed = (checkpoint_state(folder / f / "checkpoint.h5") for f in ("reference", "run"))
        assert reference["attrs/ranks"] == comm.size
        assert comm.size == 1 or any(k.endswith("nonlocal/halo/send") for k in reference)
        assert reference.keys() == resumed.keys()
        for k in reference:
            assert same(reference[k], resumed[k]), k
        # The largest rank's particle count over the mean at every output, also after the resume;
        # at the end it is the checkpoint's, whose ranks hold their particles' ids.
        counts = [len(reference[f"rank{r}/particles/id"]) for r in range(comm.size)]
        for f in ("reference", "run"):
            rows = list(csv.DictReader(open(folder / f / "history.csv")))
            imbalance = np.array([float(r["imbalance"]) for r in rows])
            assert len(rows) > 10 and np.all(np.isfinite(imbalance))
            assert imbalance[-1] == pytest.approx(max(counts) / np.mean(counts), rel=1e-12)


@pytest.mark.skipif(comm.size == 1, reason="another number of ranks needs several")
def test_resume_on_another_number_of_ranks_continues_to_round_off(tmp_path, capsys):
    """A checkpoint of N ranks resumed on one, and of one resumed on N: the particles go to the
    owners of their cells on the new partition, the pair lists are built anew."""
    import shutil

    from dolfin_mpm.app import scenario
    from dolfin_mpm.app.runner import Runner
    from dolfin_mpm.io import checkpoint

    folder = comm.bcast(tmp_path, root=0)
    path = folder / "fall.toml"
    if comm.rank == 0:
        path.write_text(SCENARIO)
    comm.Barrier()

    def serial(out: Path, end: str, resume: bool = False) -> None:  # on rank 0 alone
        cfg = scenario.load(path, [f"time.end={end}"])
        sim = scenario.build(cfg, MPI.COMM_SELF)
        history = None
        if resume:
            data = checkpoint.read(out / "checkpoint.h5", MPI.COMM_SELF)
            checkpoint.restore(sim, data)
            history = data["history"]
        else:
            out.mkdir()
            (out / "scenario.toml").write_text(SCENARIO)
        Runner(sim, out, history=history, progress=False).run()

    quiet = ["--quiet", "--output"]
    assert main(["run", str(path), *quiet, str(folder / "ranks"), "--set", "time.end=0.04"]) == 0
    assert main(["run", str(path), *quiet, str(folder / "ranks-to-1"), "--set", "time.end=0.022"]) == 0
    if comm.rank == 0:
        serial(folder / "one", "0.04")
        serial(folder / "1-to-ranks", "0.022")
        shutil.copy(folder / "ranks" / "run.json", folder / "1-to-ranks")
        serial(folder / "ranks-to-1", "0.04", resume=True)
    comm.Barrier()
    assert main(["resume", str(folder / "1-to-ranks"), "--set", "time.end=0.04"]) == 0
    out = capsys.readouterr().out
    if comm.rank == 0:
        assert f"written on 1 rank: on {comm.size}, each particle went to the owner of its cell" in out
        last = {f: list(csv.DictReader(open(folder / f / "history.csv")))[-1] for f in
                ("ranks", "ranks-to-1", "one", "1-to-ranks")}  # fmt: skip
        for resumed, reference in (("ranks-to-1", "ranks"), ("1-to-ranks", "one")):
            a, b = last[resumed], last[reference]
            assert float(a["t"]) == float(b["t"]) == 0.04
            assert float(a["discharged"]) > 0.0 and int(a["particles"]) == int(b["particles"])
            for k in ("kinetic", "strain", "potential", "dissipated", "discharged"):
                assert float(a[k]) == pytest.approx(float(b[k]), rel=1e-9), (resumed, k)
        resharded = checkpoint_state(folder / "1-to-ranks" / "checkpoint.h5")
        assert resharded["attrs/ranks"] == comm.size


def test_each_rank_reads_its_own_part_of_a_checkpoint_and_whole_groups_on_another_number(tmp_path):
    """A checkpoint of N ranks: each rank writes and reads its own group; on fewer ranks, rank r
    of M takes the groups r, r + M, ...; every rank gets all nodes, and the sinks' totals add up."""
    from dolfin_mpm.io import checkpoint

    folder = comm.bcast(tmp_path, root=0)
    path = folder / "fall.toml"
    if comm.rank == 0:
        path.write_text(SCENARIO)
    comm.Barrier()
    assert main(["run", str(path), "--quiet", "--output", str(folder / "run"), "--set", "time.end=0.03"]) == 0
    file = folder / "run" / "checkpoint.h5"
    with h5py.File(file, "r") as f:
        counts = [len(f[f"rank{r}/particles/mass"]) for r in range(comm.size)]
        nodes = sum(len(f[f"rank{r}/nodes"]) for r in range(comm.size))
        sunk = sum(float(f[f"rank{r}/sinks/below/mass"][()]) for r in range(comm.size))
    assert sum(counts) > 0 and sunk > 0.0
    mine = checkpoint.read(file, comm)
    assert len(mine["particles"]["mass"]) == counts[comm.rank] and mine["attrs"]["ranks"] == comm.size
    if comm.size == 1:
        return
    last = comm.rank == comm.size - 1
    fewer = comm.Split(int(last))  # the first N - 1 ranks, and the last alone
    part = checkpoint.read(file, fewer)
    taken = range(fewer.rank, comm.size, fewer.size)
    assert len(part["particles"]["mass"]) == sum(counts[g] for g in taken) and part["resharded"]
    assert len(part["nodes"]) == nodes and part["R_changes"].shape[1] == nodes * 2
    assert fewer.allreduce(float(part["sinks"]["below"]["mass"])) == pytest.approx(sunk, rel=1e-14)
    fewer.Free()


def checkpoint_state(path) -> dict:
    """Every rank's part of a checkpoint and its attributes, flattened (not the history)."""
    out = {}
    with h5py.File(path, "r") as f:
        out.update({f"attrs/{k}": np.asarray(v) for k, v in f.attrs.items()})
        for name in f:
            if name.startswith("rank"):
                f[name].visititems(
                    lambda key, d, rank=name: (
                        out.update({f"{rank}/{key}": d[()]}) if isinstance(d, h5py.Dataset) else None
                    )
                )
    return out


def test_a_scenario_starts_with_its_particles_balanced_over_the_ranks():
    """The column fills an eighth of its mesh: cut by cell count, one rank of two held it all."""
    from dolfin_mpm.app import scenario

    cfg = scenario.load(Path(__file__).parents[1] / "demos" / "column_collapse.toml")
    sim = scenario.build(cfg, comm)
    assert sim.solver.imbalance() <= 1.05


def test_dealing_the_cells_anew_keeps_the_nodal_conditions_on_their_nodes():
    """A repartitioned grid numbers its nodes anew: each condition keeps the same points and values."""
    from dolfin_mpm.parallel.rebalance import deal, renumber

    grid = dm.Grid(mesh.create_rectangle(comm, [np.zeros(2), np.ones(2)], [6, 5], mesh.CellType.triangle))
    floor = dm.FixedBC(grid.nodes_where(lambda x: np.isclose(x[1], 0.0)))
    top = grid.nodes_where(lambda x: np.isclose(x[1], 1.0))
    lid = dm.VelocityBC(top, np.column_stack([grid.node_x[top, 0], np.full(len(top), np.nan)]))  # u = x
    owned = grid.num_owned_cells
    inputs = np.asarray(grid.mesh.geometry.input_global_indices)[dm.compat.geometry_dofmap(grid.mesh)[:owned]]
    cells = np.concatenate(comm.allgather(inputs))
    ranks = np.arange(len(cells)) * comm.size // len(cells)  # strips of the input order: another partition
    mine = comm.rank == 0
    new = deal(grid, cells if mine else cells[:0], ranks.astype(np.int32) if mine else np.zeros(0, np.int32))
    renumber(grid, new, [floor, lid])
    assert new.partition is not None and new.comm is grid.comm
    assert comm.allreduce(new.num_owned_cells) == comm.allreduce(owned)
    assert np.array_equal(np.sort(floor.nodes), np.flatnonzero(np.isclose(new.node_x[:, 1], 0.0)))
    assert np.array_equal(np.sort(lid.nodes), np.flatnonzero(np.isclose(new.node_x[:, 1], 1.0)))
    # node_x is tabulated through each cell's map: the same point to round-off on another partition
    assert np.allclose(lid.velocity[:, 0], new.node_x[lid.nodes, 0], rtol=0.0, atol=1e-15)
    assert np.all(np.isnan(lid.velocity[:, 1]))
    on = [
        np.unique(np.concatenate(comm.allgather(g.node_inputs()[n])))
        for g, n in ((new, lid.nodes), (grid, top))
    ]
    assert np.array_equal(*on)  # the same nodes over all ranks


@pytest.mark.parametrize("dim", [2, 3])
def test_rebalancing_evens_out_the_particles_and_changes_no_result(dim):
    """A block low in a mesh cut into layers of equal cell count: dealt by the particles, the
    ranks hold equal shares, and the run goes on as on one rank."""
    up = dim - 1
    cells = lambda c: np.ones(c.shape[1])  # noqa: E731

    def run(comm, balance: bool):
        if dim == 2:
            msh = dm.partition.create_rectangle(comm, [(0, 0), (1, 1)], (12, 12), cells, axes=(up,))
        else:
            msh = dm.partition.create_box(comm, [(0, 0, 0), (1, 1, 1)], (8, 8, 8), cells, axes=(up,))
        grid = dm.Grid(msh)
        mat = dm.DruckerPragerViscoplastic(E=1e6, nu=0.3, rho=1500.0, phi=30.0, gamma=1e3)
        P = dm.seed(grid, mat, ppc=4, where=lambda x: (x[0] < 0.5) & (x[up] > 0.2) & (x[up] < 0.6))
        floor = dm.FixedBC(grid.nodes_where(lambda x: np.isclose(x[up], 0.0)))
        g = np.zeros(dim)
        g[up] = -9.81
        solver = dm.Solver(grid, P, mat, bcs=[floor], gravity=g, dt=2e-4,
                           averaging=dm.NonlocalAverage(radius=0.1 if dim == 2 else 0.15))  # fmt: skip
        solver.run_until(0.0, steps=20)
        before = solver.imbalance()
        changed = solver.rebalance() if balance else False
        after = solver.imbalance()
        solver.run_until(0.0, steps=30)
        return before, changed, after, solver.total_momentum(), solver.energies()

    before, changed, after, p, e = run(comm, True)
    *_, p1, e1 = run(MPI.COMM_SELF, False)
    assert changed == (comm.size > 1)
    if comm.size > 1:
        assert before > 1.4, "the layers should leave the block on few ranks"
        assert after <= 1.1, (before, after)
    assert p == pytest.approx(p1, rel=1e-10, abs=1e-14)
    for k in ("kinetic", "strain", "dissipated"):
        assert e[k] == pytest.approx(e1[k], rel=1e-9), k


def test_the_nodal_histories_follow_their_nodes_when_the_cells_are_dealt_anew():
    """The loop's changes of R and the damping's mean velocities are owned nodal arrays: after a
    repartition each new owned node has the values its node had (here its coordinates)."""
    cells = lambda c: np.ones(c.shape[1])  # noqa: E731
    grid = dm.Grid(dm.partition.create_rectangle(comm, [(0, 0), (1, 1)], (12, 12), cells, axes=(1,)))
    mat = dm.LinearElastic(E=1e6, nu=0.3, rho=1500.0)
    P = dm.seed(grid, mat, ppc=4, where=lambda x: (x[1] > 0.2) & (x[1] < 0.5))
    solver = dm.Solver(grid, P, mat, damping=0.1, damping_mean_time=0.01)
    coordinates = lambda g: g.node_x[: g.num_owned_nodes, :2].ravel().copy()  # noqa: E731
    solver.state.R_changes = [coordinates(grid), 2.0 * coordinates(grid)]
    solver.state.v_mean = -coordinates(grid)
    assert solver.rebalance() == (comm.size > 1)
    new = solver.grid
    assert (new is not grid) == (comm.size > 1)
    R, v_mean = solver.state.R_changes, solver.state.v_mean
    same = functools.partial(np.allclose, rtol=0.0, atol=1e-15)  # node_x is the cells' map's, to round-off
    assert same(R[0], coordinates(new)) and same(R[1], 2.0 * coordinates(new))
    assert same(v_mean, -coordinates(new))


# The serial run is matched to round-off, so without the damping: its sign of a velocity that
# round-off leaves at +-1e-17 differs from one partition to another.
REBALANCED = SCENARIO.replace("[solver]\n", "[solver]\nrebalance = 1.0\nrebalance_interval = 4\n").replace(
    "damping = 0.05\ndamping_mean_time = 0.005\n", ""
)


def test_a_rebalanced_run_resumes_bit_identical_and_equals_the_serial_run(tmp_path):
    """The checkpoint keeps how the cells were dealt: the resumed run makes the same mesh again."""
    from dolfin_mpm.app import scenario
    from dolfin_mpm.app.runner import Runner
    from dolfin_mpm.io import xdmf

    folder = run_and_resume(tmp_path, REBALANCED)
    if comm.rank == 0:
        one = folder / "one"
        one.mkdir()
        Runner(scenario.build(scenario.load(folder / "fall.toml"), MPI.COMM_SELF), one, progress=False).run()
        reference, resumed = (checkpoint_state(folder / f / "checkpoint.h5") for f in ("reference", "run"))
        assert bool(reference["attrs/repartitioned"]) == (comm.size > 1)
        assert reference.keys() == resumed.keys()
        for k in reference:
            assert same(reference[k], resumed[k]), k
        with h5py.File(folder / "reference" / "checkpoint.h5") as f:
            assert ("partition" in f) == (comm.size > 1)
        last = {f: list(csv.DictReader(open(folder / f / "history.csv")))[-1] for f in ("reference", "one")}
        assert float(last["reference"]["discharged"]) > 0.0
        # the grid series, read back in input order, is the serial run's through every repartition
        grids = {f: xdmf.read(folder / f / "grid.xdmf", 10) for f in ("reference", "one")}  # mid-run
        (_, x, cells, fields), (_, x1, cells1, fields1) = grids["reference"], grids["one"]
        momentum, momentum1 = fields["momentum"], fields1["momentum"]
        distance, match = cKDTree(x1).query(x)  # the serial mesh may number its input otherwise
        assert distance.max() < 1e-12 and np.unique(match).size == len(x1)
        as_set = lambda cells: {tuple(c) for c in np.sort(cells, axis=1)}  # noqa: E731
        assert as_set(match[cells]) == as_set(cells1)
        assert np.abs(momentum).max() > 0.0
        assert np.allclose(momentum, momentum1[match], rtol=1e-9, atol=1e-12 * np.abs(momentum).max())
        for k in ("kinetic", "strain", "potential", "dissipated", "discharged"):
            assert float(last["reference"][k]) == pytest.approx(float(last["one"][k]), rel=1e-9), k


def _layout_run(folder, layout, t_end=0.03, after=None):
    """The falling block of the output tests, written with ``layout`` into ``folder``."""
    grid = dm.Grid(rectangle((0, 0), (1, 1), (6, 6)))
    mat = dm.LinearElastic(E=1e4, nu=0.3, rho=100.0)
    P = dm.seed(grid, mat, ppc=4, where=lambda x: x[1] < 0.5)
    P.v[:, 0] = 0.1 * P.x[:, 1]  # grid velocity and momentum non-zero everywhere the block is
    bottom = dm.FixedBC(grid.nodes_where(lambda x: np.isclose(x[1], 0.0)))
    solver = dm.Solver(grid, P, mat, bcs=[bottom], gravity=(0, -9.81), dt=1e-3)
    with dm.Output(folder, comm, layout=layout) as out:
        solver.run(t_end, output=out, output_interval=0.01, progress=False)
    return solver


LAYOUTS = ["per-rank", "collective"] if h5py.get_config().mpi else ["per-rank"]


@pytest.mark.parametrize("layout", LAYOUTS)
def test_each_rank_writes_its_own_share_and_the_series_reads_as_the_gathered_one(tmp_path, layout):
    """Particles (by id) and grid (by input node) equal the gathered output bit for bit, every time."""
    from dolfin_mpm.io import xdmf

    folder = comm.bcast(tmp_path, root=0)
    solver = _layout_run(folder / layout, layout)
    _layout_run(folder / "gather", "gather")
    owned = len(solver.particles)
    files = sorted((folder / layout).glob("particles*.h5"))
    if layout == "per-rank":  # each rank's file holds its particles and no others
        with h5py.File(folder / layout / f"particles-rank{comm.rank}.h5") as f:
            assert len(f["step3/x"]) == owned
    comm.Barrier()
    if comm.rank != 0:
        return
    assert len(files) == (comm.size if layout == "per-rank" else 1)
    root = xdmf.ET.parse(folder / layout / "particles.xdmf").getroot()
    spatial = root.findall(".//Grid[@CollectionType='Spatial']")
    assert len(spatial) == (4 if layout == "per-rank" and comm.size > 1 else 0)
    for k in range(4):
        for name in ("particles", "grid"):
            t, x, cells, fields = xdmf.read(folder / layout / f"{name}.xdmf", k)
            t1, x1, cells1, fields1 = xdmf.read(folder / "gather" / f"{name}.xdmf", k)
            assert t == t1 == pytest.approx(0.01 * k)
            if name == "particles":
                order, order1 = np.argsort(fields["id"]), np.argsort(fields1["id"])
                assert np.array_equal(x[order], x1[order1])
            else:  # the same nodes in the same order; the same cells in any order
                order = order1 = slice(None)
                assert np.array_equal(x, x1) and np.array_equal(fields.pop("node"), np.arange(len(x1)))
                as_set = lambda c: {tuple(r) for r in np.sort(c, axis=1)}  # noqa: E731
                assert as_set(cells) == as_set(cells1)
            assert fields.keys() == fields1.keys()
            for f in fields:
                assert np.array_equal(fields[f][order], fields1[f][order1]), (name, k, f)
    assert np.abs(fields["momentum"]).max() > 0.0


@pytest.mark.parametrize("layout", LAYOUTS)
def test_a_series_written_in_pieces_extends_in_another_layout(tmp_path, layout):
    """Resumed gathered (as on one rank), a series in pieces keeps its earlier times readable,
    and the new times get their own mesh (not the pieces' one of the same name)."""
    from dolfin_mpm.io import xdmf

    folder = comm.bcast(tmp_path, root=0)
    _layout_run(folder / "run", layout, t_end=0.02)
    solver = _layout_run(folder / "scratch", "gather", t_end=0.005)
    with dm.Output(folder / "run", comm, after=0.01, layout="gather") as out:
        assert out.last_time == 0.01
        solver.time = 0.015
        out.write(solver)
    total = solver.num_particles()
    if comm.rank != 0:
        return
    times = [xdmf.read(folder / "run" / "grid.xdmf", k)[0] for k in range(3)]
    assert times == [0.0, 0.01, 0.015] == xdmf.times(folder / "run" / "grid.xdmf")
    with pytest.raises(IndexError):
        xdmf.read(folder / "run" / "grid.xdmf", 3)
    for k in range(3):
        _, x, _, fields = xdmf.read(folder / "run" / "particles.xdmf", k)
        assert len(x) == total and np.all(np.isfinite(fields["velocity"]))
        _, x, cells, fields = xdmf.read(folder / "run" / "grid.xdmf", k)
        assert len(x) == len(fields["mass"]) == 49 and len(cells) == 72 and cells.max() == 48
        assert k == 0 or fields["mass"].sum() > 0.0  # t = 0: before the first P2G


@pytest.mark.parametrize("layout", ["gather", *LAYOUTS])
def test_a_data_file_that_cannot_be_read_stops_every_rank(tmp_path, layout):
    """On extending, a damaged ``.h5`` of any rank is an OSError on all ranks, not a hang."""
    folder = comm.bcast(tmp_path, root=0) / "run"
    _layout_run(folder, layout, t_end=0.01)
    comm.Barrier()
    if comm.rank == 0:
        (sorted(folder.glob("grid*.h5"))[0]).write_bytes(b"not HDF5")
    comm.Barrier()
    with pytest.raises(OSError, match="grid"):
        dm.Output(folder, comm, after=0.0, layout=layout)


def test_a_series_of_empty_pieces_reads_as_empty(tmp_path):
    from dolfin_mpm.io import xdmf

    path = comm.bcast(tmp_path, root=0) / "empty.xdmf"
    series = xdmf.XDMFSeries(path, comm=comm, layout="per-rank")
    series.write(0.0, np.zeros((0, 3)), np.zeros((0, 1), dtype=np.int32), "Polyvertex", {"p": np.zeros(0)})
    series.close()
    if comm.rank == 0:
        t, x, cells, fields = xdmf.read(path)
        assert t == 0.0 and x.shape == (0, 3) and len(cells) == 0 and fields["p"].shape == (0,)
