"""Scenario files: a whole simulation in TOML, validated up front and built into objects.

    config = load("silo.toml", overrides=["nonlocal.radius=0"])  # ScenarioError lists every problem
    sim = build(config, MPI.COMM_WORLD)  # grid, particles, materials, walls, sinks, solver

Tables: ``[mesh]``, ``[materials.<name>]``, ``[nonlocal]``, ``[bodies.<name>]``,
``[walls.<name>]``, ``[sinks.<name>]``, ``[solver]``, ``[time]``, ``[[events]]``, ``[output]``
(see the README and ``demos/*.toml``). Validation reports unknown keys, missing keys, wrong
types and out-of-range values together, each with its TOML path
(``materials.sand.phi: must be in (0, 90) degrees, got 120``).
"""

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

try:
    import tomllib
except ModuleNotFoundError:  # Python < 3.11
    import tomli as tomllib

from mpi4py import MPI

from dolfin_mpm.app.regions import Expression, Region
from dolfin_mpm.averaging.nonlocal_average import WEIGHTS, NonlocalAverage
from dolfin_mpm.core import compat
from dolfin_mpm.core.boundary import BoundaryCondition, FixedBC, FrictionalWall, SlipBC, VelocityBC
from dolfin_mpm.core.grid import Grid
from dolfin_mpm.core.particles import Sink
from dolfin_mpm.core.seeding import geostatic_stress, reference_points, seed
from dolfin_mpm.explicit.options import INTEGERS, SCHEMES, Options
from dolfin_mpm.explicit.solver import Solver
from dolfin_mpm.materials import DruckerPragerViscoplastic, LinearElastic
from dolfin_mpm.parallel import partition
from dolfin_mpm.params import Range, parameters

__all__ = ["MODELS", "ScenarioError", "Simulation", "apply_overrides", "build", "load", "parse", "validate"]

INF = math.inf


#: Material models by name: class and its parameters (ranges, units, defaults), as the class
#: declares them.
MODELS = {
    name: (cls, parameters(cls))
    for name, cls in (("elastic", LinearElastic), ("drucker_prager", DruckerPragerViscoplastic))
}
_WALLS = ("fixed", "slip", "frictional", "velocity")
_DIAGONALS = ("right", "left", "crossed", "right/left", "left/right")
#: The ``[solver]`` options but ``gravity`` and ``on_exit``: (kind, default, interval or
#: choices), as :class:`~dolfin_mpm.explicit.options.Options` declares them.
_SOLVER = {
    "scheme": ("string", Options.scheme, SCHEMES),
    **{
        name: ("integer" if name in INTEGERS else "number", p.default, p.range)
        for name, p in parameters(Options).items()
    },
}
_PARTICLE_FIELDS = ("speed", "p", "q", "mass", "volume")


class ScenarioError(ValueError):
    """Everything wrong with a scenario, one ``path: problem`` line each."""

    def __init__(self, errors: list[str]):
        self.errors = list(errors)
        super().__init__("\n".join(self.errors))


def _show(value) -> str:
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, dict):
        return "a table"
    if isinstance(value, list):
        return "[" + ", ".join(_show(v) for v in value) + "]"
    return repr(value).lower() if isinstance(value, bool) else repr(value)


class _Checker:
    """Collects problems, each with its TOML path, instead of stopping at the first."""

    def __init__(self):
        self.errors: list[str] = []

    def fail(self, path: str, message: str) -> None:
        self.errors.append(f"{path}: {message}")

    def keys(self, table: dict, path: str, allowed) -> None:
        for key in table:
            if key not in allowed:
                self.fail(f"{path}.{key}" if path else key, f"unknown key (allowed: {', '.join(allowed)})")

    def table(self, parent: dict, key: str, path: str, required=True) -> dict | None:
        where = f"{path}.{key}" if path else key
        if key not in parent:
            if required:
                self.fail(where, "missing table")
            return None
        if not isinstance(parent[key], dict):
            self.fail(where, f"must be a table, got {_show(parent[key])}")
            return None
        return parent[key]

    def named_tables(self, parent: dict, key: str, required=True) -> dict[str, dict]:
        """``[key.<name>]`` tables, by name."""
        tables = self.table(parent, key, "", required) or {}
        if required and key in parent and not tables:
            self.fail(key, "needs at least one entry")
        good = {}
        for name, t in tables.items():
            if isinstance(t, dict):
                good[name] = t
            else:
                self.fail(f"{key}.{name}", f"must be a table, got {_show(t)}")
        return good

    def value(
        self, t: dict, path: str, key: str, kind: str, default=None, required=False, check=None, size=0
    ):
        """``t[key]`` of ``kind`` (number, integer, string, bool, numbers, strings, vector).

        ``check`` is a :class:`~dolfin_mpm.params.Range` or a tuple of choices; ``size`` the length of a
        ``numbers`` array (0: any). Returns ``default`` when missing or bad.
        """
        where = f"{path}.{key}"
        if key not in t:
            if required:
                self.fail(where, "missing" + (f" ({check.describe()})" if isinstance(check, Range) else ""))
            return default
        v = t[key]
        is_num = lambda a: isinstance(a, (int, float)) and not isinstance(a, bool)  # noqa: E731
        expected = {
            "number": ("a number", is_num(v)),
            "integer": ("an integer", isinstance(v, int) and not isinstance(v, bool)),
            "string": ("a string", isinstance(v, str)),
            "bool": ("true or false", isinstance(v, bool)),
            "numbers": (
                f"an array of {size or 'any number of'} numbers",
                isinstance(v, list) and all(map(is_num, v)) and (not size or len(v) == size),
            ),
            "strings": ("an array of strings", isinstance(v, list) and all(isinstance(a, str) for a in v)),
            "vector": (
                f"an array of {size} numbers or expression strings",
                isinstance(v, list) and len(v) == size and all(is_num(a) or isinstance(a, str) for a in v),
            ),
        }[kind]
        if not expected[1]:
            self.fail(where, f"must be {expected[0]}, got {_show(v)}")
            return default
        if isinstance(check, Range):
            values = v if isinstance(v, list) else [v]
            if not all(check.contains(a) for a in values):
                self.fail(where, f"{check.describe()}, got {_show(v)}")
                return default
        elif check is not None and v not in check:
            self.fail(where, f"must be one of {', '.join(map(_show, check))}, got {_show(v)}")
            return default
        if kind == "number":
            return float(v)
        if kind == "numbers":
            return [float(a) for a in v]
        return v

    def region(self, t: dict, path: str, key: str, gdim: int, required=True):
        """A region: ``{min, max}`` box, an array of boxes (their union) or an expression string."""
        where = f"{path}.{key}"
        if key not in t:
            if required:
                self.fail(
                    where, "missing (a {min = [...], max = [...]} box, an array of boxes or an expression)"
                )
            return None
        v = t[key]
        if isinstance(v, str):
            try:
                Expression(v)
            except ValueError as e:
                self.fail(where, str(e))
                return None
            return {"expression": v}
        boxes = v if isinstance(v, list) else [v]
        if not boxes or not all(isinstance(b, dict) for b in boxes):
            self.fail(
                where,
                f"must be a box {{min = [...], max = [...]}}, an array of boxes or an expression, "
                f"got {_show(v)}",
            )
            return None
        out = []
        for k, b in enumerate(boxes):
            bpath = where if isinstance(v, dict) else f"{where}[{k}]"
            self.keys(b, bpath, ("min", "max"))
            lo = self.value(b, bpath, "min", "numbers", required=True, size=gdim)
            hi = self.value(b, bpath, "max", "numbers", required=True, size=gdim)
            if lo is not None and hi is not None:
                if any(a > c for a, c in zip(lo, hi)):
                    self.fail(
                        f"{bpath}.max", f"must be >= min in every component, got {_show(hi)} < {_show(lo)}"
                    )
                out.append((lo, hi))
        return {"boxes": out}

    def vector(self, t: dict, path: str, key: str, gdim: int, default=None, required=False):
        """``gdim`` numbers or expression strings of x, y, z."""
        v = self.value(t, path, key, "vector", default=None, required=required, size=gdim)
        if v is None:
            return default
        for k, a in enumerate(v):
            if isinstance(a, str):
                try:
                    Expression(a)
                except ValueError as e:
                    self.fail(f"{path}.{key}[{k}]", str(e))
        return v


# -- reading -------------------------------------------------------------------------------------
def parse(text: str, source: str = "scenario") -> dict:
    """The TOML document ``text``; a syntax error becomes a :class:`ScenarioError` with its line."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ScenarioError([f"{source}: {e}"]) from None


def apply_overrides(data: dict, overrides) -> None:
    """Set ``key.path=value`` assignments (TOML values; bare words are strings) in ``data``."""
    errors = []
    for item in overrides:
        key, sep, text = item.partition("=")
        keys = key.strip().split(".")
        if not sep or not all(keys):
            errors.append(f"--set {item}: expected key.path=value")
            continue
        try:
            value = tomllib.loads(f"v = {text.strip()}")["v"]
        except tomllib.TOMLDecodeError:
            value = text.strip()
        t = data
        for k, name in enumerate(keys[:-1]):
            t = t.setdefault(name, {})
            if not isinstance(t, dict):
                errors.append(f"--set {item}: {'.'.join(keys[: k + 1])} is not a table")
                break
        else:
            t[keys[-1]] = value
    if errors:
        raise ScenarioError(errors)


def load(path, overrides=(), base: Path | None = None) -> dict:
    """Read, override and validate the scenario file ``path``.

    Args:
        path: the TOML file.
        overrides: ``key.path=value`` assignments applied before validation.
        base: folder that relative file names (``mesh.file``) refer to; default: the file's.

    Returns:
        The validated scenario with every default filled in (see :func:`validate`).

    Raises:
        ScenarioError: unreadable or malformed file, or every problem validation found.

    """
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as e:
        raise ScenarioError([f"{path}: cannot read ({e.strerror})"]) from None
    data = parse(text, str(path))
    apply_overrides(data, overrides)
    return validate(data, path.parent if base is None else base)


# -- validation ----------------------------------------------------------------------------------
def validate(data: dict, base: Path = Path(".")) -> dict:
    """Check the whole scenario; returns it normalised with defaults, or raises :class:`ScenarioError`."""
    c = _Checker()
    c.keys(
        data,
        "",
        (
            "title",
            "mesh",
            "materials",
            "nonlocal",
            "bodies",
            "walls",
            "sinks",
            "solver",
            "time",
            "events",
            "output",
        ),
    )
    cfg = {"title": c.value(data, "", "title", "string", default="")}
    cfg["mesh"], gdim = _mesh(c, c.table(data, "mesh", ""), Path(base))
    cfg["materials"] = {
        name: _material(c, t, f"materials.{name}") for name, t in c.named_tables(data, "materials").items()
    }
    cfg["nonlocal"] = _nonlocal(c, c.table(data, "nonlocal", "", required=False), cfg["materials"])
    cfg["sinks"] = {}
    for name, t in c.named_tables(data, "sinks", False).items():
        c.keys(t, f"sinks.{name}", ("region",))
        cfg["sinks"][name] = {"region": c.region(t, f"sinks.{name}", "region", gdim)}
    cfg["solver"] = _solver(c, c.table(data, "solver", "", required=False) or {}, gdim, cfg["sinks"])
    cfg["bodies"] = {
        name: _body(c, t, f"bodies.{name}", gdim, cfg["materials"], cfg["solver"]["gravity"])
        for name, t in c.named_tables(data, "bodies").items()
    }
    cfg["walls"] = {
        name: _wall(c, t, f"walls.{name}", gdim) for name, t in c.named_tables(data, "walls", False).items()
    }
    cfg["time"] = _time(c, c.table(data, "time", ""))
    cfg["events"] = _events(c, data.get("events", []), cfg["time"], cfg["walls"])
    cfg["output"] = _output(
        c, c.table(data, "output", "", required=False) or {}, cfg["time"], cfg["materials"], gdim
    )
    if c.errors:
        raise ScenarioError(c.errors)
    return cfg


def _mesh(c: _Checker, t: dict | None, base: Path) -> tuple[dict, int]:
    if t is None:
        return {}, 2
    shape = c.value(t, "mesh", "shape", "string", required=True, check=("rectangle", "box", "file"))
    if shape == "file":
        c.keys(t, "mesh", ("shape", "file", "gdim"))
        gdim = c.value(t, "mesh", "gdim", "integer", default=2, check=(2, 3))
        name = c.value(t, "mesh", "file", "string", required=True)
        file = None
        if name is not None:
            file = (base / name).resolve()
            if not file.is_file():
                c.fail("mesh.file", f"no such file: {file}")
        return {"shape": shape, "file": str(file), "gdim": gdim}, gdim
    gdim = 3 if shape == "box" else 2
    c.keys(
        t,
        "mesh",
        ("shape", "lower", "upper", "cells", "diagonal")
        if gdim == 2
        else ("shape", "lower", "upper", "cells"),
    )
    lower = c.value(t, "mesh", "lower", "numbers", required=True, size=gdim)
    upper = c.value(t, "mesh", "upper", "numbers", required=True, size=gdim)
    if lower and upper and not all(a < b for a, b in zip(lower, upper)):
        c.fail(
            "mesh.upper", f"must exceed mesh.lower = {_show(lower)} in every component, got {_show(upper)}"
        )
    cells = c.value(
        t, "mesh", "cells", "numbers", required=True, size=gdim, check=Range(1, INF, closed=(True, False))
    )
    if cells is not None and not all(float(n).is_integer() for n in cells):
        c.fail("mesh.cells", f"must be whole numbers, got {_show(cells)}")
        cells = None
    m = {
        "shape": shape,
        "lower": lower,
        "upper": upper,
        "cells": cells and [int(n) for n in cells],
        "gdim": gdim,
    }
    if gdim == 2:
        m["diagonal"] = c.value(t, "mesh", "diagonal", "string", default="right", check=_DIAGONALS)
    return m, gdim


def _material(c: _Checker, t: dict, path: str) -> dict:
    model = c.value(t, path, "model", "string", required=True, check=tuple(MODELS))
    if model is None:
        return {"model": None}
    cls, params = MODELS[model]
    c.keys(t, path, ("model", *params))
    m = {"model": model}
    for name, p in params.items():
        m[name] = c.value(t, path, name, "number", default=p.default, required=p.required, check=p.range)
    if not any(m[name] is None and p.required for name, p in params.items()):
        try:
            m["state"] = list(cls(**{k: m[k] for k in params}).state_fields())
        except ValueError as e:  # a check across parameters ("psi must be in [0, phi]")
            name, _, problem = str(e).partition(" ")
            c.fail(f"{path}.{name}", problem)
    return m


def _nonlocal(c: _Checker, t: dict | None, materials: dict) -> dict:
    if t is None:
        return {"radius": 0.0, "weight": "cubic", "skin": None}
    c.keys(t, "nonlocal", ("radius", "weight", "skin"))
    n = {
        "radius": c.value(t, "nonlocal", "radius", "number", 0.0, True, NonlocalAverage.RADIUS),
        "weight": c.value(t, "nonlocal", "weight", "string", "cubic", check=tuple(WEIGHTS)),
        "skin": c.value(t, "nonlocal", "skin", "number", None, check=NonlocalAverage.SKIN),
    }
    models = [m["model"] for m in materials.values()]
    if n["radius"] > 0.0 and not any(MODELS[m][0].plastic for m in models if m in MODELS):
        plastic = [name for name, (cls, _) in MODELS.items() if cls.plastic]
        c.fail(
            "nonlocal.radius",
            f"averaging needs a plastic material ({', '.join(plastic)}), got {_show(models)}",
        )
    return n


def _solver(c: _Checker, t: dict, gdim: int, sinks: dict) -> dict:
    c.keys(t, "solver", ("gravity", "on_exit", *_SOLVER))
    s = {"gravity": c.value(t, "solver", "gravity", "numbers", [0.0] * gdim, size=gdim)}
    for name, (kind, default, check) in _SOLVER.items():
        s[name] = c.value(t, "solver", name, kind, default, check=check)
    s["on_exit"] = c.value(t, "solver", "on_exit", "string", "error", check=("error", *sinks))
    return s


def _body(c: _Checker, t: dict, path: str, gdim: int, materials: dict, gravity) -> dict:
    c.keys(t, path, ("material", "ppc", "region", "velocity", "stress"))
    b = {
        "material": c.value(t, path, "material", "string", required=True, check=tuple(materials)),
        "ppc": c.value(t, path, "ppc", "integer", 4, check=Range(1, INF, closed=(True, False))),
        "region": c.region(t, path, "region", gdim, required=False),
        "velocity": c.vector(t, path, "velocity", gdim),
        "stress": None,
    }
    try:
        reference_points(gdim, b["ppc"])
    except ValueError as e:
        c.fail(f"{path}.ppc", str(e).removeprefix("ppc "))
    s = c.table(t, "stress", path, required=False)
    if s is not None:
        spath = f"{path}.stress"
        c.keys(s, spath, ("type", "surface", "K0"))
        b["stress"] = {
            "type": c.value(s, spath, "type", "string", required=True, check=("geostatic",)),
            "surface": c.value(s, spath, "surface", "number", required=True),
            "K0": c.value(s, spath, "K0", "number", None, check=Range(0.0, INF, closed=(True, False))),
        }
        if not any(gravity):
            c.fail(f"{spath}.type", "geostatic stress needs solver.gravity")
    return b


def _wall(c: _Checker, t: dict, path: str, gdim: int) -> dict:
    kind = c.value(t, path, "type", "string", required=True, check=_WALLS)
    extra = {"slip": ("normal",), "frictional": ("normal", "friction_angle"), "velocity": ("velocity",)}
    c.keys(t, path, ("type", "region", *extra.get(kind, ())))
    w = {"type": kind, "region": c.region(t, path, "region", gdim)}
    if kind in ("slip", "frictional"):
        w["normal"] = c.value(t, path, "normal", "numbers", required=True, size=gdim)
        if w["normal"] is not None and not any(w["normal"]):
            c.fail(f"{path}.normal", "must be a non-zero vector")
    if kind == "frictional":
        w["friction_angle"] = c.value(
            t, path, "friction_angle", "number", 0.0, check=Range(0.0, 90.0, "degrees", (True, False))
        )
    if kind == "velocity":
        w["velocity"] = c.value(t, path, "velocity", "numbers", required=True, size=gdim)
    return w


def _time(c: _Checker, t: dict | None) -> dict:
    if t is None:
        return {"start": 0.0, "end": 0.0}
    c.keys(t, "time", ("start", "end"))
    start = c.value(t, "time", "start", "number", 0.0, check=Range(-INF, INF))
    end = c.value(t, "time", "end", "number", None, True, Range(start, INF, "s"))
    return {"start": start, "end": end if end is not None else start}


def _events(c: _Checker, events, time: dict, walls: dict) -> list[dict]:
    if not isinstance(events, list) or not all(isinstance(e, dict) for e in events):
        c.fail("events", f"must be an array of tables ([[events]]), got {_show(events)}")
        return []
    out = []
    span = Range(time["start"], time["end"], "s", (True, True))
    for k, t in enumerate(events):
        path = f"events[{k}]"
        c.keys(t, path, ("time", "remove_walls", "damping"))
        e = {
            "time": c.value(t, path, "time", "number", time["start"], True, span),
            "remove_walls": c.value(t, path, "remove_walls", "strings", []),
            "damping": c.value(t, path, "damping", "number", None, check=_SOLVER["damping"][2]),
        }
        for name in e["remove_walls"]:
            if name not in walls:
                c.fail(f"{path}.remove_walls", f"no wall named {_show(name)} (walls: {', '.join(walls)})")
        out.append(e)
    return sorted(out, key=lambda e: e["time"])


def _output(c: _Checker, t: dict, time: dict, materials: dict, gdim: int) -> dict:
    keys = ("interval", "xdmf", "checkpoint_interval", "figures", "figure_field", "figure_interval")
    c.keys(t, "output", keys)
    span = max(time["end"] - time["start"], 1e-300)
    positive = Range(0.0, INF, "s")
    fields = [*_PARTICLE_FIELDS, *"xyz"[:gdim]]
    fields = [f"v{a}" if len(a) == 1 else a for a in fields]
    fields += sorted({s for m in materials.values() for s in m.get("state", [])})
    known = all("state" in m for m in materials.values())
    o = {
        "interval": c.value(t, "output", "interval", "number", span / 50, check=positive),
        "xdmf": c.value(t, "output", "xdmf", "bool", True),
        "checkpoint_interval": c.value(
            t, "output", "checkpoint_interval", "number", span / 10, check=positive
        ),
        "figures": c.value(t, "output", "figures", "bool", True),
        # A material with bad parameters has no state names yet: no second error from it here.
        "figure_field": c.value(
            t, "output", "figure_field", "string", "speed", check=tuple(fields) if known else None
        ),
        "figure_interval": c.value(t, "output", "figure_interval", "number", span / 5, check=positive),
    }
    return o


# -- building ------------------------------------------------------------------------------------
@dataclass
class Simulation:
    """A built scenario: the solver with everything it holds, and the scheduled events.

    Attributes:
        config: the validated scenario.
        solver: the solver (grid, particles, materials, walls, sinks, averaging).
        walls: the boundary conditions by name, in file order.
        applied: indices of ``config["events"]`` already applied.

    """

    config: dict
    solver: Solver
    walls: dict[str, BoundaryCondition]
    applied: list[int]

    def apply_event(self, k: int) -> None:
        """Apply event ``k``: remove its walls, set its damping."""
        event = self.config["events"][k]
        gone = {id(self.walls[name]) for name in event["remove_walls"]}
        self.solver.bcs = [bc for bc in self.solver.bcs if id(bc) not in gone]
        if event["damping"] is not None:
            self.solver.damping = event["damping"]
        self.applied.append(k)

    def discharged_mass(self) -> float:
        """Mass absorbed by all sinks [kg] (per metre in 2D), summed over ranks."""
        local = sum(s.mass for s in self.solver.sinks.values())
        return self.solver.comm.allreduce(local, MPI.SUM)


def _make_region(spec: dict, tol: float) -> Region:
    if "expression" in spec:
        return Region(expression=Expression(spec["expression"]))
    return Region(boxes=spec["boxes"], tol=tol)


def _make_mesh(m: dict, comm):
    if m["shape"] == "file":
        return compat.read_mesh(comm, m["file"], m["gdim"])
    # On several ranks, cells dealt by count in coordinate bisection: the same partition in every
    # run, which a resumed run needs (DOLFINx's graph partitioners may cut differently each time).
    corners, count = [np.array(m["lower"]), np.array(m["upper"])], lambda c: np.ones(c.shape[1])
    if m["shape"] == "box":
        return partition.create_box(comm, corners, m["cells"], weight=count)
    return partition.create_rectangle(comm, corners, m["cells"], weight=count, diagonal=m["diagonal"])


def build(cfg: dict, comm=MPI.COMM_WORLD) -> Simulation:
    """The objects of a validated scenario, at its start time (collective over ``comm``).

    Raises:
        ScenarioError: problems only the mesh reveals (a wall that holds no node, a body with
            no particle, a mesh of the wrong dimension), each with its TOML path.

    """
    errors = []
    try:
        grid = Grid(_make_mesh(cfg["mesh"], comm))
    except (ValueError, RuntimeError, OSError) as e:
        raise ScenarioError([f"mesh: {e}"]) from None
    if grid.gdim != cfg["mesh"]["gdim"]:
        raise ScenarioError(
            [f"mesh.gdim: the mesh has dimension {grid.gdim}, the scenario says {cfg['mesh']['gdim']}"]
        )
    lo, hi = grid.node_x.min(axis=0, initial=INF), grid.node_x.max(axis=0, initial=-INF)
    extent = comm.allreduce(float(np.max(hi - lo, initial=0.0)), MPI.MAX)
    tol = 1e-9 * extent

    names = list(cfg["materials"])
    materials = []
    for spec in cfg["materials"].values():
        cls, params = MODELS[spec["model"]]
        materials.append(cls(**{k: spec[k] for k in params}))
    state_fields = {k: v for m in materials for k, v in m.state_fields().items()}
    gravity = np.array(cfg["solver"]["gravity"])

    particles = None
    for name, b in cfg["bodies"].items():
        k = names.index(b["material"])
        where = _make_region(b["region"], tol) if b["region"] else None
        try:
            P = seed(grid, materials[k], ppc=b["ppc"], where=where, material_index=k)
        except ValueError as e:
            errors.append(f"bodies.{name}.region: {e}")
            continue
        if comm.allreduce(len(P), MPI.SUM) == 0:
            errors.append(f"bodies.{name}.region: holds no particles on this mesh")
        for i, v in enumerate(b["velocity"] or []):
            P.v[:, i] = Expression(v)(P.x.T) if isinstance(v, str) else v
        if b["stress"] is not None:
            mat = materials[k]
            K0 = b["stress"]["K0"] if b["stress"]["K0"] is not None else mat.nu / (1.0 - mat.nu)
            g = float(np.linalg.norm(gravity))
            P.sigma = geostatic_stress(P.x, mat.rho, g, b["stress"]["surface"], K0, grid.gdim)
        P.ensure_state(state_fields)
        if particles is None:
            particles = P
        else:
            particles.extend(P)

    walls = {}
    for name, w in cfg["walls"].items():
        nodes = grid.nodes_where(_make_region(w["region"], tol))
        if comm.allreduce(len(nodes), MPI.SUM) == 0:
            errors.append(f"walls.{name}.region: holds no grid nodes")
        if w["type"] == "fixed":
            walls[name] = FixedBC(nodes)
        elif w["type"] == "slip":
            walls[name] = SlipBC(nodes, normal=tuple(w["normal"]))
        elif w["type"] == "frictional":
            mu = math.tan(math.radians(w["friction_angle"]))
            walls[name] = FrictionalWall(nodes, normal=tuple(w["normal"]), mu=mu)
        else:
            walls[name] = VelocityBC(nodes, velocity=np.array(w["velocity"]))
    if errors:
        raise ScenarioError(errors)

    sinks = [Sink(name, region=_make_region(s["region"], tol)) for name, s in cfg["sinks"].items()]
    n = cfg["nonlocal"]
    averaging = NonlocalAverage(n["radius"], n["weight"], n["skin"]) if n["radius"] > 0.0 else None
    s = cfg["solver"]
    solver = Solver(
        grid, particles, materials, bcs=list(walls.values()), gravity=gravity, sinks=sinks,
        averaging=averaging, **{k: s[k] for k in ("on_exit", *_SOLVER)},
    )  # fmt: skip
    start = cfg["time"]["start"]
    # A negative start is whole steps before t = 0, so that t = 0 (an opening, say) is a step.
    solver.time = -math.ceil(-start / solver.dt) * solver.dt if start < 0.0 else start
    return Simulation(cfg, solver, walls, applied=[])
