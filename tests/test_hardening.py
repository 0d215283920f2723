"""Scenario input cannot crash the program, hang it, exhaust its memory or silently change the physics.

Every bad input gives a ScenarioError naming its TOML path (and, through the CLI, exit 2 with no
traceback); a few bounds keep expressions and sizes from hanging or exhausting memory.
"""

import re
import signal
import time
import warnings
from pathlib import Path

import dolfin_mpm  # noqa: F401  (first: loads DOLFINx's libraries)

# isort: split
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from dolfin_mpm.app import scenario
from dolfin_mpm.app.cli import main
from dolfin_mpm.app.regions import Expression, Region
from dolfin_mpm.core.boundary import FrictionalWall, SlipBC, VelocityBC

DEMOS = Path(__file__).parents[1] / "demos"
BAR = DEMOS / "elastic_bar.toml"


def _refused(overrides, path: str, fragment: str = "", build=True) -> str:
    """The single problem of the elastic bar with ``overrides``, which starts with ``path: ``."""
    with pytest.raises(scenario.ScenarioError) as info:
        cfg = scenario.load(BAR, overrides)
        if build:
            scenario.build(cfg)
    (error,) = info.value.errors
    assert error.startswith(f"{path}: "), error
    assert fragment in error, error
    return error


def _validate(path: str, value) -> dict:
    """The elastic bar with ``value`` at the TOML ``path``, validated."""
    data = scenario.parse(BAR.read_text())
    *tables, key = path.split(".")
    t = data
    for name in tables:
        t = t.setdefault(name, {})
    t[key] = value
    return scenario.validate(data, DEMOS)


# -- expressions: parsed against a whitelist -----------------------------------------------------
LOGIC = "combine conditions with & | ~ and put each comparison in parentheses"


@pytest.mark.parametrize(
    "text, fragment",
    [
        ("y < 0.2 and x > 0.1", LOGIC),
        ("(y < 0.2) or (x > 0.1)", LOGIC),
        ("not (y < 0.2)", LOGIC),
        ("y < 0.2 & x > -1", LOGIC),  # numpy would read 0.2 & x, then a chained comparison
        ("y < 0.2 | x", LOGIC),
        ("0 < x < 0.5", LOGIC),
        ("sin(x, out=x) > 9", "keyword"),
        ("sin(x, x) > 9", "takes 1"),  # a second positional argument is numpy's out
        ("where(x > 0)", "takes 3"),
        ("x.real > 0", "attributes"),
        ("x[0] > 0", "subscripts"),
        ("(lambda: 1)() > 0", "may only call"),
        ("[a for a in x]", "ListComp"),
        ("x if y else z", "where(condition, a, b)"),
        ("__import__('os') > 0", "may only call"),
        ("open > 0", "may only use"),
        ("pi(x) > 0", "not a function"),
        ("sin > 0", "without calling it"),
        ("x^2 > 0", "x**2"),
        ("'a' > 0", "only numbers"),
        ("1" * 400 + " > x", "number too large"),
        ("10**10**10 > 0", "power in an exponent"),
        ("(x**2)**(2**2) > 0", "power in an exponent"),
        ("x**101 > 0", "exponent beyond +-100"),
        ("x**-1e3 > 0", "exponent beyond +-100"),
        ("-" * 200 + "x > 0", "nested more than 100"),
        ("x > " + "+".join(["x"] * 300), "nested more than 100"),
        ("x > 0" + " " * 996, "1001 characters long, at most 1000 allowed"),
        ("x" * 1_000_000, "1000000 characters long, at most 1000 allowed"),
        ("x >", "invalid expression"),
        ("x\0 > 0", "null"),
    ],
    ids=lambda v: v if len(v) <= 40 else f"{v[:30]}... ({len(v)} characters)",
)
def test_expressions_outside_the_whitelist_are_named_refusals(text, fragment):
    for path, value, where in (
        ("walls.clamp.region", text, "walls.clamp.region"),
        ("sinks.drain.region", text, "sinks.drain.region"),
        ("bodies.bar.velocity", [text, 0.0], "bodies.bar.velocity[0]"),
    ):
        with pytest.raises(scenario.ScenarioError) as info:
            _validate(path, value)
        (error,) = info.value.errors
        assert error.startswith(f"{where}: ") and fragment in error, error


def test_the_whitelist_keeps_what_expressions_are_for():
    x = np.array([[0.0, 0.3, 0.6], [0.1, 0.1, 0.5], [0.0, 0.0, 0.0]])
    cases = {
        "(y < 0.2) & (x > 0.1)": [False, True, False],
        "~(x > 0.5) | (y == 0.5)": [True, True, True],
        "hypot(x, y) <= 0.35": [True, True, False],
        "where(x > 0.5, 1, 0) * 2 - abs(-x) ** 2": [0.0, -0.09, 2 - 0.36],
        "0.01 * sin(pi * x / 2) + minimum(x, 0.5) + arctan2(y, 1) ** 0":
            [1.0, 1.3 + 0.01 * np.sin(0.15 * np.pi), 1.5 + 0.01 * np.sin(0.3 * np.pi)],
        "True": [True, True, True],
    }  # fmt: skip
    for text, expected in cases.items():
        assert np.allclose(Expression(text)(x), expected), text
    sim = scenario.build(scenario.load(BAR, ['walls.clamp.region="(x < 1e-9) & (y > -1)"']))
    assert len(sim.walls["clamp"][0].nodes) == 2


def test_expressions_see_copies_of_the_coordinates():
    x = np.random.default_rng(1).random((3, 5))
    before = x.copy()
    value = Expression("x")(x)
    assert not np.shares_memory(value, x)
    Region(expression=Expression("sqrt(x) > 2"))(x)
    assert np.array_equal(x, before)


def test_a_huge_exact_power_fails_at_once_instead_of_computing():
    """Whole numbers are floats: 9 ** 96059601 overflows instead of taking minutes as an integer."""
    e = Expression("9 ** (99 * 99 * 99 * 99) > 0")
    start = time.perf_counter()
    with pytest.raises(ValueError, match="fails"):
        e(np.zeros((3, 2)))
    assert time.perf_counter() - start < 1.0


# -- expressions: evaluated once when the scenario is built ---------------------------------------
@pytest.mark.parametrize(
    "overrides, path, fragment",
    [
        (['sinks.drain.region="1/0 > 0"'], "sinks.drain.region", "division by zero"),
        (['sinks.drain.region="x + 1"'], "sinks.drain.region", "must be a condition"),
        (['walls.clamp.region="0 ** -1 > x"'], "walls.clamp.region", "fails"),
        (['bodies.bar.region="x"'], "bodies.bar.region", "must be a condition"),
        (['bodies.bar.velocity=["x > 0", 0.0]'], "bodies.bar.velocity[0]", "real numbers"),
        (['bodies.bar.velocity=["1 / (x - x)", 0.0]'], "bodies.bar.velocity[0]", "not a finite number"),
        (['bodies.bar.velocity=["sqrt(-1 - x)", 0.0]'], "bodies.bar.velocity[0]", "not a finite number"),
        (['bodies.bar.velocity=["(-8) ** (1 / 3)", 0.0]'], "bodies.bar.velocity[0]", "real numbers"),
    ],
)
def test_expressions_that_would_fail_in_the_run_fail_the_build(overrides, path, fragment):
    scenario.load(BAR, overrides)  # the syntax is fine
    _refused(overrides, path, fragment)


# -- numbers that must be finite -----------------------------------------------------------------
@pytest.mark.parametrize(
    "overrides, path, fragment",
    [
        (["walls.rollers.normal=[nan, 1.0]"], "walls.rollers.normal", "must be finite"),
        (["walls.rollers.normal=[inf, 1.0]"], "walls.rollers.normal", "must be finite"),
        (["solver.gravity=[inf, 0.0]"], "solver.gravity", "must be finite"),
        (["solver.gravity=[0.0, nan]"], "solver.gravity", "must be finite"),
        (["bodies.bar.velocity=[nan, 0.0]"], "bodies.bar.velocity", "must be finite"),
        (["bodies.bar.velocity=[0.0, -inf]"], "bodies.bar.velocity", "must be finite"),
        (["walls.clamp.region.min=[nan, 0.0]"], "walls.clamp.region.min", "-inf for no bound"),
        (["walls.clamp.region.min=[inf, 0.0]"], "walls.clamp.region.min", "-inf for no bound"),
        (["walls.clamp.region.max=[0.0, -inf]"], "walls.clamp.region.max", "inf for no bound"),
        (["walls.clamp.type=velocity", "walls.clamp.velocity=[nan, 0.0]"], "walls.clamp.velocity", "finite"),
        (["mesh.lower=[-inf, 0.0]"], "mesh.lower", "must be finite"),
        (["mesh.lower=[-1e308, 0.0]", "mesh.upper=[1e308, 0.04]"], "mesh.upper", "overflows"),
        (["mesh.upper=[1e-310, 0.04]"], "mesh.cells", "precision"),
        (["mesh.lower=[1e9, 0.0]", "mesh.upper=[1000000000.001, 0.04]", "mesh.cells=[36000, 1]"],
         "mesh.cells", "precision"),
        (["mesh.cells=[1e30, 2]"], "mesh.cells", "at most 2147483647"),
        (["time.start=-1e308", "time.end=1e308"], "time.end", "end - start overflows"),
        (["time.start=-1e308"], "time.end", "more than 1e+12 steps"),
        (["time.end=1e308"], "time.end", "more than 1e+12 steps"),
        (["solver.dt=1e-300"], "time.end", "more than 1e+12 steps"),
        (["time.start=1e12", "time.end=1000000000001.0", "solver.dt=1e-4"], "time.end", "precision"),
        (["output.interval=1e308", "solver.dt=1e-10"], "output.interval", "finite number of steps"),
        (["materials.bar.E=1e308"], "materials.bar.E", "p-wave speed is inf"),
        (["materials.bar.rho=1e-320"], "materials.bar.E", "p-wave speed is inf"),
        (["solver.gravity=[0.0, -1e300]", "materials.bar.rho=1e10",
          'bodies.bar.stress={type = "geostatic", surface = 1e10}'], "bodies.bar.stress", "overflows"),
        (['bodies.bar.stress={type = "geostatic", surface = nan}', "solver.gravity=[0.0, -9.81]"],
         "bodies.bar.stress.surface", "must be finite"),
    ],
)  # fmt: skip
def test_numbers_that_must_be_finite_are_checked(overrides, path, fragment):
    _refused(overrides, path, fragment)


def test_an_overflowing_normal_keeps_its_wall():
    """A normal of 1e308 components had a norm of inf: the wall held nodes with a zero normal."""
    sim = scenario.build(scenario.load(BAR, ["walls.rollers.normal=[1e308, 1e308]"]))
    assert np.allclose(sim.walls["rollers"][0].normal, [np.sqrt(0.5), np.sqrt(0.5)])
    tiny = scenario.build(scenario.load(BAR, ["walls.rollers.normal=[0.0, 1e-320]"]))
    assert np.array_equal(tiny.walls["rollers"][0].normal, [0.0, 1.0])


@pytest.mark.parametrize("cls", [SlipBC, FrictionalWall])
def test_walls_refuse_normals_that_are_not_finite(cls):
    nodes = np.arange(3)
    assert np.allclose(cls(nodes, normal=(1e308, -1e308)).normal, [np.sqrt(0.5), -np.sqrt(0.5)])
    assert np.array_equal(cls(nodes, normal=(5e-324, 0.0)).normal, [1.0, 0.0])
    for normal in ((np.nan, 1.0), (np.inf, 0.0), (-np.inf, np.inf), (0.0, 0.0)):
        with pytest.raises(ValueError, match="normal must be a non-zero vector of 2 finite numbers"):
            cls(nodes, normal=normal)


def test_a_prescribed_velocity_may_be_free_but_not_infinite():
    assert VelocityBC(np.arange(2), velocity=[np.nan, 1.0])._set.tolist() == [[False, True]] * 2
    with pytest.raises(ValueError, match="finite"):
        VelocityBC(np.arange(2), velocity=[np.inf, 1.0])


def test_boxes_refuse_nan_corners():
    with pytest.raises(ValueError, match="box corners"):
        Region(boxes=[([np.nan, 0.0], [1.0, 1.0])])


# -- sizes, before anything is allocated ---------------------------------------------------------
def test_the_available_memory_is_read():
    memory = scenario.available_memory()
    if Path("/proc/meminfo").exists():
        assert memory is not None and memory > 1e6


def test_a_mesh_too_large_for_memory_is_refused_before_any_work(monkeypatch):
    monkeypatch.setattr(scenario, "available_memory", lambda: 1e9)
    start = time.perf_counter()
    error = _refused(["mesh.cells=[3000, 3000]"], "mesh.cells", build=False)
    assert time.perf_counter() - start < 5.0
    assert error == (
        "mesh.cells: 18,000,000 cells and up to 72,000,000 particles (4 per cell of bodies.bar) "
        "would need about 162 GB, 1 GB available"
    )


def test_too_many_particles_per_cell_are_refused(monkeypatch):
    monkeypatch.setattr(scenario, "available_memory", lambda: 1e10)
    error = _refused(["bodies.bar.ppc=1000000"], "bodies.bar.ppc", build=False)
    assert error.endswith(
        "up to 72,000,000 particles (1000000 per cell of bodies.bar) would need about 144 GB, 10 GB available"
    )
    _refused(["bodies.bar.ppc=4611686018427387904"], "bodies.bar.ppc", "particles in one cell", False)


def test_build_checks_the_sizes_again_with_the_memory_it_has(monkeypatch):
    cfg = scenario.load(BAR)
    monkeypatch.setattr(scenario, "available_memory", lambda: 1e5)
    with pytest.raises(scenario.ScenarioError, match=r"^mesh.cells: 72 cells .* 0.0001 GB available$"):
        scenario.build(cfg)


# -- the file itself -----------------------------------------------------------------------------
def test_a_file_that_is_not_utf8_or_not_a_file_is_named(tmp_path):
    (tmp_path / "latin1.toml").write_bytes('title = "Böschung"\n'.encode("latin-1"))
    with pytest.raises(
        scenario.ScenarioError, match=r"latin1.toml: not UTF-8 text \(byte 0xf6 at offset 10\)"
    ):
        scenario.load(tmp_path / "latin1.toml")
    (tmp_path / "folder").mkdir()
    with pytest.raises(scenario.ScenarioError, match=r"folder: cannot read \(Is a directory\)"):
        scenario.load(tmp_path / "folder")
    with pytest.raises(scenario.ScenarioError, match="nested too deeply"):
        scenario.parse("a = " + "[" * 5000 + "]" * 5000)
    with pytest.raises(scenario.ScenarioError, match="nested too deeply"):
        scenario.apply_overrides({}, ["a=" + "[" * 5000 + "]" * 5000])


#: A legacy VTK file meshio reads, whose triangle names a point it does not have.
_VTK_POINTING_PAST_ITS_POINTS = b"""# vtk DataFile Version 2.0
bad
ASCII
DATASET UNSTRUCTURED_GRID
POINTS 3 double
0 0 0
1 0 0
0 1 0
CELLS 1 4
3 0 1 9
CELL_TYPES 1
5
"""


@pytest.mark.parametrize(
    "name, content, fragment",
    [
        ("garbage.xdmf", b"garbage\x00\x01", "is not an XDMF file (not well-formed"),
        ("empty.xdmf", b"", "is not an XDMF file (no element found"),
        ("no_extension", b"hello", "is not a mesh file meshio reads (ReadError"),
        ("broken.msh", b"$MeshFormat\ngarbage\n", "is not a mesh file meshio reads"),
        ("inconsistent.vtk", _VTK_POINTING_PAST_ITS_POINTS, "cells name points 0 to 9, the file has 3"),
    ],
)
def test_a_mesh_file_that_is_not_a_mesh_is_named(tmp_path, capsys, name, content, fragment):
    """Each of these ended in a reader's traceback (exit 1); under MPI rank 0's would hang the others."""
    (tmp_path / name).write_bytes(content)
    text = BAR.read_text()
    start = text.index("[mesh]")
    end = text.index("\n[", start) + 1
    path = tmp_path / "bar.toml"
    path.write_text(f'{text[:start]}[mesh]\nshape = "file"\nfile = "{tmp_path / name}"\n\n{text[end:]}')
    assert main(["check", str(path)]) == 2
    out, err = capsys.readouterr()
    assert err.startswith(f"error: mesh.file: {tmp_path / name} ") and fragment in err, err
    assert "Traceback" not in out + err


# -- through the command line --------------------------------------------------------------------
@pytest.mark.parametrize(
    "overrides, expected",
    [
        (["walls.rollers.normal=[nan, 1.0]"], "walls.rollers.normal: must be finite"),
        (['walls.clamp.region="y < 0.2 and x > 0.1"'], "walls.clamp.region: expression"),
        (['walls.clamp.region="y < 0.2 & x > -1"'], "walls.clamp.region: expression"),
        (['sinks.drain.region="1/0 > 0"'], "sinks.drain.region: expression '1/0 > 0' fails"),
        (["mesh.cells=[1e30, 2]"], "mesh.cells: must be at most"),
        (["time.end=1e308"], "time.end: the run from t = 0 s to 1e+308 s"),
        (["materials.bar.E=1e308"], "materials.bar.E: with rho = 1.0 the p-wave speed"),
        (['walls.clamp.region="10**10**10 > 0"'], "walls.clamp.region: expression"),
        (['walls.clamp.region="~True"'], "walls.clamp.region: expression '~True'"),  # 3.13 warns on ~bool
        (["walls.clamp.region.max=[nan, 0.04]"], "walls.clamp.region.max: must be numbers"),
    ],
)
def test_cli_check_exits_2_with_the_path(overrides, expected, capsys):
    args = ["check", str(BAR)]
    for item in overrides:
        args += ["--set", item]
    assert main(args) == 2
    out, err = capsys.readouterr()
    assert err.startswith(f"error: {expected}"), err
    assert "Traceback" not in out + err


def test_cli_check_exits_2_on_sizes_and_bad_files(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(scenario, "available_memory", lambda: 1e9)
    assert main(["check", str(BAR), "--set", "mesh.cells=[3000, 3000]"]) == 2
    assert "error: mesh.cells: 18,000,000 cells" in capsys.readouterr().err
    (tmp_path / "bad.toml").write_bytes(b"title = \xff\n")
    assert main(["check", str(tmp_path / "bad.toml")]) == 2
    out, err = capsys.readouterr()
    assert "bad.toml: not UTF-8 text" in err and "Traceback" not in out + err


# -- fuzz: anything generated is checked and run through the CLI with exit 0, 1 or 2 -------------
_ATOMS = ["x", "y", "z", "pi", "e", "inf", "0", "1", "0.5", "2.5", "1e308", "-1", "100", "101", "nan", "foo",
          "True", "'s'", "1j", "__builtins__", "sin", "(x > 0.1)", "(y <= 0.02)"]  # fmt: skip
_UNARY = ["-", "~", "not ", "+", "*"]
_BINARY = ["+", "-", "*", "/", "//", "%", "**", "&", "|", "^", " < ", " > ", " <= ", " == ", " != ",
           " and ", " or ", " << ", " @ ", " if x else ", ", ", "."]  # fmt: skip
_CALLS = ["sin", "sqrt", "log", "exp", "where", "hypot", "minimum", "maximum", "abs", "arctan2", "eval",
          "open", "getattr", "x.real"]  # fmt: skip
_NUMBERS = ["nan", "inf", "-inf", "1e308", "-1e308", "0", "-1", "1e-320", "0.5", "3", "4", "100",
            "4611686018427387904", '"text"', "true", "{}", "[]"]  # fmt: skip
_KEYS = {
    "materials.bar.E": 1, "materials.bar.nu": 1, "materials.bar.rho": 1, "mesh.cells": 2, "mesh.lower": 2,
    "mesh.upper": 2, "bodies.bar.ppc": 1, "bodies.bar.velocity": 2, "walls.rollers.normal": 2,
    "walls.clamp.region.min": 2, "walls.clamp.region.max": 2, "solver.gravity": 2, "solver.dt": 1,
    "solver.courant": 1, "time.start": 1, "time.end": 1, "output.interval": 1, "solver.damping": 1,
    "bodies.bar.stress.surface": 1, "bodies.bar.stress.K0": 1, "walls.rollers.friction_angle": 1,
    "solver.flip": 1, "solver.scheme": 1, "solver.stress": 1, "solver.volumetric": 1,
}  # fmt: skip
_EXPRESSION_KEYS = ["walls.clamp.region", "bodies.bar.region", "sinks.drain.region"]


def _expression_strategy():
    """Expressions of the grammar's pieces, valid or not: the whitelist's input."""
    leaf = st.sampled_from(_ATOMS)

    def grow(inner):
        calls = st.tuples(st.sampled_from(_CALLS), st.lists(inner, max_size=3), st.booleans())
        return st.one_of(
            st.tuples(st.sampled_from(_UNARY), inner).map("".join),
            st.tuples(inner, st.sampled_from(_BINARY), inner).map("".join),
            inner.map(lambda a: f"({a})"),
            calls.map(lambda c: f"{c[0]}({', '.join([*c[1], *(['out=x'] if c[2] else [])])})"),
        )

    return st.recursive(leaf, grow, max_leaves=8)


_EXPRESSIONS = _expression_strategy()


def _numbers():
    """Values for number keys: the awkward ones, any float (nan and inf too), huge integers."""
    return st.one_of(
        st.sampled_from(_NUMBERS),
        st.floats(allow_nan=True, allow_infinity=True).map(repr),
        st.integers(min_value=-(2**70), max_value=2**70).map(str),
    )


@st.composite
def _overrides(draw) -> list[str]:
    out = []
    for _ in range(draw(st.integers(1, 3))):
        kind = draw(st.sampled_from(["expression", "condition", "velocity", "value"]))
        if kind in ("expression", "condition"):
            text = draw(_EXPRESSIONS)
            if kind == "condition":
                text = f"({text}) {draw(st.sampled_from(['<', '>=', '!=']))} ({draw(_EXPRESSIONS)})"
            out.append(f"{draw(st.sampled_from(_EXPRESSION_KEYS))}={text!r}")
        elif kind == "velocity":
            part = st.one_of(_EXPRESSIONS.map(repr), st.sampled_from(_NUMBERS))
            parts = draw(st.lists(part, min_size=2, max_size=2))
            out.append(f"bodies.bar.velocity=[{', '.join(parts)}]")
        else:
            key = draw(st.sampled_from(sorted(_KEYS)))
            values = draw(st.lists(_numbers(), min_size=_KEYS[key], max_size=_KEYS[key]))
            out.append(f"{key}=" + (values[0] if len(values) == 1 else "[" + ", ".join(values) + "]"))
    if any(o.startswith("bodies.bar.stress") for o in out):
        out += ['bodies.bar.stress.type="geostatic"', "solver.gravity=[0.0, -9.81]"]
    return out


class _Hang(Exception):
    pass


def _alarm(signum, frame):
    raise _Hang


@pytest.mark.filterwarnings("ignore:dt = .* the stable step:RuntimeWarning")  # drawn dt may exceed it
def test_fuzz_the_cli_exits_0_1_or_2_without_traceback_hang_or_stray_files(tmp_path, monkeypatch, capsys):
    """300 generated scenarios (expressions and values, fixed seed): ``check`` exits 0 or 2 and an
    accepted one runs a step with exit 0, 1 (a named simulation error) or 2, each with no
    traceback, within 20 s, writing nothing outside its output folder."""
    monkeypatch.setattr(scenario, "available_memory", lambda: 20e6)  # sizes stay small and quick
    monkeypatch.chdir(tmp_path)  # where results/ would go
    previous = signal.signal(signal.SIGALRM, _alarm)
    outcomes = {"refused": 0, "ran": 0, "failed": 0}

    @settings(max_examples=300, derandomize=True, deadline=None, database=None, print_blob=True,
              suppress_health_check=list(HealthCheck))  # fmt: skip
    @given(_overrides())
    def case(overrides):
        sets = [a for o in overrides for a in ("--set", o)]
        signal.alarm(20)
        try:
            code = main(["check", str(BAR), *sets])
            out, err = capsys.readouterr()
            assert code in (0, 2) and "Traceback" not in out + err, (overrides, code, err)
            if code == 2:
                assert err.startswith("error: "), err
                outcomes["refused"] += 1
                return
            folder = tmp_path / "run"
            steps = ["--set", "time.end=0", "--set", "time.start=-2e-9", "--set", "output.figures=false"]
            code = main(["run", str(BAR), *sets, *steps, "--output", str(folder), "--force", "--quiet"])
            out, err = capsys.readouterr()
            assert code in (0, 1, 2) and "Traceback" not in out + err, (overrides, code, err)
            if code == 1:  # the simulation went bad: named by step, particle and field
                assert err.startswith("error: step ") and "particle" in err, (overrides, err)
            outcomes["ran" if code == 0 else "failed"] += 1
        except _Hang:
            pytest.fail(f"{overrides}: no answer within 20 s")
        finally:
            signal.alarm(0)
        assert sorted(p.name for p in tmp_path.iterdir()) in ([], ["run"]), overrides

    try:
        case()
    finally:
        signal.signal(signal.SIGALRM, previous)
    print(outcomes)
    assert outcomes["refused"] >= 100 and outcomes["ran"] >= 10, outcomes


@pytest.mark.parametrize(
    "overrides, path, fragment",
    [
        (["nonlocal.radius=1e-320"], "nonlocal.radius", "at least 1e-9 times the mesh's diagonal"),
        (["nonlocal.radius=1e300"], "nonlocal.radius", "more than 10 times the mesh's diagonal"),
        (["nonlocal.radius=0.001", "nonlocal.skin=1e308"], "nonlocal.skin", "more than 10 times"),
        (["nonlocal.radius=0.3", "mesh.cells=[100, 185]", "bodies.fill.ppc=16"], "nonlocal.radius",
         "pairs of particles within radius + skin = 0.375 m would need about"),
    ],
)  # fmt: skip
def test_a_non_local_radius_that_overflows_or_pairs_every_particle_is_refused(
    overrides, path, fragment, monkeypatch
):
    """A radius of 1e300 overflowed in the first step; a large one asked for n^2 pairs of points."""
    monkeypatch.setattr(scenario, "available_memory", lambda: 10e9)
    with pytest.raises(scenario.ScenarioError) as info:
        scenario.build(scenario.load(DEMOS / "silo.toml", overrides))
    (error,) = info.value.errors
    assert error.startswith(f"{path}: ") and fragment in error, error


def test_a_step_above_the_stable_one_is_warned_in_one_line(capsys):
    """The run goes on (the estimate has a safety factor), but not silently."""
    with pytest.warns(RuntimeWarning, match=r"times the stable step") as record:
        sim = scenario.build(scenario.load(BAR, ["solver.dt=1.0"]))
    stable = sim.solver.critical_dt
    assert sim.solver.dt == 1.0 and f"{1.0 / stable:.3g} times" in str(record[0].message)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        scenario.build(scenario.load(BAR, [f"solver.dt={0.9 * stable!r}"]))  # below: no warning
    assert main(["check", str(BAR), "--set", "solver.dt=1.0"]) == 0
    out, err = capsys.readouterr()
    assert err.startswith("warning: dt = 1 s is") and err.count("\n") == 1 and "Traceback" not in out + err


@pytest.mark.parametrize("normal", ["[0.0, 1e308]", "[0.0, 7.0]"])
def test_a_frictional_wall_whose_normal_points_into_the_material_is_refused(normal):
    """A campaign's case: the floor's normal flipped by an overflowing or large component let
    the column fall through the floor (a unilateral wall holds only what lies behind its normal)."""
    collapse = DEMOS / "column_collapse.toml"
    with pytest.raises(scenario.ScenarioError) as info:
        scenario.build(scenario.load(collapse, [f"walls.floor.normal={normal}"]))
    (error,) = info.value.errors
    assert error.startswith("walls.floor.normal: ")
    assert re.search(r"points into the material \((\d+) of the \1 particles within a cell", error)  # all
    scenario.build(scenario.load(collapse, ["walls.floor.normal=[0.0, -1e308]"]))  # out of it: accepted


@pytest.mark.parametrize("surface", ["-1.0", "0.15"])
def test_a_geostatic_surface_below_the_body_is_refused(surface):
    """A campaign's case: surface = -1 m put the whole column in tension, and it was accepted."""
    with pytest.raises(scenario.ScenarioError) as info:
        overrides = [f"bodies.column.stress.surface={surface}"]
        scenario.build(scenario.load(DEMOS / "column_collapse.toml", overrides))
    (error,) = info.value.errors
    assert error.startswith(f"bodies.column.stress.surface: {surface} m lies below the body's top particle")


def test_the_stable_step_counts_the_particles_speed():
    """A step carries neither a wave nor a particle across more than courant of a cell: an initial
    velocity of 1e308 m/s gives a step count that is refused, not an overflow at step 1."""
    at_rest = scenario.build(scenario.load(BAR, ["bodies.bar.velocity=[0.0, 0.0]"])).solver
    moving = scenario.build(scenario.load(BAR, ["bodies.bar.velocity=[-40.0, 30.0]"])).solver
    c = at_rest.materials[0].p_wave_speed()
    assert moving.critical_dt == pytest.approx(at_rest.critical_dt * c / (c + 50.0), rel=1e-12)
    _refused(["bodies.bar.velocity=[-1e308, -1]"], "time.end", "1e+308 m/s, sets it: bodies.*.velocity")


def test_the_fuzz_campaign_runs_small(monkeypatch, capsys):
    """``scripts/fuzz_campaign.py`` (mutated shipped scenarios, checked and run) on a few cases."""
    import importlib.util
    import sys

    spec = importlib.util.spec_from_file_location(
        "fuzz_campaign", DEMOS.parent / "scripts" / "fuzz_campaign.py"
    )
    campaign = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(campaign)
    monkeypatch.setattr(sys, "argv", ["fuzz_campaign", "--cases", "12", "--seed", "7"])
    assert campaign.main_campaign() == 0
    summary = capsys.readouterr().out.strip().splitlines()[-1]
    assert (
        summary.startswith("12 cases (seed 7)")
        and "0 with a traceback, a hang or another exit code" in summary
    )
