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
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

try:
    import tomllib
except ModuleNotFoundError:  # Python < 3.11
    import tomli as tomllib

from mpi4py import MPI

from dolfin_mpm.app.regions import Expression, Region
from dolfin_mpm.averaging.law import LAWS, MIX, NonlocalLaw
from dolfin_mpm.averaging.nonlocal_average import WEIGHTS, NonlocalAverage
from dolfin_mpm.core import compat
from dolfin_mpm.core.boundary import FixedBC, FrictionalWall, SlipBC, VelocityBC
from dolfin_mpm.core.grid import Grid
from dolfin_mpm.core.particles import Sink
from dolfin_mpm.core.seeding import geostatic_stress, reference_points, seed
from dolfin_mpm.core.walls import RigidWall
from dolfin_mpm.explicit.options import (
    INTEGERS,
    LIGHT_NODES,
    QUADRATURE,
    SCHEMES,
    STRESS,
    VOLUMETRIC,
    Options,
)
from dolfin_mpm.explicit.solver import Solver
from dolfin_mpm.io import xdmf
from dolfin_mpm.io.groups import read_groups
from dolfin_mpm.materials import DruckerPragerViscoplastic, LinearElastic
from dolfin_mpm.parallel import partition
from dolfin_mpm.params import Range, parameters

__all__ = [
    "BYTES_PER_CELL", "BYTES_PER_PAIR", "BYTES_PER_PARTICLE", "MAX_STEPS", "MODELS", "ScenarioError",
    "Simulation", "apply_overrides", "available_memory", "build", "load", "parse", "validate",
]  # fmt: skip

INF = math.inf
#: What a run needs per mesh cell and per material point [bytes], on the safe side (the silo
#: measured about 0.5 kB each; non-local averaging's neighbour lists come on top). Sizes are
#: checked against the available memory before anything is allocated.
BYTES_PER_CELL, BYTES_PER_PARTICLE = 1000, 2000
#: ... and per pair of particles that non-local averaging weighs (index, weight, spare room).
BYTES_PER_PAIR = 32
#: Most time steps of a run, and the largest ``|t| / dt``: the time keeps about 12 bits below
#: each step (a float has 52), so that ``t + dt`` still advances the time accurately.
MAX_STEPS = 1e12
#: Most cells along an axis of a generated mesh (DOLFINx counts them in 32 bits).
_MAX_CELLS = 2**31 - 1


#: Material models by name: class and its parameters (ranges, units, defaults), as the class
#: declares them.
MODELS = {
    name: (cls, parameters(cls))
    for name, cls in (("elastic", LinearElastic), ("drucker_prager", DruckerPragerViscoplastic))
}
_WALLS = ("fixed", "slip", "frictional", "velocity")
#: The keys of a wall given as geometry (:class:`~dolfin_mpm.core.walls.RigidWall`): the
#: dimension of its points, and the least and most points (0: no limit).
_GEOMETRY = {"segment": (2, 2, 2), "polygon": (2, 2, 0), "facet": (3, 3, 0)}
_DIAGONALS = ("right", "left", "crossed", "right/left", "left/right")
#: The ``[solver]`` options but ``gravity`` and ``on_exit``: (kind, default, interval or
#: choices), as :class:`~dolfin_mpm.explicit.options.Options` declares them.
_SOLVER = {
    "scheme": ("string", Options.scheme, SCHEMES),
    "volumetric": ("string", Options.volumetric, VOLUMETRIC),
    "stress": ("string", Options.stress, STRESS),
    "quadrature": ("string", Options.quadrature, QUADRATURE),
    "light_nodes": ("string", Options.light_nodes, LIGHT_NODES),
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


def _finite(a) -> bool:
    """Whether ``a`` is not a number (left to the type check) or a finite one."""
    return not isinstance(a, (int, float)) or isinstance(a, bool) or math.isfinite(a)


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
        #: Whether the mesh is read from a file (whose physical groups a region may name by tag).
        self.mesh_file = False

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
        self,
        t: dict,
        path: str,
        key: str,
        kind: str,
        default=None,
        required=False,
        check=None,
        size=0,
        finite=True,
    ):
        """``t[key]`` of ``kind`` (number, integer, string, bool, numbers, strings, vector).

        ``check`` is a :class:`~dolfin_mpm.params.Range` or a tuple of choices; ``size`` the length of a
        ``numbers`` array (0: any). Numbers without a range must be finite unless ``finite`` is
        false. Returns ``default`` when missing or bad.
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
        values = v if isinstance(v, list) else [v]
        if check is None and finite and not all(map(_finite, values)):
            self.fail(where, f"must be finite, got {_show(v)}")
            return default
        if isinstance(check, Range):
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

    def region(self, t: dict, path: str, key: str, gdim: int, required=True, tag=True):
        """A region: ``{min, max}`` box, an array of boxes (their union) or an expression string.

        Where ``tag``, also ``{tag = k}``: the physical group k of the mesh file.
        """
        where = f"{path}.{key}"
        if key not in t:
            if required:
                self.fail(
                    where, "missing (a {min = [...], max = [...]} box, an array of boxes or an expression)"
                )
            return None
        v = t[key]
        if isinstance(v, dict) and "tag" in v:
            self.keys(v, where, ("tag",))
            number = self.value(
                v, where, "tag", "integer", required=True, check=Range(1, INF, closed=(True, False))
            )
            if not tag:
                self.fail(
                    where, "a tag is for bodies and walls (a sink acts where particles are): give a box"
                )
            elif not self.mesh_file:
                self.fail(where, 'a tag names a physical group of a mesh file (mesh.shape = "file")')
            return None if number is None or not tag or not self.mesh_file else {"tag": number}
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
            lo = self.value(b, bpath, "min", "numbers", required=True, size=gdim, finite=False)
            hi = self.value(b, bpath, "max", "numbers", required=True, size=gdim, finite=False)
            for key, corner, sign in (("min", lo, -1.0), ("max", hi, 1.0)):
                if corner is not None and any(math.isnan(a) or a == -sign * INF for a in corner):
                    self.fail(
                        f"{bpath}.{key}",
                        f"must be numbers ({_show(sign * INF)} for no bound), got {_show(corner)}",
                    )
                    lo = hi = None
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
    except RecursionError:
        raise ScenarioError([f"{source}: arrays or tables nested too deeply"]) from None


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
        except RecursionError:
            errors.append(f"--set {item}: arrays or tables nested too deeply")
            continue
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
        text = path.read_bytes().decode("utf-8")
    except OSError as e:
        raise ScenarioError([f"{path}: cannot read ({e.strerror or e})"]) from None
    except UnicodeDecodeError as e:
        raise ScenarioError(
            [f"{path}: not UTF-8 text (byte 0x{e.object[e.start]:02x} at offset {e.start})"]
        ) from None
    data = parse(text, str(path))
    apply_overrides(data, overrides)
    return validate(data, path.parent if base is None else base)


# -- sizes ---------------------------------------------------------------------------------------
def available_memory() -> float | None:
    """Memory this machine can give without swapping [bytes]; ``None`` when unknown.

    ``MemAvailable`` of ``/proc/meminfo``, else the free physical pages; unknown: no size checks.
    """
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                key, _, value = line.partition(":")
                if key == "MemAvailable":
                    return float(value.split()[0]) * 1024.0  # given in kB
    except (OSError, ValueError, IndexError):
        pass
    try:
        return float(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (AttributeError, OSError, ValueError):
        return None


def _available_total(comm) -> float | None:
    """The available memory of the machines the ranks of ``comm`` run on, together (collective)."""
    machines = dict(comm.allgather((MPI.Get_processor_name(), available_memory())))
    return None if None in machines.values() else sum(machines.values())


def _needs(need: float, memory: float) -> str:
    return f"would need about {need / 1e9:.3g} GB, {memory / 1e9:.3g} GB available"


def _num_cells(mesh: dict) -> int:
    """The cell count of a generated mesh (triangles or tetrahedra)."""
    per_box = 6 if mesh["shape"] == "box" else 4 if mesh.get("diagonal") == "crossed" else 2
    return per_box * math.prod(mesh["cells"])


def _size_errors(cells: int, bodies: dict, memory: float | None, path: str) -> list[str]:
    """Problems of ``cells`` mesh cells with the particles of ``bodies`` in ``memory`` bytes.

    A body counts ``ppc`` particles in every cell: seeding lays them out before keeping those in
    its region.
    """
    if memory is None:
        return []
    ppc = {name: b["ppc"] for name, b in bodies.items()}
    need = cells * (BYTES_PER_CELL + sum(ppc.values()) * BYTES_PER_PARTICLE)
    if need <= memory:
        return []
    listed = ", ".join(f"{n} per cell of bodies.{name}" for name, n in ppc.items())
    problem = (
        f"{cells:,} cells and up to {cells * sum(ppc.values()):,} particles ({listed}) {_needs(need, memory)}"
    )
    # The mesh's fault if it does not fit with one particle per cell and body, else the largest ppc's.
    if cells * (BYTES_PER_CELL + len(ppc) * BYTES_PER_PARTICLE) > memory:
        return [f"{path}: {problem}"]
    return [f"bodies.{max(ppc, key=ppc.get)}.ppc: {problem}"]


# -- validation ----------------------------------------------------------------------------------
def validate(data: dict, base: Path = Path(".")) -> dict:
    """Check the whole scenario; returns it normalised with defaults, or raises :class:`ScenarioError`."""
    c = _Checker()
    cfg = _scenario(c, data, Path(base))
    if c.errors:
        raise ScenarioError(c.errors)
    return cfg


def _scenario(c: _Checker, data: dict, base: Path) -> dict:
    """The scenario ``data`` normalised with defaults, its problems into ``c``."""
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
    # On several ranks, as if every rank had a machine like this one (build checks exactly).
    memory = available_memory()
    memory = None if memory is None else memory * MPI.COMM_WORLD.size
    cfg["mesh"], gdim = _mesh(c, c.table(data, "mesh", ""), base)
    c.mesh_file = cfg["mesh"].get("shape") == "file"
    cfg["materials"] = {
        name: _material(c, t, f"materials.{name}") for name, t in c.named_tables(data, "materials").items()
    }
    cfg["nonlocal"] = _nonlocal(c, c.table(data, "nonlocal", "", required=False), cfg["materials"])
    cfg["sinks"] = {}
    for name, t in c.named_tables(data, "sinks", False).items():
        c.keys(t, f"sinks.{name}", ("region",))
        cfg["sinks"][name] = {"region": c.region(t, f"sinks.{name}", "region", gdim, tag=False)}
    cfg["solver"] = _solver(c, c.table(data, "solver", "", required=False) or {}, gdim, cfg["sinks"])
    cfg["bodies"] = {
        name: _body(c, t, f"bodies.{name}", gdim, cfg["materials"], cfg["solver"]["gravity"], memory)
        for name, t in c.named_tables(data, "bodies").items()
    }
    if cfg["mesh"].get("cells"):  # a generated mesh with valid cell counts
        c.errors += _size_errors(_num_cells(cfg["mesh"]), cfg["bodies"], memory, "mesh.cells")
    cfg["walls"] = {
        name: _wall(c, t, f"walls.{name}", gdim) for name, t in c.named_tables(data, "walls", False).items()
    }
    cfg["time"] = _time(c, c.table(data, "time", ""))
    cfg["events"] = _events(c, data.get("events", []), cfg["time"], cfg["walls"])
    cfg["output"] = _output(
        c, c.table(data, "output", "", required=False) or {}, cfg["time"], cfg["materials"], gdim
    )
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
        ("shape", "lower", "upper", "cells", "diagonal", "partition")
        if gdim == 2
        else ("shape", "lower", "upper", "cells", "partition"),
    )
    lower = c.value(t, "mesh", "lower", "numbers", required=True, size=gdim)
    upper = c.value(t, "mesh", "upper", "numbers", required=True, size=gdim)
    if lower and upper and not all(a < b for a, b in zip(lower, upper)):
        c.fail(
            "mesh.upper", f"must exceed mesh.lower = {_show(lower)} in every component, got {_show(upper)}"
        )
        lower = upper = None
    if lower and upper and not all(math.isfinite(b - a) for a, b in zip(lower, upper)):
        c.fail("mesh.upper", f"upper - lower overflows, got {_show(upper)} and {_show(lower)}")
        lower = upper = None
    cells = c.value(
        t, "mesh", "cells", "numbers", required=True, size=gdim, check=Range(1, INF, closed=(True, False))
    )
    if cells is not None and not all(float(n).is_integer() for n in cells):
        c.fail("mesh.cells", f"must be whole numbers, got {_show(cells)}")
        cells = None
    if cells is not None and max(cells) > _MAX_CELLS:
        c.fail("mesh.cells", f"must be at most {_MAX_CELLS} along an axis, got {_show(cells)}")
        cells = None
    if cells and lower and upper:
        h = [(b - a) / n for a, b, n in zip(lower, upper, cells)]
        coordinate = max(map(abs, lower + upper))
        if not all(hk > 1e-10 * coordinate for hk in h) or not 0.0 < math.prod(h) < INF:
            c.fail(
                "mesh.cells",
                f"cells of {' x '.join(f'{hk:g}' for hk in h)} m at coordinates up to {coordinate:g} m: "
                "below the precision of the coordinates, or a cell volume that is not a finite number",
            )
    m = {
        "shape": shape,
        "lower": lower,
        "upper": upper,
        "cells": cells and [int(n) for n in cells],
        "gdim": gdim,
    }
    if gdim == 2:
        m["diagonal"] = c.value(t, "mesh", "diagonal", "string", default="right", check=_DIAGONALS)
    # The axes the ranks' cuts go across, in turn ("x": strips across x); default: each cut across
    # the longest extent of what it cuts.
    m["partition"] = c.value(t, "mesh", "partition", "string", default=None)
    axes = "xyz"[:gdim]
    if m["partition"] is not None and not (m["partition"] and set(m["partition"]) <= set(axes)):
        c.fail(
            "mesh.partition",
            f'must be axes of {_show(axes)} in the order of the cuts, e.g. "x", got {_show(m["partition"])}',
        )
        m["partition"] = None
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
            material = cls(**{k: m[k] for k in params})
        except ValueError as e:  # a check across parameters ("psi must be in [0, phi]")
            name, _, problem = str(e).partition(" ")
            c.fail(f"{path}.{name}", problem)
            return m
        m["state"] = list(material.state_fields())
        try:
            with np.errstate(all="ignore"):
                speed = material.p_wave_speed()
        except ArithmeticError:
            speed = INF
        if not 0.0 < speed < INF:  # the explicit time step is h / speed
            c.fail(
                f"{path}.E",
                f"with rho = {_show(m['rho'])} the p-wave speed is {speed:g} m/s, not a positive "
                "finite number (the moduli or E / rho overflow or underflow)",
            )
    return m


def _nonlocal(c: _Checker, t: dict | None, materials: dict) -> dict:
    if t is None:
        return {
            "radius": 0.0, "weight": "cubic", "skin": None, "law": "max", "m": None,
            "boundary_correction": False,
        }  # fmt: skip
    c.keys(t, "nonlocal", ("radius", "weight", "skin", "law", "m", "boundary_correction"))
    n = {
        "radius": c.value(t, "nonlocal", "radius", "number", 0.0, True, NonlocalAverage.RADIUS),
        "weight": c.value(t, "nonlocal", "weight", "string", "cubic", check=tuple(WEIGHTS)),
        "skin": c.value(t, "nonlocal", "skin", "number", None, check=NonlocalAverage.SKIN),
        "law": c.value(t, "nonlocal", "law", "string", "max", check=LAWS),
        "m": None,
        "boundary_correction": c.value(t, "nonlocal", "boundary_correction", "bool", False),
    }
    law = t.get("law", "max")  # m is checked against a valid law only
    if "m" in t and law in LAWS and law != "overnonlocal":
        c.fail("nonlocal.m", f'the factor of law "overnonlocal" alone, got it with law "{law}"')
    else:
        n["m"] = c.value(t, "nonlocal", "m", "number", None, check=MIX)
        if law == "overnonlocal" and "m" not in t:
            c.fail("nonlocal.m", f'missing: law "overnonlocal" needs its factor m ({MIX.describe()})')
    if n["law"] not in ("max", None) and n["weight"] not in ("wendland", None):
        c.fail(
            "nonlocal.law",
            f'"{n["law"]}" needs the positive-definite weight "wendland" (nonlocal.weight), '
            f'got "{n["weight"]}"',
        )
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
    if not math.isfinite(math.hypot(*s["gravity"])):
        c.fail("solver.gravity", f"its magnitude overflows, got {_show(s['gravity'])}")
        s["gravity"] = [0.0] * gdim
    for name, (kind, default, check) in _SOLVER.items():
        s[name] = c.value(t, "solver", name, kind, default, check=check)
    s["on_exit"] = c.value(t, "solver", "on_exit", "string", "error", check=("error", *sinks))
    return s


def _body(c: _Checker, t: dict, path: str, gdim: int, materials: dict, gravity, memory) -> dict:
    c.keys(t, path, ("material", "ppc", "region", "velocity", "stress"))
    b = {
        "material": c.value(t, path, "material", "string", required=True, check=tuple(materials)),
        "ppc": c.value(t, path, "ppc", "integer", 4, check=Range(1, INF, closed=(True, False))),
        "region": c.region(t, path, "region", gdim, required=False),
        "velocity": c.vector(t, path, "velocity", gdim),
        "stress": None,
    }
    if memory is not None and b["ppc"] * BYTES_PER_PARTICLE > memory:
        c.fail(
            f"{path}.ppc", f"{b['ppc']} particles in one cell {_needs(b['ppc'] * BYTES_PER_PARTICLE, memory)}"
        )
        b["ppc"] = 1
    try:
        reference_points(gdim, b["ppc"])
    except ValueError as e:
        c.fail(f"{path}.ppc", str(e).removeprefix("ppc "))
        b["ppc"] = 1  # no second problem from its size
    except MemoryError:
        c.fail(f"{path}.ppc", f"{b['ppc']} particles in one cell do not fit in memory")
        b["ppc"] = 1
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
    if any(k in t for k in _GEOMETRY):
        return _rigid_wall(c, t, path, gdim, kind)
    extra = {"slip": ("normal",), "frictional": ("normal", "friction_angle"), "velocity": ("velocity",)}
    c.keys(t, path, ("type", "region", *extra.get(kind, ())))
    w = {"type": kind, "region": c.region(t, path, "region", gdim)}
    if kind in ("slip", "frictional"):
        w["normal"] = c.value(t, path, "normal", "numbers", required=True, size=gdim)
        if w["normal"] is not None and not any(w["normal"]):
            c.fail(f"{path}.normal", "must be a non-zero vector")
    if kind == "frictional":
        w["friction_angle"] = _friction_angle(c, t, path)
    if kind == "velocity":
        w["velocity"] = c.value(t, path, "velocity", "numbers", required=True, size=gdim)
    return w


def _friction_angle(c: _Checker, t: dict, path: str) -> float:
    return c.value(t, path, "friction_angle", "number", 0.0, check=Range(0.0, 90.0, "degrees", (True, False)))


def _rigid_wall(c: _Checker, t: dict, path: str, gdim: int, kind: str) -> dict:
    """A rigid wall as geometry: ``segment``, ``polygon`` (a chain of segments) or ``facet``.

    In 2D ``segment = [[x0, y0], [x1, y1]]`` or ``polygon = [[x, y], ...]``; in 3D
    ``facet = [[x, y, z], ...]``, a flat convex polygon.
    """
    given = [k for k in _GEOMETRY if k in t]
    key = given[0]
    w = {"type": kind, "region": None, key: None, "friction_angle": 0.0}
    if len(given) > 1:
        c.fail(path, f"give one of {', '.join(_GEOMETRY)}, not {' and '.join(given)}")
        return w
    c.keys(t, path, ("type", key, *(("friction_angle",) if kind == "frictional" else ())))
    if kind not in ("slip", "frictional"):
        c.fail(f"{path}.type", f"a wall given as a {key} is 'slip' or 'frictional', got {_show(kind)}")
        return w
    dim, least, most = _GEOMETRY[key]
    if dim != gdim:
        allowed = " or ".join(f"a {k}" for k, (d, _, _) in _GEOMETRY.items() if d == gdim)
        c.fail(f"{path}.{key}", f"walls as geometry in {gdim}D are {allowed}, got a {key} (or use a region)")
        return w
    points = t[key]
    shape_ok = (
        isinstance(points, list)
        and least <= len(points) <= (most or len(points))
        and all(isinstance(p, list) and len(p) == gdim for p in points)
        and all(isinstance(a, (int, float)) and not isinstance(a, bool) for p in points for a in p)
    )
    if not shape_ok:
        count = {"segment": "two points", "polygon": "two or more points", "facet": "three or more points"}[
            key
        ]
        form = "[[x, y], ...]" if gdim == 2 else "[[x, y, z], ...]"
        c.fail(f"{path}.{key}", f"must be {count} {form} of numbers, got {_show(points)}")
        return w
    if kind == "frictional":
        w["friction_angle"] = _friction_angle(c, t, path)
    try:
        for piece in _pieces(key, points):
            RigidWall(piece, name=f"{path}.{key}")
    except ValueError as e:
        c.fail(f"{path}.{key}", str(e).split(": ", 1)[1])
        return w
    w[key] = [[float(a) for a in p] for p in points]
    return w


def _pieces(key: str, points: list) -> list:
    """The points of each :class:`RigidWall` of a wall given as ``key``: a polygon's segments."""
    return [points[k : k + 2] for k in range(len(points) - 1)] if key == "polygon" else [points]


def _time(c: _Checker, t: dict | None) -> dict:
    if t is None:
        return {"start": 0.0, "end": 0.0}
    c.keys(t, "time", ("start", "end"))
    start = c.value(t, "time", "start", "number", 0.0, check=Range(-INF, INF))
    end = c.value(t, "time", "end", "number", None, True, Range(start, INF, "s"))
    if end is not None and not math.isfinite(end - start):
        c.fail("time.end", f"end - start overflows, got {_show(end)} and {_show(start)}")
        end = None
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
    keys = ("interval", "xdmf", "layout", "checkpoint_interval", "figures", "figure_field", "figure_interval")
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
        "layout": c.value(t, "output", "layout", "string", "auto", check=("auto", *xdmf.LAYOUTS)),
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
    if o["layout"] not in ("auto", None):
        try:
            xdmf.check_layout(o["layout"])
        except ValueError as e:
            c.fail("output.layout", str(e).removeprefix("output layout: "))
    return o


# -- building ------------------------------------------------------------------------------------
@dataclass
class Simulation:
    """A built scenario: the solver with everything it holds, and the scheduled events.

    Attributes:
        config: the validated scenario.
        solver: the solver (grid, particles, materials, walls, sinks, averaging).
        walls: the boundary conditions of each named wall (a rigid wall's segments or facet), in file order.
        applied: indices of ``config["events"]`` already applied.

    """

    config: dict
    solver: Solver
    walls: dict[str, list]
    applied: list[int]

    def apply_event(self, k: int) -> None:
        """Apply event ``k``: remove its walls, set its damping."""
        event = self.config["events"][k]
        gone = {id(bc) for name in event["remove_walls"] for bc in self.walls[name]}
        self.solver.bcs = [bc for bc in self.solver.bcs if id(bc) not in gone]
        if event["damping"] is not None:
            self.solver.damping = event["damping"]
        self.applied.append(k)

    def discharged_mass(self) -> float:
        """Mass absorbed by all sinks [kg] (per metre in 2D), summed over ranks."""
        local = sum(s.mass for s in self.solver.sinks.values())
        return self.solver.comm.allreduce(local, MPI.SUM)


def _make_region(spec: dict, tol: float) -> Region:
    """The region of a box or expression spec (a tag's cells and nodes come from :func:`read_groups`)."""
    if "expression" in spec:
        return Region(expression=Expression(spec["expression"]))
    return Region(boxes=spec["boxes"], tol=tol)


def _make_mesh(m: dict, comm, bodies: dict | None = None):
    if m["shape"] == "file":
        return compat.read_mesh(comm, m["file"], m["gdim"])
    # On several ranks, cells dealt in coordinate bisection of the particles the bodies will seed
    # in them: the same partition in every run, which a resumed run needs (DOLFINx's graph
    # partitioners may cut differently each time).
    corners = [np.array(m["lower"]), np.array(m["upper"])]
    weight = _seeded(bodies or {}, 1e-9 * float(np.max(corners[1] - corners[0])))
    axes = None if m.get("partition") is None else tuple("xyz".index(a) for a in m["partition"])
    if m["shape"] == "box":
        return partition.create_box(comm, corners, m["cells"], weight=weight, axes=axes)
    return partition.create_rectangle(
        comm, corners, m["cells"], weight=weight, axes=axes, diagonal=m["diagonal"]
    )


def _seeded(bodies: dict, tol: float):
    """Each cell's weight: the particles per cell of the bodies whose region holds its centroid.

    Cells no body holds weigh nothing, so that every rank starts with about as many particles.
    By count where no cell would weigh anything, or a region fails (it is named later, on the
    nodes).
    """

    def weight(c: np.ndarray) -> np.ndarray:  # c: cell centroids, shape=(3, n)
        w = np.zeros(c.shape[1])
        try:
            for b in bodies.values():
                inside = np.ones(c.shape[1]) if b["region"] is None else _make_region(b["region"], tol)(c)
                w += b["ppc"] * np.asarray(inside, dtype=bool)
        except Exception:  # the region's own check on the nodes names the problem
            return np.ones(c.shape[1])
        return w if w.sum() > 0.0 else np.ones(c.shape[1])

    return weight


def _agree(comm, errors: list[str]) -> list[str]:
    """The problems found on any rank, in order, on every rank (collective)."""
    return list(dict.fromkeys(e for rank in comm.allgather(errors) for e in rank))


def _regions(cfg: dict):
    """``(TOML path, region spec)`` of every body, wall and sink."""
    for table in ("bodies", "walls", "sinks"):
        for name, t in cfg[table].items():
            if t["region"]:
                yield f"{table}.{name}.region", t["region"]


def _evaluate(errors: list[str], path: str, region: Region, x: np.ndarray) -> None:
    """Evaluate ``region`` at the points ``x`` (``shape=(3, n)``), a problem into ``errors``."""
    try:
        region(x)
    except ValueError as e:
        errors.append(f"{path}: {e}")


def build(cfg: dict, comm=MPI.COMM_WORLD) -> Simulation:
    """The objects of a validated scenario, at its start time (collective over ``comm``).

    Every region and field expression is evaluated once on the mesh's nodes or the seeded
    particles, so that one that fails at run time fails here; sizes are checked against the
    available memory before the mesh and the particles are made.

    Raises:
        ScenarioError: problems only the mesh reveals (a wall that holds no node, a body with
            no particle, a mesh of the wrong dimension, an expression that fails on the
            mesh, a time step that makes the run too long), each with its TOML path.

    """
    memory = _available_total(comm)
    if cfg["mesh"]["shape"] != "file":
        errors = _size_errors(_num_cells(cfg["mesh"]), cfg["bodies"], memory, "mesh.cells")
        if errors:
            raise ScenarioError(errors)
    try:
        grid = Grid(_make_mesh(cfg["mesh"], comm, cfg["bodies"]))
    except (ValueError, RuntimeError, OSError, MemoryError) as e:
        key = "mesh.file" if cfg["mesh"]["shape"] == "file" else "mesh"
        raise ScenarioError([f"{key}: {str(e) or 'out of memory'}"]) from None
    if grid.gdim != cfg["mesh"]["gdim"]:
        raise ScenarioError(
            [f"mesh.gdim: the mesh has dimension {grid.gdim}, the scenario says {cfg['mesh']['gdim']}"]
        )
    if cfg["mesh"]["shape"] == "file":
        cells = grid.mesh.topology.index_map(grid.mesh.topology.dim).size_global
        errors = _size_errors(cells, cfg["bodies"], memory, "mesh.file")
        if errors:
            raise ScenarioError(errors)
    lo, hi = grid.node_x.min(axis=0, initial=INF), grid.node_x.max(axis=0, initial=-INF)
    extent = comm.allreduce(float(np.max(hi - lo, initial=0.0)), MPI.MAX)
    tol = 1e-9 * extent
    diagonal = math.hypot(
        *(comm.allreduce(float(b), MPI.MAX) - comm.allreduce(float(a), MPI.MIN) for a, b in zip(lo, hi))
    )

    # Every region once on the nodes: an expression that fails or is not a condition; a tag
    # that names no group of its kind in the file.
    nodes = np.ascontiguousarray(grid.node_x.T)
    errors = []
    tagged = any("tag" in spec for _, spec in _regions(cfg))
    groups = read_groups(comm, cfg["mesh"]["file"], grid) if tagged else None
    for path, spec in _regions(cfg):
        if "tag" not in spec:
            _evaluate(errors, path, _make_region(spec, tol), nodes)
        elif not _has_group(groups, spec["tag"], path.startswith("bodies."), comm):
            kind = (
                f"cells of dimension {grid.gdim}"
                if path.startswith("bodies.")
                else "lower-dimensional elements"
            )
            errors.append(
                f"{path}: tag {spec['tag']} names no physical group of {kind} in {cfg['mesh']['file']} "
                f"(it has {groups.describe()})"
            )
    errors = _agree(comm, errors)
    if errors:
        raise ScenarioError(errors)

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
        tag = (b["region"] or {}).get("tag")
        where = _make_region(b["region"], tol) if b["region"] and tag is None else None
        cells = None if tag is None else groups.cell_tags[: grid.num_owned_cells] == tag
        try:
            P = seed(grid, materials[k], ppc=b["ppc"], where=where, material_index=k, cells=cells)
        except ValueError as e:
            errors.append(f"bodies.{name}.region: {e}")
            P = None
        except MemoryError:
            errors.append(f"bodies.{name}.ppc: the particles do not fit in memory")
            P = None
        if comm.allreduce(0 if P is None else len(P), MPI.SUM) == 0 and P is not None:
            errors.append(f"bodies.{name}.region: holds no particles on this mesh")
        if b["stress"] is not None:  # collective: on every rank, with particles or not
            top = comm.allreduce(
                -INF if P is None else float(np.max(P.x[:, grid.gdim - 1], initial=-INF)), MPI.MAX
            )
        if P is None:
            continue
        for i, v in enumerate(b["velocity"] or []):
            try:
                P.v[:, i] = Expression(v).numbers(P.x.T) if isinstance(v, str) else v
            except ValueError as e:
                errors.append(f"bodies.{name}.velocity[{i}]: {e}")
        if b["stress"] is not None:
            mat = materials[k]
            K0 = b["stress"]["K0"] if b["stress"]["K0"] is not None else mat.nu / (1.0 - mat.nu)
            g = math.hypot(*gravity)
            surface = b["stress"]["surface"]
            if surface < top:
                errors.append(
                    f"bodies.{name}.stress.surface: {_show(surface)} m lies below the body's top particle "
                    f"at {top:.6g} m: the geostatic stress would be tension above it"
                )
            with np.errstate(all="ignore"):
                P.sigma = geostatic_stress(P.x, mat.rho, g, surface, K0, grid.gdim)
            if not np.all(np.isfinite(P.sigma)):
                errors.append(
                    f"bodies.{name}.stress: the geostatic stress overflows (rho = {mat.rho:g} kg/m^3, "
                    f"g = {g:g} m/s^2, surface = {surface:g} m)"
                )
        if not (np.all(np.isfinite(P.mass)) and np.all(P.mass > 0.0) and np.all(P.volume > 0.0)):
            errors.append(
                f"bodies.{name}.material: particle masses rho * volume are not positive finite numbers "
                f"(rho = {materials[k].rho:g} kg/m^3)"
            )
        P.ensure_state(state_fields)
        if particles is None:
            particles = P
        else:
            particles.extend(P)

    # The sinks also on the particles (they act on particle positions at every step).
    if particles is not None:
        for name, spec in cfg["sinks"].items():
            _evaluate(errors, f"sinks.{name}.region", _make_region(spec["region"], tol), particles.x.T)

    walls = {}
    for name, w in cfg["walls"].items():
        if w["region"] is None:  # a rigid wall as geometry: one RigidWall per segment or facet
            key = next(k for k in _GEOMETRY if w.get(k))
            mu = math.tan(math.radians(w["friction_angle"]))
            walls[name] = [RigidWall(piece, mu, f"walls.{name}.{key}") for piece in _pieces(key, w[key])]
            for wall in walls[name] if particles is not None else ():
                try:
                    wall.check(grid, particles)
                except ValueError as e:
                    errors.append(str(e))
            continue
        if "tag" in w["region"]:
            nodes = groups.node_tags[w["region"]["tag"]]
        else:
            nodes = grid.nodes_where(_make_region(w["region"], tol))
        if comm.allreduce(len(nodes), MPI.SUM) == 0:
            errors.append(f"walls.{name}.region: holds no grid nodes")
        if w["type"] == "fixed":
            walls[name] = [FixedBC(nodes)]
        elif w["type"] == "slip":
            walls[name] = [SlipBC(nodes, normal=tuple(w["normal"]))]
        elif w["type"] == "frictional":
            mu = math.tan(math.radians(w["friction_angle"]))
            walls[name] = [FrictionalWall(nodes, normal=tuple(w["normal"]), mu=mu)]
            # unilateral: a normal into the material lets it through (collective on every rank)
            reach = comm.allreduce(float(np.max(grid.cell_height, initial=0.0)), MPI.MAX)
            x = particles.x if particles is not None else np.zeros((0, 3))
            into, out = comm.allreduce(np.array(walls[name][0].sides(grid.node_x, x, reach)))
            if into > out:
                errors.append(
                    f"walls.{name}.normal: {_show(w['normal'])} points into the material ({into} of "
                    f"the {into + out} particles within a cell of its nodes lie on the side it points "
                    "to): a frictional wall's normal points out of the material, into the wall"
                )
        else:
            walls[name] = [VelocityBC(nodes, velocity=np.array(w["velocity"]))]
    errors = _agree(comm, errors)
    if errors:
        raise ScenarioError(errors)
    errors = _averaging_errors(cfg["nonlocal"], particles, grid.gdim, diagonal, memory, comm)
    if errors:
        raise ScenarioError(errors)

    sinks = [Sink(name, region=_make_region(s["region"], tol)) for name, s in cfg["sinks"].items()]
    n = cfg["nonlocal"]
    averaging = (
        NonlocalAverage(
            n["radius"], n["weight"], n["skin"], NonlocalLaw(n["law"], n["m"]), n["boundary_correction"]
        )
        if n["radius"] > 0.0
        else None
    )
    s = cfg["solver"]
    try:
        solver = Solver(
            grid, particles, materials, bcs=[bc for bcs in walls.values() for bc in bcs], gravity=gravity,
            sinks=sinks,
            averaging=averaging, **{k: s[k] for k in ("on_exit", *_SOLVER)},
        )  # fmt: skip
    except ValueError as e:
        raise ScenarioError([f"solver: {e}"]) from None
    if cfg["mesh"].get("partition") is not None:  # a rebalance cuts as the start did
        solver.partition_axes = tuple("xyz".index(a) for a in cfg["mesh"]["partition"])
    interval = cfg["output"]["interval"]
    if s["dt"] is None and 0.0 < solver.dt < INF and interval / solver.dt < MAX_STEPS:
        solver.fit_step(interval)  # outputs at exact multiples of the interval
    errors = _step_errors(cfg, solver.dt)
    if errors:
        if solver.start_speed > max(m.p_wave_speed() for m in materials):  # the bodies set the step
            speed = f"{solver.start_speed:.3g} m/s"
            errors = [
                f"{e} (the particles' speed at the start, {speed}, sets it: bodies.*.velocity)"
                for e in errors
            ]
        raise ScenarioError(errors)
    start = cfg["time"]["start"]
    # A negative start is whole steps before t = 0, so that t = 0 (an opening, say) is a step.
    solver.time = -math.ceil(-start / solver.dt - 1e-9) * solver.dt if start < 0.0 else start
    return Simulation(cfg, solver, walls, applied=[])


def _has_group(groups, tag: int, of_cells: bool, comm) -> bool:
    """Whether the file's physical group ``tag`` holds cells (``of_cells``) or lower-dimensional elements."""
    if of_cells:
        return comm.allreduce(bool(np.any(groups.cell_tags == tag)), MPI.LOR)
    return tag in groups.node_tags


def _averaging_errors(n: dict, particles, gdim: int, diagonal: float, memory, comm) -> list[str]:
    """Problems of the non-local radius and skin on this mesh with these particles (collective)."""
    if n["radius"] == 0.0:
        return []
    skin = 0.25 * n["radius"] if n["skin"] is None else n["skin"]
    reach = n["radius"] + skin
    if n["radius"] < 1e-9 * diagonal:
        return [
            f"nonlocal.radius: must be at least 1e-9 times the mesh's diagonal {diagonal:g} m, "
            f"got {n['radius']:g}"
        ]
    if reach > 10.0 * diagonal:
        return [
            f"nonlocal.{'radius' if n['radius'] > skin else 'skin'}: radius + skin = {reach:g} m is more "
            f"than 10 times the mesh's diagonal {diagonal:g} m (every particle would weigh nearly alike)"
        ]
    count = comm.allreduce(len(particles), MPI.SUM)
    volume = comm.allreduce(float(np.sum(particles.volume)), MPI.SUM)
    ball = math.pi * reach * reach * (1.0 if gdim == 2 else 4.0 / 3.0 * reach)  # no OverflowError
    pairs = 0.5 * count * min(count, count * ball / volume)
    need = pairs * BYTES_PER_PAIR
    if memory is None or need <= memory:
        return []
    return [
        f"nonlocal.radius: about {pairs:.3g} pairs of particles within radius + skin = {reach:g} m "
        f"{_needs(need, memory)}"
    ]


def _step_errors(cfg: dict, dt: float) -> list[str]:
    """Problems of the time step ``dt`` [s]: the run's step count, the time's precision."""
    if not 0.0 < dt < INF:
        if cfg["solver"]["dt"] is not None:
            return [f"solver.dt: the time step is {dt:g} s, not a positive finite number"]
        return [
            f"mesh: the time step courant * smallest cell height / (p-wave speed + particle speed) "
            f"is {dt:g} s, not a positive finite number"
        ]
    start, end = cfg["time"]["start"], cfg["time"]["end"]
    steps, scale = (end - start) / dt, max(abs(start), abs(end)) / dt
    if steps > MAX_STEPS:
        return [
            f"time.end: the run from t = {start:g} s to {end:g} s would take more than {MAX_STEPS:g} steps "
            f"of {dt:.3g} s"
        ]
    if scale > MAX_STEPS:
        return [
            f"time.end: steps of {dt:.3g} s at t = {max(abs(start), abs(end)):g} s are below the time's "
            f"precision (|t| / dt above {MAX_STEPS:g})"
        ]
    return [
        f"output.{k}: {cfg['output'][k]:g} s is not a finite number of steps of {dt:.3g} s"
        for k in ("interval", "checkpoint_interval", "figure_interval")
        if not math.isfinite(cfg["output"][k] / dt)
    ]
