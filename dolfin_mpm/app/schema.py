"""The scenario format from its validator: a JSON Schema, a reference page and ``--explain``.

    dolfin-mpm schema -o scenario.schema.json            # JSON Schema (draft 2020-12)
    dolfin-mpm schema --reference -o docs/scenario.md    # the reference page
    dolfin-mpm check --explain materials.sand.phi        # one key: meaning, kind, range, default

The validator (:mod:`dolfin_mpm.app.scenario`) stays the one place that says which keys exist,
their kinds, ranges, choices and defaults and whether they are required: :func:`record` runs
it over example documents that together take every branch (every material model, wall type
and form, region form, mesh shape) with a checker that notes each table's allowed keys and
each value's checks. What only the meanings add is :data:`DESCRIPTIONS`, one line per key.

Editors that check TOML against a JSON Schema (Even Better TOML, Taplo) take it from a
comment on a scenario's first line: ``#:schema ./scenario.schema.json``.
"""

import dataclasses
import difflib
import functools
import math
import re
import tempfile
from dataclasses import dataclass
from pathlib import Path

from dolfin_mpm.app import scenario
from dolfin_mpm.params import Range

__all__ = [
    "DESCRIPTIONS", "VARIES", "Form", "Spec", "UnknownKey", "discriminators", "explain", "record",
    "reference", "schema",
]  # fmt: skip

#: What a check or a default is when it depends on the rest of the scenario (the materials'
#: names, the mesh's dimension, the run's times).
VARIES = "depends on the scenario"
#: The name that stands for every name of a named table, ``materials.<name>.phi``.
NAME = "<name>"

#: One line per key, by normalised path: what it means, with its unit.
DESCRIPTIONS = {
    "title": "title of the run, shown in its summary",
    "mesh": "the background grid",
    "mesh.shape": 'a generated "rectangle" (2D triangles) or "box" (3D tetrahedra), or a mesh "file"',
    "mesh.file": "mesh file, relative to the scenario's folder: DOLFINx XDMF or anything meshio reads "
    "(gmsh .msh)",
    "mesh.gdim": "dimension of the mesh file's geometry",
    "mesh.lower": "lower corner of the generated mesh [m]",
    "mesh.upper": "upper corner of the generated mesh [m], above mesh.lower in every component",
    "mesh.cells": "cells along each axis (whole numbers)",
    "mesh.diagonal": 'how each square of the rectangle is cut into triangles ("crossed": four, which do '
    'not lock in isochoric plastic flow; two lock unless solver.volumetric = "nodal")',
    "mesh.partition": 'axes the ranks\' cuts go across, in turn, at the start and in each rebalance ("x": '
    "strips across x; default: the longest extent of each part)",
    "materials": "the materials, one table per name, which bodies refer to",
    "materials.<name>.model": "the constitutive model",
    "materials.<name>.E": "Young's modulus [Pa]",
    "materials.<name>.nu": "Poisson's ratio [-]",
    "materials.<name>.rho": "mass density [kg/m^3]",
    "materials.<name>.phi": "angle of internal friction [degrees]",
    "materials.<name>.gamma": "viscosity parameter of the Perzyna law [1/s] (inf: rate independent)",
    "materials.<name>.N": "exponent of the viscosity law [-]",
    "materials.<name>.c": "cohesion [Pa]",
    "materials.<name>.rho_c": "critical density [kg/m^3], at most rho: below it a point is apart, stress "
    "free, and keeps its volume at m / rho_c (none: the volume follows the flow)",
    "nonlocal": "non-local averaging of the viscoplastic rate (needs a plastic material)",
    "nonlocal.radius": "support radius r of the average [m] (0: the local model)",
    "nonlocal.weight": "weight function over the ball of radius r",
    "nonlocal.skin": "extra search distance that lets pairs be reused [m] (default: r / 4)",
    "nonlocal.law": 'how the average enters the stress ("paper", "overstress" and "overnonlocal" need weight '
    '"wendland")',
    "nonlocal.m": 'factor m > 1 of law "overnonlocal", d = m A u + (1 - m) u (that law needs it)',
    "nonlocal.boundary_correction": "the weight a point misses beyond a free surface or a wall goes to "
    "its own value",
    "bodies": "the bodies of material points, one table per name",
    "bodies.<name>.material": "name of its material in [materials]",
    "bodies.<name>.ppc": "particles per cell: a square number on triangles, 8^l or 4 * 8^l on tetrahedra",
    "bodies.<name>.region": "where the body is seeded (default: the whole mesh)",
    "bodies.<name>.region.min": "lower corner of a box [m] (-inf: no bound)",
    "bodies.<name>.region.max": "upper corner of a box [m] (inf: no bound), >= min",
    "bodies.<name>.region.tag": "physical group of the mesh file whose cells the body fills",
    "bodies.<name>.velocity": "initial velocity [m/s]: numbers or expressions of x, y, z",
    "bodies.<name>.stress": "initial stress",
    "bodies.<name>.stress.type": "geostatic: the weight of the material above (needs solver.gravity)",
    "bodies.<name>.stress.surface": "height of the free surface above which nothing weighs [m], at or "
    "above the body's top",
    "bodies.<name>.stress.K0": "horizontal over vertical stress [-] (default: nu / (1 - nu))",
    "walls": "boundary conditions on grid nodes or rigid walls as geometry, applied in file order",
    "walls.<name>.type": "what the wall does to the velocity: hold it at rest, let it slip, slide with "
    "Coulomb friction, or prescribe it",
    "walls.<name>.region": "the grid nodes the wall holds",
    "walls.<name>.region.min": "lower corner of a box [m] (-inf: no bound)",
    "walls.<name>.region.max": "upper corner of a box [m] (inf: no bound), >= min",
    "walls.<name>.region.tag": "physical group of the mesh file whose lines (2D) or triangles, lines and "
    "points (3D) hold the wall's nodes",
    "walls.<name>.normal": "outward normal of a slip or frictional wall, out of the material into the "
    "wall (any length but 0)",
    "walls.<name>.friction_angle": "wall friction angle [degrees]: mu = tan(friction_angle)",
    "walls.<name>.velocity": "prescribed velocity of the nodes [m/s]",
    "walls.<name>.segment": "a 2D rigid wall [[x0, y0], [x1, y1]] [m], the material on its left going "
    "from the first point to the second",
    "walls.<name>.polygon": "a chain of 2D rigid walls [[x, y], ...] [m], the material on its left",
    "walls.<name>.facet": "a 3D rigid wall [[x, y, z], ...] [m]: a flat convex polygon, counter-clockwise "
    "seen from the material",
    "sinks": "regions that take particles out of the run and record what they carried",
    "sinks.<name>.region": "where particles are absorbed",
    "sinks.<name>.region.min": "lower corner of a box [m] (-inf: no bound)",
    "sinks.<name>.region.max": "upper corner of a box [m] (inf: no bound), >= min",
    "solver": "the explicit solver's settings",
    "solver.gravity": "gravitational acceleration [m/s^2], one number per axis (default: 0)",
    "solver.on_exit": '"error" to stop when a particle leaves the grid, or the name of the sink that '
    "takes it",
    "solver.scheme": "where the velocities of the strain rate come from: re-mapped momentum (MUSL) or the "
    "nodal solve (USL)",
    "solver.volumetric": "volumetric strain rate of each particle's cell, or averaged over the nodes' "
    'patches against locking ("nodal")',
    "solver.stress": "stress a particle carries into the next step: its cell's mean or its own",
    "solver.quadrature": "how the internal force integrates each cell: over the particles, or over the "
    "area of each cell the material fills",
    "solver.light_nodes": "nodes whose own stable step is below the step (in patches that hold little "
    'material): solved as the others, or tied to their neighbours ("aggregate")',
    "solver.flip": "FLIP fraction of the particle velocity update [-] (1: pure FLIP, 0: PIC)",
    "solver.damping": "local non-viscous (Cundall) damping factor [-]",
    "solver.damping_mean_time": "the damping opposes each node's departure from its running mean "
    "velocity over this time [s], leaving steady flow undamped (default: the velocity itself)",
    "solver.courant": "Courant factor of the automatic time step [-]",
    "solver.dt": "time step [s] (default: courant * smallest cell height / (p-wave speed + particle "
    "speed), shortened to a whole fraction of output.interval)",
    "solver.mass_tol": "nodes lighter than mass_tol * the largest nodal mass are left at rest [-]",
    "solver.fixed_point_tol": "tolerance of the step's fixed-point loop on the relative change of the "
    "internal forces [-]",
    "solver.fixed_point_max_iter": "most iterates of the fixed-point loop per step",
    "solver.relaxation": "under-relaxation of the fixed-point iterates [-]",
    "solver.anderson_depth": "depth of the fixed-point loop's Anderson acceleration (0: plain iteration)",
    "solver.extrapolation": "order of the fixed-point loop's first iterate, extrapolated from the last steps",
    "solver.rebalance": "under MPI, deal the cells to the ranks anew by their particles when the largest "
    "rank's particle count over the mean exceeds this [-] (default: never)",
    "solver.rebalance_interval": "steps between the checks of the ranks' particle imbalance",
    "time": "the span of the run",
    "time.start": "start time [s]; a negative start is whole steps before t = 0",
    "time.end": "end time [s], at or after time.start",
    "events": "changes at given times, [[events]], applied in time order (an outlet opening)",
    "events.time": "when the event acts [s], from time.start to time.end",
    "events.remove_walls": "names of the walls to remove",
    "events.damping": "new solver.damping from then on [-]",
    "output": "what the run writes",
    "output.interval": "time between outputs of particles, grid and history [s] (default: the run's span "
    "/ 50)",
    "output.xdmf": "write particles.xdmf and grid.xdmf",
    "output.layout": "how the ranks write them: gather (to rank 0, one file), collective (one file, each "
    "rank its rows; needs h5py with MPI), per-rank (a file per rank, one XDMF series); auto: gather on "
    "one rank, else collective where h5py has MPI, else per-rank",
    "output.checkpoint_interval": "time between checkpoints [s] (default: the run's span / 10)",
    "output.figures": "draw figures of the particles, the energy balance and the discharge",
    "output.figure_field": "particle field the figures colour by: speed, p, q, mass, volume, vx, vy, vz "
    "or a state field of the materials (eps_vp, ...)",
    "output.figure_interval": "time between particle figures [s] (default: the run's span / 5)",
}


@dataclass(frozen=True)
class Spec:
    """What the validator checks of one key in one form of its table, over the examples.

    Attributes:
        kind: a value's (``number``, ``integer``, ``string``, ``bool``, ``numbers``, ``strings``,
            ``vector``), or ``table``, ``tables`` (named, ``[key.<name>]``), ``region``,
            ``array`` (of tables, ``[[key]]``), ``geometry`` (a rigid wall's points).
        required: whether it is reported missing.
        default: its value when missing (``None``: none), or :data:`VARIES`.
        check: a :class:`~dolfin_mpm.params.Range`, a tuple of choices, ``None`` or :data:`VARIES`.
        sizes: the lengths an array takes (empty: any; 2 and 3: the mesh's dimension).
        finite: whether numbers without a range must be finite.

    """

    kind: str
    required: bool = False
    default: object = None
    check: object = None
    sizes: frozenset = frozenset()
    finite: bool = True


@dataclass
class Form:
    """One set of keys a table may have (the keys of a material model, of a wall type...).

    Attributes:
        keys: the allowed keys, in the validator's order.
        specs: each key's :class:`Spec`.
        seen: the values the examples gave each key with choices (what tells forms apart).
        alone: whether the form was seen as a table of its own.
        listed: whether it was seen in an array of tables (an array of boxes, ``[[events]]``).

    """

    keys: tuple
    specs: dict
    seen: dict
    alone: bool
    listed: bool


class _Recorder(scenario._Checker):
    """A checker that also notes, by TOML path, each table's allowed keys and each key's checks."""

    def __init__(self):
        super().__init__()
        self.tables: dict[str, tuple] = {}  # concrete table path -> allowed keys
        self.specs: dict[tuple, dict] = {}  # (concrete table path, key) -> the check's arguments
        self.seen: dict[tuple, object] = {}  # (concrete table path, key) -> a choice's value

    def _note(self, path: str, key: str, kind: str, **spec) -> None:
        spec = {**dataclasses.asdict(Spec(kind)), **spec}
        self.specs.setdefault((path, key), spec)  # the first: named_tables checks with table too

    def keys(self, table, path, allowed):
        self.tables[path] = tuple(allowed)
        super().keys(table, path, allowed)

    def table(self, parent, key, path, required=True):
        self._note(path, key, "table", required=required)
        return super().table(parent, key, path, required)

    def named_tables(self, parent, key, required=True):
        self._note("", key, "tables", required=required)
        return super().named_tables(parent, key, required)

    def value(self, t, path, key, kind, default=None, required=False, check=None, size=0, finite=True):
        self._note(path, key, kind, required=required, default=default, check=check,
                   sizes=frozenset([size]) if size else frozenset(), finite=finite)  # fmt: skip
        if isinstance(check, tuple) and key in t:
            self.seen[(path, key)] = t[key]
        return super().value(t, path, key, kind, default, required, check, size, finite)

    def region(self, t, path, key, gdim, required=True, tag=True):
        self._note(path, key, "region", required=required)
        return super().region(t, path, key, gdim, required, tag)


def _inside(r: Range) -> float:
    """A number inside ``r``."""
    if math.isinf(r.low) and math.isinf(r.high):
        return 0.0
    if math.isinf(r.high):
        return r.low + 1.0
    return r.high - 1.0 if math.isinf(r.low) else 0.5 * (r.low + r.high)


def _examples() -> list[dict]:
    """Scenarios that together take every branch of the validator.

    In 2D and in 3D: every material model (its required parameters inside their ranges), every
    wall type on a region and every slip or frictional wall as geometry, every region form (box,
    boxes, expression), sinks and events; and a mesh file with tags. They differ in their names
    and times, so that what depends on the scenario shows as such.
    """
    return [_example(2), _example(3), {
        "mesh": {"shape": "file", "file": "mesh.msh"},
        "materials": {"soil": _material("elastic")},
        "bodies": {"soil": {"material": "soil", "region": {"tag": 1}}},
        "walls": {"floor": {"type": "fixed", "region": {"tag": 2}}},
        "time": {"end": 1.0},
    }]  # fmt: skip


def _material(model: str) -> dict:
    """A material of ``model`` with its required parameters inside their ranges."""
    return {
        "model": model,
        **{k: _inside(p.range) for k, p in scenario.MODELS[model][1].items() if p.required},
    }


def _example(gdim: int) -> dict:
    """A scenario in ``gdim`` dimensions that takes every branch but the mesh file's."""
    zero, one = [0.0] * gdim, [1.0] * gdim
    box = {"min": zero, "max": [*one[:-1], 0.5]}
    regions = (box, [box, box], "y < 0.5")
    extra = {"slip": {"normal": one}, "frictional": {"normal": one, "friction_angle": 20.0},
             "velocity": {"velocity": zero}}  # fmt: skip
    walls = {kind: {"type": kind, "region": regions[k % 3], **extra.get(kind, {})}
             for k, kind in enumerate(scenario._WALLS)}  # fmt: skip
    for key, (dim, least, _) in scenario._GEOMETRY.items():
        if dim == gdim:  # points in a plane of the mesh, none three on a line
            points = [[math.cos(2.0 * k), math.sin(2.0 * k), 0.0][:gdim] for k in range(least)]
            walls[f"slip_{key}"] = {"type": "slip", key: points}
            walls[f"frictional_{key}"] = {"type": "frictional", key: points, "friction_angle": 20.0}
    models = list(scenario.MODELS)
    names = [f"{model}{gdim}" for model in models]
    return {
        "title": f"every branch in {gdim}D",
        "mesh": {
            "shape": "box" if gdim == 3 else "rectangle",
            "lower": zero,
            "upper": one,
            "cells": [1] * gdim,
        },
        "materials": {name: _material(model) for name, model in zip(names, models)},
        "nonlocal": {"radius": 0.1},
        "bodies": {
            f"body{k}": {"material": names[k % len(names)], "region": region, "velocity": ["x", *zero[1:]]}
            for k, region in enumerate(regions)
        }
        | {"settled": {"material": names[0], "stress": {"type": "geostatic", "surface": 1.0}}},
        "walls": walls,
        "sinks": {f"sink{k}_{gdim}d": {"region": region} for k, region in enumerate(regions)},
        "solver": {"gravity": [*zero[1:], -9.81], "on_exit": f"sink0_{gdim}d"},
        "time": {"start": -gdim, "end": gdim},
        "events": [{"time": 0.0, "remove_walls": ["fixed"]}],
        "output": {},
    }


def _normal(path: str, named) -> tuple[str, bool]:
    """``materials.sand.phi`` as ``materials.<name>.phi``, indexes dropped, and whether it had one."""
    parts = re.sub(r"\[\d+\]", "", path).split(".")
    if len(parts) > 1 and parts[0] in named:
        parts[1] = NAME
    return ".".join(parts), path.endswith("]")


def _join(path: str, key: str) -> str:
    return f"{path}.{key}" if path else key


def _merged(full: str, specs: list[dict]) -> Spec:
    """One :class:`Spec` of key ``full`` checked in several tables (a differing default or check varies)."""
    first = specs[0]
    if any(s[name] != first[name] for s in specs for name in ("kind", "required", "finite")):
        raise RuntimeError(f"{full}: checked as different kinds, or required in one table and not another")
    fields = {name: first[name] if all(s[name] == first[name] for s in specs) else VARIES
              for name in ("default", "check")}  # fmt: skip
    sizes = frozenset().union(*(s["sizes"] for s in specs))
    return Spec(first["kind"], first["required"], **fields, sizes=sizes, finite=first["finite"])


@functools.cache
def record() -> dict[str, list[Form]]:
    """The scenario format as the validator checks it: each table's forms, by normalised path.

    Raises:
        RuntimeError: an example the validator rejects, or a key it allows but checks nowhere.

    """
    raw: dict[str, dict[tuple, dict]] = {}  # table path -> allowed keys -> what the examples gave
    with tempfile.TemporaryDirectory() as folder:
        (Path(folder) / "mesh.msh").touch()
        for k, doc in enumerate(_examples()):
            c = _Recorder()
            scenario._scenario(c, doc, Path(folder))
            if c.errors:
                raise RuntimeError(f"example {k} fails validation: {'; '.join(c.errors)}")
            named = {key for (path, key), s in c.specs.items() if s["kind"] == "tables"}
            for path, allowed in c.tables.items():
                where, listed = _normal(path, named)
                form = raw.setdefault(where, {}).setdefault(allowed, {"specs": {}, "seen": {}})
                form["listed" if listed else "alone"] = True
                for key in allowed:
                    if (path, key) in c.specs:
                        form["specs"].setdefault(key, []).append(c.specs[path, key])
                    if (path, key) in c.seen:
                        form["seen"].setdefault(key, []).append(c.seen[path, key])
    out = {}
    for where, forms in raw.items():
        out[where] = []
        for allowed, f in forms.items():
            specs = {key: _merged(_join(where, key), s) for key, s in f["specs"].items()}
            for key in allowed:
                full = _join(where, key)
                if key in specs:
                    continue
                if full in raw:  # read by hand, each entry checked as a table: [[events]]
                    specs[key] = Spec("array")
                elif key in scenario._GEOMETRY:
                    specs[key] = Spec("geometry", True)
                else:
                    raise RuntimeError(f"{full}: allowed, but no check of it was recorded")
            seen = {key: list(dict.fromkeys(v)) for key, v in f["seen"].items()}
            out[where].append(Form(allowed, specs, seen, f.get("alone", False), f.get("listed", False)))
    return out


def discriminators(forms: list[Form]) -> list[str]:
    """The keys that tell a table's forms apart: a choice every form requires (``model``, ``type``)."""
    if len(forms) < 2:
        return []
    return [
        key
        for key in forms[0].keys
        if all(key in f.specs and f.specs[key].required and isinstance(f.specs[key].check, tuple)
               for f in forms)
    ]  # fmt: skip


# -- JSON Schema ---------------------------------------------------------------------------------
#: What the validator checks beyond the schema: across keys, and against the mesh.
_LIMITS = (
    "Left to `dolfin-mpm check`, which a schema cannot express: array lengths equal to the mesh's dimension "
    "(2 or 3), names that refer to other tables (bodies.*.material, solver.on_exit, "
    "events.remove_walls), output.figure_field's fields, bounds set by other keys (time.end >= "
    "time.start, events.time within the run, rho_c <= rho), finite numbers, whole cell counts, "
    "the particles per cell a cell takes, box corners min <= max, the syntax of expressions, "
    "mesh.partition's axes, tags only with a mesh file, the non-local law's weight and a plastic "
    "material for averaging, rigid walls that are flat, convex and not degenerate, sizes against "
    "the memory, and what only the mesh reveals (a wall that holds no node, a body with no "
    "particle)."
)


def _bounds(r: Range) -> dict:
    out = {}
    if math.isfinite(r.low):
        out["minimum" if r.closed[0] else "exclusiveMinimum"] = r.low
    if math.isfinite(r.high):
        out["maximum" if r.closed[1] else "exclusiveMaximum"] = r.high
    return out


def _number(kind: str, check) -> dict:
    out = {"type": "integer" if kind == "integer" else "number"}
    if isinstance(check, Range):
        out.update(_bounds(check))
    elif isinstance(check, tuple):
        out["enum"] = list(check)
    return out


def _items(s: dict, sizes: frozenset) -> dict:
    if sizes:
        s["minItems"], s["maxItems"] = min(sizes), max(sizes)
    return s


def _value(spec: Spec, fmt: dict, full: str) -> dict:
    """The schema of one key's value, without its description."""
    kind, check = spec.kind, spec.check
    if kind in ("number", "integer"):
        return _number(kind, check)
    if kind == "string":
        return {"type": "string", **({"enum": list(check)} if isinstance(check, tuple) else {})}
    if kind == "bool":
        return {"type": "boolean"}
    if kind == "numbers":
        return _items({"type": "array", "items": _number("number", check)}, spec.sizes)
    if kind == "strings":
        return {"type": "array", "items": {"type": "string"}}
    if kind == "vector":
        return _items({"type": "array", "items": {"type": ["number", "string"]}}, spec.sizes)
    if kind == "table":
        return _tables(full, [f for f in fmt[full] if f.alone], fmt)
    if kind == "tables":
        entry = _join(full, NAME)
        out = {"type": "object", "additionalProperties": _tables(entry, fmt[entry], fmt)}
        return {**out, "minProperties": 1} if spec.required else out
    if kind == "array":
        return {"type": "array", "items": _tables(full, fmt[full], fmt)}
    if kind == "region":
        alone, listed = ([f for f in fmt[full] if getattr(f, a)] for a in ("alone", "listed"))
        expression = {"type": "string", "description": "a condition of x, y, z, e.g. (y < 0.2) & (x > 0.1)"}
        boxes = {"type": "array", "minItems": 1, "items": _tables(full, listed, fmt)}
        return {"anyOf": [_tables(full, alone, fmt), boxes, expression]}
    dim, least, most = scenario._GEOMETRY[full.rsplit(".", 1)[1]]  # geometry
    point = {"type": "array", "items": {"type": "number"}, "minItems": dim, "maxItems": dim}
    return {"type": "array", "items": point, "minItems": least, **({"maxItems": most} if most else {})}


def _key(spec: Spec, fmt: dict, full: str) -> dict:
    out = _value(spec, fmt, full)
    if full in DESCRIPTIONS:
        out["description"] = DESCRIPTIONS[full]
    default = spec.default
    finite = not isinstance(default, float) or math.isfinite(default)
    if default is not None and default is not VARIES and finite and spec.kind != "table":
        out["default"] = default
    return out


def _tables(path: str, forms: list[Form], fmt: dict) -> dict:
    """The schema of a table at ``path`` that takes one of ``forms``."""
    tell = discriminators(fmt[path])
    out = []
    for f in forms:
        properties = {key: _key(f.specs[key], fmt, _join(path, key)) for key in f.keys}
        for key in tell:  # each form takes the choices its examples gave
            properties[key]["enum"] = [v for v in f.specs[key].check if v in f.seen[key]]
        required = [key for key in f.keys if f.specs[key].required]
        out.append({"type": "object", "properties": properties, "additionalProperties": False,
                    **({"required": required} if required else {})})  # fmt: skip
    return out[0] if len(out) == 1 else {"oneOf": out}


def schema() -> dict:
    """The JSON Schema (draft 2020-12) of scenario files, from the validator."""
    fmt = record()
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "dolfin-mpm scenario",
        **_tables("", fmt[""], fmt),
        "description": f"Generated from the validator (dolfin-mpm schema). {_LIMITS}",
    }


# -- explanations --------------------------------------------------------------------------------
class UnknownKey(KeyError):
    """A key the scenario format lacks; the message names the closest ones."""

    def __str__(self):
        return self.args[0]


def _kind(spec: Spec, path: str, fmt: dict) -> str:
    """The kind in words: ``array of 2 or 3 numbers``."""
    n = " or ".join(map(str, sorted(spec.sizes)))
    if spec.kind == "region":
        alone, listed = (
            [f"{{{', '.join(f.keys)}}}" for f in fmt[path] if getattr(f, a)] for a in ("alone", "listed")
        )
        return f"region: an expression, a table {' or '.join(alone)}, or an array of {' or '.join(listed)}"
    if spec.kind == "geometry":
        dim = scenario._GEOMETRY[path.rsplit(".", 1)[1]][0]
        return f"array of points [{', '.join('xyz'[:dim])}]"
    return {
        "number": "number", "integer": "integer", "string": "string", "bool": "true or false",
        "numbers": f"array of {n or 'any number of'} numbers", "strings": "array of strings",
        "vector": f"array of {n} numbers or expressions of x, y, z", "table": "table",
        "tables": f"tables [{path}.<name>]", "array": f"array of tables [[{path}]]",
    }[spec.kind]  # fmt: skip


def _allowed(spec: Spec, path: str) -> str:
    check = spec.check
    if check is VARIES:
        return VARIES
    if isinstance(check, Range):
        text = check.describe().removeprefix("must be ")
        return f"each {text}" if spec.kind == "numbers" else text
    if isinstance(check, tuple):
        return "one of " + ", ".join(map(scenario._show, check))
    if spec.kind == "geometry":
        _, least, most = scenario._GEOMETRY[path.rsplit(".", 1)[1]]
        return f"{least}{'' if most else ' or more'} points"
    if spec.kind in ("number", "numbers", "vector"):
        return "finite" if spec.finite else "numbers, inf allowed"
    return ""


def _default(spec: Spec) -> str:
    """The default in TOML, ``required``, or ``""`` for none."""
    if spec.required:
        return "required"
    if spec.default is None or spec.kind == "table":
        return ""
    return VARIES if spec.default is VARIES else scenario._show(spec.default)


def _where(forms: list[Form], having: list[Form]) -> str:
    """Which of a table's ``forms`` are ``having``: ``with type = "slip", not with segment`` (``""``: all)."""
    if len(having) == len(forms):
        return ""
    tell = discriminators(forms)
    values = {d: [v for v in forms[0].specs[d].check if any(v in f.seen[d] for f in having)] for d in tell}
    parts = [
        f"with {d} = {' or '.join(map(scenario._show, values[d]))}"
        for d in tell
        if len(values[d]) < len({v for f in forms for v in f.seen[d]})
    ]
    used = {k for f in having for k in f.keys}
    others = [f for f in forms if f not in having and all(set(f.seen[d]) & set(values[d]) for d in tell)]
    without = dict.fromkeys(k for f in others for k in f.keys if f.specs[k].required and k not in used)
    return ", ".join(parts + (["not with " + ", ".join(without)] if without else []))


def _groups(forms: list[Form], name: str) -> list[tuple[Spec, list[Form]]]:
    """The specs of key ``name`` over a table's forms, those alike but for array sizes merged."""
    out = []
    for f in forms:
        if name not in f.keys:
            continue
        spec = f.specs[name]
        for k, (s, having) in enumerate(out):
            if dataclasses.replace(s, sizes=spec.sizes) == spec:
                out[k] = (dataclasses.replace(s, sizes=s.sizes | spec.sizes), [*having, f])
                break
        else:
            out.append((spec, [f]))
    return out


def _paths(fmt: dict, path: str = "") -> list[str]:
    """The tables' paths, each after the table that holds it, in the validator's order of keys."""
    out = [path]
    for name in dict.fromkeys(k for f in fmt[path] for k in f.keys):
        full = _join(path, name)
        for p in (full, _join(full, NAME)):
            if p in fmt and p not in out:
                out += _paths(fmt, p)
    return out


def _lookup(key: str) -> str:
    """``key`` normalised (``materials.sand.phi`` -> ``materials.<name>.phi``); :class:`UnknownKey`."""
    fmt = record()
    named = {k for f in fmt[""] for k, s in f.specs.items() if s.kind == "tables"}
    path, _ = _normal(key.strip(), named)
    known = {_join(where, k) for where, forms in fmt.items() for f in forms for k in f.keys} | set(fmt)
    if path in known - {""}:
        return path
    close = difflib.get_close_matches(path, sorted(known - {""}), n=3, cutoff=0.6)
    hint = (
        f"did you mean {', '.join(close)}?"
        if close
        else f"the top-level keys are {', '.join(fmt[''][0].keys)}"
    )
    raise UnknownKey(f"{key}: no such key in a scenario; {hint}")


def explain(key: str) -> str:
    """What ``key`` of a scenario is: meaning, kind, allowed values with unit, default, where.

    ``key`` may be concrete (``materials.sand.phi``, ``solver.flip``, ``events[0].time``) or a
    table (``walls``, ``walls.floor``: its keys are listed).

    Raises:
        UnknownKey: no such key, with the closest ones in the message.

    """
    fmt = record()
    path = _lookup(key)
    where, name = path.rsplit(".", 1) if "." in path else ("", path)
    if where not in fmt:  # an entry of named tables: walls.<name>
        lines = [f"{path}: one of the {where} ({DESCRIPTIONS[where]})"]
    else:
        lines = [f"{path}: {DESCRIPTIONS.get(path, '')}"]
        for spec, having in _groups(fmt[where], name):
            allowed, default, only = _allowed(spec, path), _default(spec), _where(fmt[where], having)
            lines.append(f"  kind: {_kind(spec, path, fmt)}")
            lines += [f"  allowed: {allowed}"] if allowed else []
            lines.append(f"  required: {'yes' if spec.required else 'no'}")
            lines += [f"  default: {default}"] if default and not spec.required else []
            lines += [f"  only: {only}"] if only else []
    table = next((p for p in (path, _join(path, NAME)) if p in fmt), None)
    if table is not None:
        lines.append(f"  keys of {table}:")
        for k in dict.fromkeys(k for f in fmt[table] for k in f.keys):
            for spec, having in _groups(fmt[table], k):
                only = _where(fmt[table], having)
                kind = _kind(spec, _join(table, k), fmt) + (f"; {only}" if only else "")
                lines.append(f"    {k} ({kind}): {DESCRIPTIONS.get(_join(table, k), '')}")
    return "\n".join(lines)


def _cell(text: str) -> str:
    """``text`` in a Markdown table's cell."""
    return text.replace("|", "\\|").replace("<", "&lt;")


def reference() -> str:
    """The reference page of the scenario format (``docs/scenario.md``), in Markdown."""
    fmt = record()
    out = [
        "# Scenario file reference",
        "",
        "Generated from the validator (`dolfin_mpm.app.scenario`) by "
        "`dolfin-mpm schema --reference -o docs/scenario.md`: do not edit by hand. The README's "
        '"Running scenario files" describes how a scenario runs; `dolfin-mpm check --explain KEY` '
        "explains one key, and `dolfin-mpm schema -o scenario.schema.json` writes the JSON Schema "
        "(editors take it from a first line `#:schema ./scenario.schema.json`).",
        "",
        "Kinds are TOML's; *required* keys have no default; what *depends on the scenario* is set by "
        "other keys (the names of materials, walls and sinks, the mesh's dimension, the run's times). "
        "Arrays of 2 or 3 numbers have one per axis of the mesh.",
    ]
    for path in _paths(fmt):
        forms = fmt[path]
        listed = all(f.listed and not f.alone for f in forms)
        out += ["", f"## {'Top level' if not path else f'`[[{path}]]`' if listed else f'`[{path}]`'}", ""]
        if path:
            where, name = path.rsplit(".", 1) if "." in path else ("", path)
            out += [DESCRIPTIONS.get(path if name != NAME else where, "").capitalize() + ".", ""]
        tell = discriminators(forms)
        if tell or len(forms) > 1:
            out += ["One of these forms:", ""]
            for f in forms:
                label = ", ".join(f"{d} = {' or '.join(map(scenario._show, f.seen[d]))}" for d in tell)
                keys = ", ".join(f"`{k}`" for k in f.keys)
                out.append(f"- {_cell(label)}: {keys}" if label else f"- {keys}")
            out.append("")
        out += ["| key | kind | allowed | default | meaning |", "| --- | --- | --- | --- | --- |"]
        for name in dict.fromkeys(k for f in forms for k in f.keys):
            full = _join(path, name)
            for spec, having in _groups(forms, name):
                only = _where(forms, having)
                meaning = DESCRIPTIONS.get(full, "") + (f" ({only})" if only else "")
                cells = (f"`{name}`", _kind(spec, full, fmt), _allowed(spec, full), _default(spec), meaning)
                out.append("| " + " | ".join(map(_cell, cells)) + " |")
    out += ["", "## Left to the validator", "", _LIMITS, ""]
    return "\n".join(out)
