"""Scenario files: validation that reports every problem with its TOML path, building, the CLI."""

import dataclasses
import math
import subprocess
import sys
from pathlib import Path

import dolfin_mpm  # noqa: F401  (first: loads DOLFINx's libraries)

# isort: split
import h5py
import meshio
import numpy as np
import pytest
from mpi4py import MPI
from test_demos import load

from dolfin_mpm.app import scenario
from dolfin_mpm.app.cli import main
from dolfin_mpm.app.runner import Runner
from dolfin_mpm.materials import DruckerPragerViscoplastic

ROOT = Path(__file__).parents[1]
DEMOS = ROOT / "demos"

BAD = """
[mesh]
shape = "rectangle"
lower = [0.0, 0.0]
upper = [1.0, "top"]
cells = [4, 4]
colour = "red"

[materials.sand]
model = "drucker_prager"
E = 1e6
rho = 1500.0
phi = 120
gamma = 1e3

[bodies.block]
material = "clay"
ppc = 3

[walls.floor]
type = "frictional"
region = { min = [0.0, 0.0], max = [1.0, 0.0] }
normal = [0.0, -1.0]
friction_angle = 95.0

[nonlocal]
radius = 0.1
law = "gradient"

[solver]
stress = "node"
quadrature = "cells"
light_nodes = "tied"
damping_mean_time = 0.0

[time]
end = -1.0

[[events]]
time = 0.0
remove_walls = ["gate"]
"""


def test_every_problem_is_reported_with_its_toml_path(tmp_path):
    (tmp_path / "bad.toml").write_text(BAD)
    with pytest.raises(scenario.ScenarioError) as info:
        scenario.load(tmp_path / "bad.toml")
    errors = info.value.errors
    expected = [
        "mesh.colour: unknown key (allowed: shape, lower, upper, cells, diagonal, partition)",
        'mesh.upper: must be an array of 2 numbers, got [1.0, "top"]',
        "materials.sand.nu: missing (must be in (-1, 0.5))",
        "materials.sand.phi: must be in (0, 90) degrees, got 120",
        'nonlocal.law: must be one of "max", "paper", "overstress", "overnonlocal", got "gradient"',
        'bodies.block.material: must be one of "sand", got "clay"',
        "bodies.block.ppc: must be a square number (1, 4, 9, ...) on triangles, got 3",
        "walls.floor.friction_angle: must be in [0, 90) degrees, got 95.0",
        "time.end: must be > 0 s, got -1.0",
        'solver.stress: must be one of "cell", "particle", got "node"',
        'solver.quadrature: must be one of "particle", "cell", got "cells"',
        'solver.light_nodes: must be one of "own", "aggregate", got "tied"',
        "solver.damping_mean_time: must be > 0 s, got 0.0",
        'events[0].remove_walls: no wall named "gate" (walls: floor)',
    ]
    assert sorted(errors) == sorted(expected)


def test_a_bad_material_does_not_also_fail_the_figure_field():
    with pytest.raises(scenario.ScenarioError) as info:
        scenario.load(DEMOS / "silo.toml", ["materials.sand.E=-1"])
    assert str(info.value) == "materials.sand.E: must be > 0 Pa, got -1"  # and nothing else


def test_material_parameters_are_the_classes_ranged_fields():
    """The scenario's table of each model is read off its class: the same Range objects, in
    field order, with the fields' defaults; validation reports the class's range."""
    for cls, params in scenario.MODELS.values():
        ranged = [f for f in dataclasses.fields(cls) if "range" in f.metadata]
        assert list(params) == [f.name for f in ranged]
        for f in ranged:
            assert params[f.name].range is f.metadata["range"]
            assert params[f.name].required == (f.default is dataclasses.MISSING)
            assert params[f.name].required or params[f.name].default == f.default
    cls, params = scenario.MODELS["drucker_prager"]
    assert cls is DruckerPragerViscoplastic and list(params) == [
        "E",
        "nu",
        "rho",
        "phi",
        "gamma",
        "N",
        "c",
        "rho_c",
    ]
    assert list(scenario.MODELS["elastic"][1]) == ["E", "nu", "rho"]
    gamma = {f.name: f for f in dataclasses.fields(cls)}["gamma"].metadata["range"]
    with pytest.raises(scenario.ScenarioError) as info:
        scenario.load(DEMOS / "silo.toml", ["materials.sand.gamma=0"])
    assert str(info.value) == f"materials.sand.gamma: {gamma.describe()}, got 0"
    assert gamma.describe() == "must be in (0, inf] 1/s"


def test_malformed_toml_gives_line_and_column(tmp_path):
    (tmp_path / "broken.toml").write_text('[mesh]\nshape = "rectangle"\nlower = [0.0; 0.0]\n')
    with pytest.raises(scenario.ScenarioError, match=r"broken.toml: .*line 3, column 13"):
        scenario.load(tmp_path / "broken.toml")


def test_overrides_are_toml_values_or_words():
    data = {"materials": {"sand": {"phi": 30.0}}}
    scenario.apply_overrides(data, ["materials.sand.phi=35", "nonlocal.weight=gaussian", "mesh.cells=[4, 5]"])
    assert data == {
        "materials": {"sand": {"phi": 35}}, "nonlocal": {"weight": "gaussian"}, "mesh": {"cells": [4, 5]}
    }  # fmt: skip
    with pytest.raises(scenario.ScenarioError, match=r"expected key\.path=value"):
        scenario.apply_overrides(data, ["nonsense"])
    with pytest.raises(scenario.ScenarioError, match=r"materials\.sand\.phi is not a table"):
        scenario.apply_overrides(data, ["materials.sand.phi.x=1"])


@pytest.mark.parametrize("name", ["silo", "elastic_bar", "column_collapse"])
def test_shipped_examples_build(name):
    sim = scenario.build(scenario.load(DEMOS / f"{name}.toml"))
    assert sim.solver.num_particles() > 0
    for bc in (bc for bcs in sim.walls.values() for bc in bcs):  # each wall holds nodes or touches material
        assert len(bc.nodes) if hasattr(bc, "nodes") else bc.over(sim.solver.particles.x).any()


def test_a_wall_that_holds_no_node_is_named(tmp_path):
    text = (DEMOS / "elastic_bar.toml").read_text()
    (tmp_path / "s.toml").write_text(text)
    cfg = scenario.load(
        tmp_path / "s.toml", ["walls.clamp.region.min=[2.0, 0.0]", "walls.clamp.region.max=[2.0, 1.0]"]
    )
    with pytest.raises(scenario.ScenarioError, match=r"^walls.clamp.region: holds no grid nodes$"):
        scenario.build(cfg)


def test_an_iterative_law_with_another_weight_is_named():
    with pytest.raises(
        scenario.ScenarioError, match=r'nonlocal\.law: "paper" needs the positive-definite weight'
    ):
        scenario.load(DEMOS / "silo.toml", ['nonlocal.law="paper"'])


@pytest.mark.parametrize("law", ["max", "paper", "overstress"])
def test_silo_scenario_is_the_silo_demo(tmp_path, law):
    """The silo file, coarsened with --set, takes the demo's steps bit for bit (settling, opening)."""
    h, r = 0.025, 0.02
    rows = math.ceil(0.05 / h) + 1  # as the demo lays out its grid
    weight = "cubic" if law == "max" else "wendland"
    reference = load("demo_silo").run(
        h=h, radius=r, weight=weight, t_end=0.02, t_settle=0.01, progress=False, law=law
    )
    assert reference["unconverged"] == 0
    overrides = [
        f"mesh.lower=[0.0, {-rows * h!r}]", f"mesh.upper=[0.2, {0.3 + h!r}]",
        f"mesh.cells=[8, {rows + 13}]", f"nonlocal.radius={r}", "time.start=-0.01", "time.end=0.02",
        "output.xdmf=false", "output.figures=false", f'nonlocal.law="{law}"', f'nonlocal.weight="{weight}"',
        f"solver.dt={reference['dt']!r}",  # the demo's stable step, not one fitted to the output interval
    ]  # fmt: skip
    sim = scenario.build(scenario.load(DEMOS / "silo.toml", overrides))
    Runner(sim, tmp_path, progress=False).run()
    P = sim.solver.particles
    assert sim.solver.step_count == reference["steps"]
    assert np.array_equal(P.x[:, :2], reference["x"])
    assert np.array_equal(P.state["eps_vp_rate_nonlocal"], reference["e_vp_bar"])
    walls = ("left", "bottom_left", "bottom_right", "right")
    assert [id(bc) for bc in sim.solver.bcs] == [id(bc) for k in walls for bc in sim.walls[k]]


def test_mesh_files_gmsh_and_xdmf(tmp_path):
    from dolfinx import io, mesh

    pts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 0]], float)
    tri = np.array([[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]])
    meshio.write(
        tmp_path / "square.msh",
        meshio.Mesh(pts, [("line", np.array([[0, 1]])), ("triangle", tri)]),
        file_format="gmsh22",
    )
    msh = mesh.create_rectangle(MPI.COMM_WORLD, [np.zeros(2), np.ones(2)], [3, 3], mesh.CellType.triangle)
    with io.XDMFFile(MPI.COMM_WORLD, str(tmp_path / "square.xdmf"), "w") as f:
        f.write_mesh(msh)
    text = (DEMOS / "elastic_bar.toml").read_text().split("[materials.bar]")[1]
    for name, cells in (("square.msh", 4), ("square.xdmf", 18)):
        head = f'[mesh]\nshape = "file"\nfile = "{name}"\n\n[materials.bar]'
        (tmp_path / "s.toml").write_text(head + text)
        cfg = scenario.load(
            tmp_path / "s.toml",
            ["bodies.bar.region.max=[1.0, 1.0]", "walls.rollers.region=[{min=[0,0],max=[1,0]}]"],
        )
        sim = scenario.build(cfg)
        assert sim.solver.comm.allreduce(sim.solver.grid.num_cells) == cells
        assert sim.solver.num_particles() == 4 * cells


def write_tagged_square(path: Path, n: int = 6) -> None:
    """A unit square of 2 n^2 triangles in gmsh format: cells below y = 1/2 in group 1 ("sand"), above
    in 2 ("air"); the bottom's lines in group 5 ("floor"), the left side's in 6 ("left")."""
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    pts = np.c_[i.ravel() / n, j.ravel() / n, np.zeros((n + 1) ** 2)]
    at = lambda a, b: a * (n + 1) + b  # noqa: E731
    a, b = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    a, b = a.ravel(), b.ravel()
    tri = np.r_[
        np.c_[at(a, b), at(a + 1, b), at(a + 1, b + 1)], np.c_[at(a, b), at(a + 1, b + 1), at(a, b + 1)]
    ]
    below = np.r_[b, b] < n // 2
    k = np.arange(n)
    lines = np.r_[np.c_[at(k, 0), at(k + 1, 0)], np.c_[at(0, k), at(0, k + 1)]]
    line_tags, cell_tags = np.r_[np.full(n, 5), np.full(n, 6)], np.where(below, 1, 2)
    groups = {"sand": [1, 2], "air": [2, 2], "floor": [5, 1], "left": [6, 1]}
    meshio.write(
        path,
        meshio.Mesh(
            pts, [("line", lines), ("triangle", tri)],
            cell_data={"gmsh:physical": [line_tags, cell_tags], "gmsh:geometrical": [line_tags, cell_tags]},
            field_data={k: np.array(v) for k, v in groups.items()},
        ),
        file_format="gmsh22",
    )  # fmt: skip


TAGGED = """[mesh]
shape = "file"
file = "square.msh"

[materials.sand]
model = "elastic"
E = 1e5
nu = 0.3
rho = 1500.0

[bodies.sand]
material = "sand"
region = { tag = 1 }

[walls.floor]
type = "fixed"
region = { tag = 5 }

[walls.left]
type = "slip"
region = { tag = 6 }
normal = [1.0, 0.0]

[time]
end = 0.01
"""


def test_gmsh_physical_groups_name_bodies_and_walls(tmp_path):
    write_tagged_square(tmp_path / "square.msh")
    (tmp_path / "s.toml").write_text(TAGGED)
    sim = scenario.build(scenario.load(tmp_path / "s.toml"))
    s, comm = sim.solver, MPI.COMM_WORLD
    x = s.particles.x
    assert comm.allreduce(s.num_particles()) == 4 * 36 and np.all(x[:, 1] < 0.5)  # the 36 cells of "sand"
    node_x = s.grid.node_x
    for name, on in (("floor", np.isclose(node_x[:, 1], 0.0)), ("left", np.isclose(node_x[:, 0], 0.0))):
        (bc,) = sim.walls[name]
        assert np.array_equal(np.sort(bc.nodes), np.flatnonzero(on)), name
    Runner(sim, tmp_path / "run", progress=False).run()  # and it runs
    assert np.all(s.particles.x[:, 1] < 0.5)


@pytest.mark.parametrize(
    "edit, message",
    [
        (
            "region = { tag = 5 }",
            "bodies.sand.region: tag 5 names no physical group of cells of dimension 2 in",
        ),
        ("region = { tag = 0 }", "bodies.sand.region.tag: must be >= 1, got 0"),
        ('region = { tag = "sand" }', 'bodies.sand.region.tag: must be an integer, got "sand"'),
    ],
)
def test_a_tag_the_file_lacks_is_named_with_the_groups_it_has(tmp_path, edit, message):
    write_tagged_square(tmp_path / "square.msh")
    (tmp_path / "s.toml").write_text(TAGGED.replace("region = { tag = 1 }", edit))
    with pytest.raises(scenario.ScenarioError) as info:
        scenario.build(scenario.load(tmp_path / "s.toml"))
    (error,) = info.value.errors
    assert error.startswith(message), error
    if "names no" in message:
        assert (
            "(it has cells of dimension 2: 1 (sand), 2 (air); lower-dimensional: 5 (floor), 6 (left))"
            in error
        )


def test_a_tag_needs_a_mesh_file_and_a_sink_takes_none(tmp_path):
    text = (DEMOS / "elastic_bar.toml").read_text()
    (tmp_path / "s.toml").write_text(text + "\n[sinks.out]\nregion = { tag = 3 }\n")
    with pytest.raises(scenario.ScenarioError) as info:
        scenario.load(tmp_path / "s.toml", ["walls.clamp.region={tag=2}"])
    assert sorted(info.value.errors) == [
        "sinks.out.region: a tag is for bodies and walls (a sink acts where particles are): give a box",
        'walls.clamp.region: a tag names a physical group of a mesh file (mesh.shape = "file")',
    ]


def _cli(*args, cwd=None):
    return subprocess.run(
        [sys.executable, "-m", "dolfin_mpm", *args], capture_output=True, text=True, cwd=cwd, timeout=300
    )


def test_cli_check_reports_problems_without_a_traceback(tmp_path):
    (tmp_path / "bad.toml").write_text(BAD)
    r = _cli("check", str(tmp_path / "bad.toml"))
    assert r.returncode == 2
    assert "materials.sand.phi: must be in (0, 90) degrees, got 120" in r.stderr
    assert "Traceback" not in r.stderr
    (tmp_path / "broken.toml").write_text("[mesh\n")
    r = _cli("check", str(tmp_path / "broken.toml"))
    assert r.returncode == 2 and "line 1, column 6" in r.stderr and "Traceback" not in r.stderr


def test_run_refuses_an_unwritable_folder(tmp_path, capsys):
    (tmp_path / "file").write_text("")
    code = main(
        ["run", str(DEMOS / "elastic_bar.toml"), "--output", str(tmp_path / "file" / "run"), "--quiet"]
    )
    assert code == 2
    assert f"cannot write to the output folder {tmp_path / 'file' / 'run'}" in capsys.readouterr().err


def test_column_collapse_runs_to_its_end_without_inflating(tmp_path):
    """The shipped collapse, whole (0.4 s): sand pulled apart at the front keeps its volume at
    m / rho_c and the run ends (without a critical density a point inflated 60-fold and left)."""
    cfg = scenario.load(DEMOS / "column_collapse.toml", ["output.xdmf=false", "output.figures=false"])
    sim = scenario.build(cfg)
    s, mass = sim.solver, sim.solver.total_mass()
    Runner(sim, tmp_path, progress=False).run()
    P, rho_c = s.particles, cfg["materials"]["sand"]["rho_c"]
    assert s.time == pytest.approx(cfg["time"]["end"], abs=s.dt) and s.total_mass() == pytest.approx(mass)
    assert np.all(P.volume <= P.mass / rho_c * (1 + 1e-12))
    assert np.all(np.linalg.norm(P.v, axis=1) < 3.0)  # m/s: no point flung out
    assert 0.3 < np.percentile(P.x[:, 0], 99) < 0.5  # the deposit's front [m]


def test_a_run_started_whole_steps_before_zero_is_at_zero_exactly():
    """Adding dt 170 times from -170 dt left t = 1.6e-17 where the gate opens; the times are
    now whole multiples of dt, as the steps are."""
    s = scenario.build(scenario.load(DEMOS / "silo.toml", ["time.end=0.001"])).solver
    k = round(-s.time / s.dt)
    assert s.time == -k * s.dt and k > 100
    s.run_until(0.0)
    assert s.time == 0.0 and s.step_count == k
    s.run_until(0.001)
    assert s.time == (s.step_count - k) * s.dt


@pytest.mark.parametrize(
    "value, match",
    [('"xz"', r'mesh.partition: must be axes of "xy" in the order of the cuts'), ('""', "mesh.partition")],
)
def test_a_bad_partition_is_named(value, match):
    with pytest.raises(scenario.ScenarioError, match=match):
        scenario.load(DEMOS / "silo.toml", [f"mesh.partition={value}"])


def test_cells_weigh_the_particles_the_bodies_seed_in_them():
    """What the ranks' cuts balance at the start: ppc inside a body's region, nothing outside."""
    cfg = scenario.load(DEMOS / "column_collapse.toml")
    weight = scenario._seeded(cfg["bodies"], 1e-12)
    centroids = np.array([[0.05, 0.1, 0.0], [0.3, 0.1, 0.0], [0.05, 0.22, 0.0]]).T
    assert np.array_equal(weight(centroids), [4.0, 0.0, 0.0])
    assert np.array_equal(scenario._seeded({}, 1e-12)(centroids), [1.0, 1.0, 1.0])  # no body: by count


@pytest.mark.parametrize(
    "value, match",
    [
        ('"rows"', r'output.layout: must be one of "auto", "gather", "collective", "per-rank", got "rows"'),
        ('"collective"', r"output.layout: 'collective' needs h5py built with MPI \(this one is serial\)"),
    ],
)
def test_a_bad_output_layout_is_named(value, match):
    if "collective" in value and h5py.get_config().mpi:
        pytest.skip("h5py here has MPI: a collective layout is allowed")
    with pytest.raises(scenario.ScenarioError, match=match):
        scenario.load(DEMOS / "silo.toml", [f"output.layout={value}"])
    assert scenario.load(DEMOS / "silo.toml", ['output.layout="per-rank"'])["output"]["layout"] == "per-rank"


@pytest.mark.parametrize(
    "overrides, message",
    [
        (['nonlocal.law="overnonlocal"'], r'nonlocal\.m: missing: law "overnonlocal" needs its factor m'),
        (['nonlocal.law="overnonlocal"', "nonlocal.m=1.0"], r"nonlocal\.m: must be > 1, got 1\.0"),
        (['nonlocal.law="overnonlocal"', "nonlocal.m=nan"], r"nonlocal\.m: must be > 1, got nan"),
        (["nonlocal.m=2.0"], r'nonlocal\.m: the factor of law "overnonlocal" alone, got it with law "max"'),
        (['nonlocal.law="paper"', "nonlocal.m=0.5"], r'nonlocal\.m: the factor of law "overnonlocal" alone'),
    ],
)
def test_bad_mix_factors_are_named_with_their_toml_path(overrides, message):
    with pytest.raises(scenario.ScenarioError, match=message):
        scenario.load(DEMOS / "silo.toml", ['nonlocal.weight="wendland"', *overrides])


def test_the_mix_factor_reaches_the_law():
    cfg = scenario.load(
        DEMOS / "silo.toml", ['nonlocal.law="overnonlocal"', "nonlocal.m=1.01", 'nonlocal.weight="wendland"']
    )
    assert (cfg["nonlocal"]["law"], cfg["nonlocal"]["m"]) == ("overnonlocal", 1.01)
