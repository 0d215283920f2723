"""A fuzz campaign on the CLI: mutated copies of the shipped scenario files, checked and run.

Each case takes one of ``demos/*.toml``, changes one to three things in its document (a value
anywhere replaced by an extreme number, another type, an odd string or an array of another
length; a key deleted; an unknown key added; a table renamed; an array's items dropped or
doubled), writes it back as TOML and runs ``dolfin-mpm check`` on it in this process. A case
that passes the check is also run for 2 ms of simulated time (its events after that dropped),
unless those take more than ``MAX_STEPS`` steps: then it is counted as long.
What the campaign counts: exit codes, exceptions that escape the CLI (a traceback a user would
see), cases over the time limit (a hang), and the peak memory of the process. Different from
the suite's fuzz (``tests/test_hardening.py``), which sets values of one scenario with
``--set``.

    python scripts/fuzz_campaign.py [--cases 1000] [--seed 1] [--timeout 60] [--accepted]

``--accepted`` lists the changes of every case the check accepted, with its run's exit code:
whether an accepted input runs with the physics it says is for a reader to judge.
"""

import argparse
import contextlib
import copy
import io
import math
import re
import resource
import shutil
import signal
import sys
import tempfile
import time
import traceback
from collections import Counter
from pathlib import Path

import tomllib

import dolfin_mpm  # noqa: F401  (first: loads DOLFINx's libraries)

# isort: split
import numpy as np

from dolfin_mpm.app.cli import main

DEMOS = sorted((Path(__file__).resolve().parents[1] / "demos").glob("*.toml"))

NUMBERS = [math.nan, math.inf, -math.inf, 1e308, -1e308, 0.0, -0.0, -1.0, 1e-320, 5e-324, 0.5, 3.0,
           2**63, -(2**63), 2**31, 7, 0, -3]  # fmt: skip
STRINGS = ["", " ", "x", "x < 0.1", "sin(x) > 2", "1/0 > 0", "y < 0.2 and x > 0.1", "__import__('os')",
           "é∂ƒ©", "\u0000", "a" * 5000, "rectangle", "box", "drucker_prager", "cubic", "frictional",
           "geostatic", "vx", "nan", "(x > 0.1) | (y < 0.2)", "x" * 3 + "**" + "9" * 4]  # fmt: skip


#: Steps of its 2 ms beyond which an accepted case is counted as long and not run (the check
#: announces its step count; e.g. E = 1e19 Pa takes 2e8 steps of 1e-11 s).
MAX_STEPS = 100_000


class Timeout(Exception):
    """A command ran over the time limit."""


def leaves(doc, path=()):
    """Every (path, value) of the document's scalars, arrays and tables."""
    yield path, doc
    if isinstance(doc, dict):
        for k, v in doc.items():
            yield from leaves(v, (*path, k))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            yield from leaves(v, (*path, i))


def container(doc, path):
    """The table or array holding ``path``'s last key."""
    for key in path[:-1]:
        doc = doc[key]
    return doc


def random_value(rng, like):
    """A value of any kind, an array near the length of ``like`` when that is one."""
    r = rng.random()
    if r < 0.4:
        return NUMBERS[rng.integers(len(NUMBERS))]
    if r < 0.6:
        return STRINGS[rng.integers(len(STRINGS))]
    if r < 0.7:
        return bool(rng.integers(2))
    if r < 0.85:
        n = (
            int(rng.integers(0, 5))
            if not isinstance(like, list)
            else max(0, len(like) + int(rng.integers(-2, 3)))
        )
        return [NUMBERS[rng.integers(len(NUMBERS))] for _ in range(n)]
    if r < 0.95:
        return {"min": [0.0, 0.0], "max": [NUMBERS[rng.integers(len(NUMBERS))], 0.1]}
    return [[0.0, 0.0], [NUMBERS[rng.integers(len(NUMBERS))], 0.0]]


def mutate(rng, doc) -> str:
    """One change to ``doc`` in place; returns what it was."""
    places = [p for p, _ in leaves(doc) if p]
    path = places[rng.integers(len(places))]
    parent, key = container(doc, path), path[-1]
    r = rng.random()
    if r < 0.55:
        parent[key] = random_value(rng, parent[key])
        return f"{'.'.join(map(str, path))} = {parent[key]!r:.60}"
    if r < 0.7:
        del parent[key]
        return f"deleted {'.'.join(map(str, path))}"
    if r < 0.8 and isinstance(parent, dict):
        parent[f"unknown_{rng.integers(100)}"] = random_value(rng, None)
        return f"unknown key in {'.'.join(map(str, path[:-1]))}"
    if r < 0.9 and isinstance(parent, dict):
        parent[f"{key}_renamed"] = parent.pop(key)
        return f"renamed {'.'.join(map(str, path))}"
    if isinstance(parent[key], list) and parent[key]:
        items = parent[key]
        parent[key] = items[: rng.integers(len(items))] if rng.random() < 0.5 else items + items
        return f"resized {'.'.join(map(str, path))}"
    parent[key] = random_value(rng, parent[key])
    return f"{'.'.join(map(str, path))} = {parent[key]!r:.60}"


def toml_value(v) -> str:
    """``v`` as a TOML value (tables inline)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return "nan" if math.isnan(v) else ("inf" if v == math.inf else "-inf" if v == -math.inf else repr(v))
    if isinstance(v, int):
        return str(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"').replace("\u0000", "\\u0000") + '"'
    if isinstance(v, list):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f'"{k}" = {toml_value(x)}' for k, x in v.items()) + "}"
    raise TypeError(type(v))


def to_toml(doc, prefix="") -> str:
    """``doc`` as TOML: scalars and arrays first, then tables, then arrays of tables."""
    scalars = {k: v for k, v in doc.items() if not isinstance(v, dict) and not _tables(v)}
    lines = [f'"{k}" = {toml_value(v)}' for k, v in scalars.items()]
    for k, v in doc.items():
        name = f'{prefix}"{k}"'
        if isinstance(v, dict):
            lines += [f"[{name}]", to_toml(v, name + ".")]
        elif _tables(v):
            for item in v:
                lines += [f"[[{name}]]", to_toml(item, name + ".")]
    return "\n".join(lines)


def _tables(v) -> bool:
    return isinstance(v, list) and len(v) > 0 and all(isinstance(x, dict) for x in v)


def call(argv, timeout: float) -> tuple[int | str, str]:
    """``main(argv)``: its exit code (or 'traceback' / 'timeout') and what it printed."""
    out = io.StringIO()

    def alarm(*_):
        raise Timeout

    signal.signal(signal.SIGALRM, alarm)
    signal.alarm(int(timeout))
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
            code = main(argv)
    except Timeout:
        code = "timeout"
    except SystemExit as e:  # argparse
        code = e.code
    except BaseException:  # what the campaign is for: a traceback a user would see
        code = "traceback"
        out.write(traceback.format_exc())
    finally:
        signal.alarm(0)
    return code, out.getvalue()


def main_campaign() -> int:
    """Run the campaign and print its counts last; 1 when a case gave a traceback, a hang or another code."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=1000)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--timeout", type=float, default=60.0, help="seconds per command")
    parser.add_argument("--accepted", action="store_true", help="list the accepted cases' changes")
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    checks, runs, bad, accepted = Counter(), Counter(), [], []
    work = Path(tempfile.mkdtemp(prefix="fuzz-"))
    start = time.perf_counter()
    try:
        for case in range(args.cases):
            source = DEMOS[rng.integers(len(DEMOS))]
            doc = tomllib.loads(source.read_text())
            changes = [mutate(rng, doc) for _ in range(rng.integers(1, 4))]
            path = work / f"case{case}.toml"
            path.write_text(to_toml(doc))
            code, text = call(["check", str(path)], args.timeout)
            checks[code] += 1
            if code not in (0, 2) or "Traceback" in text:
                bad.append((case, source.name, changes, "check", code, text[-2000:]))
            if code != 0:
                continue
            short = copy.deepcopy(doc)  # 2 ms of it, without the events after that
            t0 = short["time"].get("start", 0.0)
            short["time"]["end"] = float(t0) + 0.002
            dt = re.search(r"dt = ([0-9.e+-]+) s", text)  # the check's summary
            if dt and 0.002 / float(dt.group(1)) > MAX_STEPS:  # a long run, announced: not run
                runs["long"] += 1
                accepted.append(
                    f"case {case} ({source.name}: {'; '.join(changes)}): long, dt = {dt.group(1)} s"
                )
                continue
            short["events"] = [
                e for e in short.get("events", []) if e.get("time", 0.0) <= short["time"]["end"]
            ]
            if not short["events"]:
                del short["events"]
            path.write_text(to_toml(short))
            folder = work / f"run{case}"
            code, text = call(["run", str(path), "--output", str(folder), "--quiet"], args.timeout)
            runs[code] += 1
            accepted.append(f"case {case} ({source.name}: {'; '.join(changes)}): run gave {code}")
            if code not in (0, 1, 2) or "Traceback" in text:
                bad.append((case, source.name, changes, "run", code, text[-2000:]))
            shutil.rmtree(folder, ignore_errors=True)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    if args.accepted:
        print("\n".join(accepted))
    for case, name, changes, what, code, text in bad:
        print(f"case {case} ({name}: {'; '.join(changes)}): {what} gave {code}\n{text}\n", file=sys.stderr)
    print(
        f"{args.cases} cases (seed {args.seed}) in {time.perf_counter() - start:.0f} s: check exit codes "
        f"{dict(checks)}, runs of the accepted ones {dict(runs)}; {len(bad)} with a traceback, a hang "
        f"or another exit code; peak memory {peak:.0f} MB"
    )
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main_campaign())
