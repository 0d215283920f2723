"""The scenario format from its validator: JSON Schema, reference page, ``check --explain``."""

import json
import math
from pathlib import Path

import dolfin_mpm  # noqa: F401  (first: loads DOLFINx's libraries)

# isort: split
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from test_scenario import BAD, TAGGED

from dolfin_mpm.app import scenario, schema
from dolfin_mpm.app.cli import main
from dolfin_mpm.params import Range

ROOT = Path(__file__).parents[1]
DEMOS = ROOT / "demos"

#: The JSON Schema keywords :func:`errors` checks; the schema may use no other.
KEYWORDS = {
    "$schema", "title", "description", "default", "type", "enum", "properties", "required",
    "additionalProperties", "minProperties", "items", "minItems", "maxItems", "oneOf", "anyOf",
    "minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum",
}  # fmt: skip
TYPES = {
    "object": lambda v: isinstance(v, dict),
    "array": lambda v: isinstance(v, list),
    "string": lambda v: isinstance(v, str),
    "boolean": lambda v: isinstance(v, bool),
    "integer": lambda v: isinstance(v, int) and not isinstance(v, bool),
    "number": lambda v: isinstance(v, (int, float)) and not isinstance(v, bool),
}


def errors(s: dict, v, path: str = "") -> list[str]:
    """What ``v`` breaks of the JSON Schema ``s`` (the subset of :data:`KEYWORDS`)."""
    if "oneOf" in s and sum(not errors(b, v, path) for b in s["oneOf"]) != 1:
        return [f"{path}: not exactly one of oneOf"]
    if "anyOf" in s and all(errors(b, v, path) for b in s["anyOf"]):
        return [f"{path}: none of anyOf"]
    types = s.get("type", [])
    if types and not any(TYPES[t](v) for t in ([types] if isinstance(types, str) else types)):
        return [f"{path}: not {types}"]
    if "enum" in s and not any(v == e and TYPES["boolean"](v) == TYPES["boolean"](e) for e in s["enum"]):
        return [f"{path}: not in {s['enum']}"]
    out = []
    bounds = {"minimum": float.__ge__, "maximum": float.__le__, "exclusiveMinimum": float.__gt__,
              "exclusiveMaximum": float.__lt__}  # fmt: skip
    if TYPES["number"](v):
        out += [f"{path}: {k} {s[k]}" for k, ok in bounds.items() if k in s and not ok(float(v), float(s[k]))]
    if isinstance(v, dict):
        out += [f"{path}.{k}: missing" for k in s.get("required", []) if k not in v]
        if len(v) < s.get("minProperties", 0):
            out.append(f"{path}: empty")
        for k, x in v.items():
            extra = s.get("additionalProperties", True)
            if k in s.get("properties", {}):
                out += errors(s["properties"][k], x, f"{path}.{k}")
            elif extra is False:
                out.append(f"{path}.{k}: unknown")
            elif isinstance(extra, dict):
                out += errors(extra, x, f"{path}.{k}")
    if isinstance(v, list):
        if not s.get("minItems", 0) <= len(v) <= s.get("maxItems", math.inf):
            out.append(f"{path}: {len(v)} items")
        for k, x in enumerate(v):
            out += errors(s["items"], x, f"{path}[{k}]") if "items" in s else []
    return out


def _keywords(s) -> set:
    if isinstance(s, list):
        return set().union(*map(_keywords, s))
    if not isinstance(s, dict):
        return set()
    inner = [v for k, v in s.items() if k not in ("properties", "enum", "default")]
    inner += list(s.get("properties", {}).values())
    return set(s) | set().union(*map(_keywords, inner))


def _recorded() -> set:
    return {
        f"{path}.{key}" if path else key
        for path, forms in schema.record().items()
        for f in forms
        for key in f.keys
    }


def test_every_recorded_key_has_a_description_and_every_description_a_key():
    recorded = _recorded()
    missing, stale = sorted(recorded - set(schema.DESCRIPTIONS)), sorted(set(schema.DESCRIPTIONS) - recorded)
    assert not missing, f"keys the validator checks without a line in schema.DESCRIPTIONS: {missing}"
    assert not stale, f"schema.DESCRIPTIONS names keys the validator does not check: {stale}"


def test_the_examples_take_every_choice_that_tells_forms_apart():
    """Every material model, wall type and mesh shape has its forms recorded."""
    told = 0
    for path, forms in schema.record().items():
        for key in schema.discriminators(forms):
            seen = {v for f in forms for v in f.seen[key]}
            assert seen == set(forms[0].specs[key].check), (path, key)
            told += 1
    assert told == 3  # mesh.shape, materials.<name>.model, walls.<name>.type


def test_a_new_key_of_the_validator_is_recorded(monkeypatch):
    monkeypatch.setitem(scenario._SOLVER, "stiffness", ("number", 1.0, Range(0.0, 2.0, "Pa")))
    schema.record.cache_clear()
    try:
        assert "solver.stiffness" in _recorded()
        assert schema.schema()["properties"]["solver"]["properties"]["stiffness"]["exclusiveMaximum"] == 2.0
    finally:
        schema.record.cache_clear()


def test_the_schema_uses_only_the_keywords_checked_here():
    s = schema.schema()
    assert s["$schema"] == "https://json-schema.org/draft/2020-12/schema"
    assert _keywords(s) <= KEYWORDS, _keywords(s) - KEYWORDS
    phi = s["properties"]["materials"]["additionalProperties"]["oneOf"][1]["properties"]["phi"]
    assert phi == {"type": "number", "exclusiveMinimum": 0.0, "exclusiveMaximum": 90.0,
                   "description": "angle of internal friction [degrees]"}  # fmt: skip
    assert s["properties"]["materials"]["minProperties"] == 1
    assert "enum" not in s["properties"]["solver"]["properties"]["on_exit"]  # the sinks' names


def _documents():
    tagged = scenario.parse(TAGGED)
    yield from ((p.name, scenario.parse(p.read_text())) for p in sorted(DEMOS.glob("*.toml")))
    yield "tagged", tagged
    yield "branches", schema._examples()[0]
    yield "branches 3D", schema._examples()[1]


@pytest.mark.parametrize("name, doc", list(_documents()), ids=lambda a: a if isinstance(a, str) else "")
def test_shipped_and_test_scenarios_match_the_schema(name, doc):
    assert errors(schema.schema(), doc) == []


@pytest.mark.parametrize(
    "overrides",
    [
        ["materials.sand.phi=120"],  # out of range
        ["materials.sand.model=elastic"],  # phi and the rest are not the elastic model's
        ["mesh.colour=red"],  # unknown key
        ["solver.flip=high"],  # wrong type
        ["output.xdmf=1"],
        ["bodies.fill.ppc=2.0"],  # an integer
        ["solver.scheme=FLIP"],  # bad choice
        ["nonlocal.weight=square"],
        ["walls.left.type=fixed"],  # a wall as geometry is slip or frictional
        ["walls.left.segment=[[0.0, 0.0]]"],  # one point
        ["sinks.discharged.region={tag=1}"],  # a sink takes no tag
        ["mesh.cells=[20, 0]"],
        ["time.end=end"],
    ],
)
def test_what_the_validator_rejects_for_a_key_the_schema_rejects(overrides):
    data = scenario.parse((DEMOS / "silo.toml").read_text())
    scenario.apply_overrides(data, overrides)
    with pytest.raises(scenario.ScenarioError):
        scenario.validate(data, DEMOS)
    assert errors(schema.schema(), data)


def test_the_test_suites_bad_scenario_fails_the_schema():
    assert errors(schema.schema(), scenario.parse(BAD))


OTHERS = [0, 0.5, -1.0, math.inf, True, "x", "y < 0.1", [0.0, 1.0], [1.0, 2.0, 3.0], {"min": [0.0, 0.0]}]


def _candidates(spec: schema.Spec) -> list:
    """Values at and about the edges of what ``spec`` allows, its choices and its default."""
    out = [] if spec.default in (None, schema.VARIES) else [spec.default]
    if isinstance(spec.check, tuple):
        out += list(spec.check)
    numbers = [0.0, 1.0, 0.25]
    if isinstance(spec.check, Range):
        r = spec.check
        numbers += [x for x in (r.low, r.high, r.low + 1e-9, r.high - 1e-9, r.low - 1.0, r.high + 1.0)
                    if math.isfinite(x)]  # fmt: skip
        numbers += [schema._inside(r)]
    out += [int(x) if spec.kind == "integer" and float(x).is_integer() else x for x in numbers]
    out += [[x] * n for x in numbers for n in spec.sizes]
    return out


SPECS = {
    f"{path}.{key}" if path else key: [f.specs[key] for f in forms if key in f.keys]
    for path, forms in schema.record().items()
    for key in dict.fromkeys(k for f in forms for k in f.keys)
}


def _toml(value) -> str:
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k} = {_toml(v)}" for k, v in value.items()) + "}"
    return json.dumps(value).replace("Infinity", "inf")


@settings(max_examples=400, derandomize=True, deadline=None)
@given(st.sampled_from(sorted(DEMOS.glob("*.toml"))), st.data())
def test_what_the_validator_accepts_the_schema_accepts(path, draw):
    """Demos with a key or two set to values about the edges of their ranges: never rejected by the
    schema alone."""
    data = scenario.parse(path.read_text())
    overrides = []
    for _ in range(draw.draw(st.sampled_from([1, 1, 2]))):
        key = draw.draw(st.sampled_from(sorted(k for k in SPECS if not k.startswith("events"))))
        value = draw.draw(
            st.sampled_from([v for s in SPECS[key] for v in _candidates(s)]) | st.sampled_from(OTHERS)
        )
        names = list(data.get(key.split(".")[0], {})) if schema.NAME in key else [""]
        assume(names)
        overrides.append(f"{key.replace(schema.NAME, names[0])}={_toml(value)}")
    try:
        scenario.apply_overrides(data, overrides)
        scenario.validate(data, DEMOS)
    except scenario.ScenarioError:
        return
    assert errors(schema.schema(), data) == [], overrides


def test_the_reference_page_is_generated():
    page = (ROOT / "docs" / "scenario.md").read_text()
    assert page == schema.reference(), (
        "docs/scenario.md differs from the validator's format: regenerate it with "
        "`dolfin-mpm schema --reference -o docs/scenario.md`"
    )


@pytest.mark.parametrize(
    "key, expected",
    [
        ("materials.sand.phi", ["friction [degrees]", "in (0, 90) degrees", 'model = "drucker_prager"']),
        ("solver.dt", ["time step [s]", "> 0 s", "required: no"]),
        ("walls.floor.friction_angle", ["[0, 90) degrees", "default: 0.0"]),
        ("events[0].damping", ["in [0, 1)"]),
        ("walls", ["keys of walls.<name>:", "segment (array of points [x, y]", "friction_angle (number"]),
    ],
)  # fmt: skip
def test_explain_names_range_unit_and_default(capsys, key, expected):
    assert main(["check", "--explain", key]) == 0
    out = capsys.readouterr().out
    for text in expected:
        assert text in out, out


def test_explain_an_unknown_key_suggests_close_ones(capsys):
    assert main(["check", "--explain", "materials.sand.phy"]) == 2
    err = capsys.readouterr().err
    assert "materials.sand.phy: no such key" in err and "materials.<name>.phi" in err
    assert "Traceback" not in err


def test_check_takes_a_scenario_or_explain(capsys):
    for argv in (["check"], ["check", str(DEMOS / "silo.toml"), "--explain", "solver.flip"]):
        with pytest.raises(SystemExit) as info:
            main(argv)
        assert info.value.code == 2
    assert "--explain KEY alone" in capsys.readouterr().err


def test_schema_writes_json(tmp_path):
    assert main(["schema", "-o", str(tmp_path / "scenario.schema.json")]) == 0
    assert json.loads((tmp_path / "scenario.schema.json").read_text()) == schema.schema()
    assert main(["schema", "-o", str(tmp_path / "missing" / "s.json")]) == 2
