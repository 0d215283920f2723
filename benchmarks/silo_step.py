"""Milliseconds per step of the flowing non-local silo, per stage, against the core's bandwidth.

The paper's silo (``demos/demo_silo.py``: r = 5 mm, cubic weight, the ``max`` law, wall
friction 20°) on meshes of h: settled, opened and discharged until ``--t-from`` [s], when the
bands have formed; then ``--runs`` windows of ``--steps`` steps each are timed, one after the
other, and their medians reported. Per window: ms per step in all and per stage (the stages do
not overlap and add up to the step), fixed-point iterations and pair-list rebuilds per step.

It sets the times against what the core can move, measured in the same run with STREAM's copy
and triad (``bandwidth.c``) on arrays far larger than the caches (``--stream-mb``) and on
arrays the size of the particles' stress: a particle-iteration (a step's time over particles x
iterations) is printed as the bytes the copy would move in that time. Memory: the bytes per particle that the
particles and the non-local pair lists hold, and the peak of what one step allocates on top
(``tracemalloc``; numpy's buffers are traced). Writes everything to JSON.

    python benchmarks/silo_step.py [--h 0.005 0.0025] [--t-from 0.05] [--runs 3] [--steps 100]
"""

import argparse
import ctypes
import json
import math
import platform
import sys
import time
import tracemalloc
from pathlib import Path

import dolfin_mpm as dm  # first: loads DOLFINx's libraries

# isort: split
import numpy as np
from mpi4py import MPI

from dolfin_mpm import native
from dolfin_mpm.explicit.step import STAGES

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "demos"))
import demo_silo

_REAL = native.array(np.float64)
_stream = native.kernels(
    Path(__file__).with_name("bandwidth.c"),
    {
        "stream_copy": (ctypes.c_int64, _REAL, _REAL),
        "stream_triad": (ctypes.c_int64, _REAL, _REAL, ctypes.c_double, _REAL),
    },
)


def bandwidth(n: int, repeats: int = 10) -> dict:
    """STREAM copy and triad [GB/s] on arrays of ``n`` doubles, best of ``repeats``."""
    a, b, c = np.full(n, 1.0), np.full(n, 2.0), np.full(n, 3.0)
    best = {"copy": math.inf, "triad": math.inf}
    for _ in range(repeats):
        t0 = time.perf_counter()
        _stream().stream_copy(n, a, b)
        t1 = time.perf_counter()
        _stream().stream_triad(n, b, c, 3.0, a)
        t2 = time.perf_counter()
        best = {"copy": min(best["copy"], t1 - t0), "triad": min(best["triad"], t2 - t1)}
    return {"copy": 16 * n / best["copy"] / 1e9, "triad": 24 * n / best["triad"] / 1e9}


def held_bytes(obj, seen=None) -> int:
    """Bytes of the numpy buffers that ``obj`` holds, through the project's objects, lists and dicts."""
    seen = set() if seen is None else seen
    if id(obj) in seen:
        return 0
    seen.add(id(obj))
    if isinstance(obj, np.ndarray):
        owner = obj
        while isinstance(owner.base, np.ndarray):
            owner = owner.base
        if id(owner) in seen and owner is not obj:
            return 0
        seen.add(id(owner))
        return owner.nbytes
    if isinstance(obj, dict):
        return sum(held_bytes(v, seen) for v in obj.values())
    if isinstance(obj, (list, tuple)):
        return sum(held_bytes(v, seen) for v in obj)
    if type(obj).__module__.startswith("dolfin_mpm") and hasattr(obj, "__dict__"):
        return sum(held_bytes(v, seen) for v in vars(obj).values())
    return 0


def flowing_silo(h: float, t_from: float):
    """The silo of ``demo_silo.run`` on a mesh of ``h`` [m], discharged until ``t_from`` [s]."""
    solver, gate = demo_silo.build(h)
    demo_silo.settle_and_open(solver, gate, 0.02, progress=False)  # demo_silo.run's settling
    solver.run(t_from, progress=False)
    return solver


def window(solver, steps: int) -> dict:
    """Time ``steps`` steps of ``solver``: ms per step in all and per stage, and the loop's counts."""
    solver.timings.clear()
    fp, rebuilds = dict(solver.fixed_point), solver.averaging.rebuilds
    n0 = solver.num_particles()
    t0 = time.perf_counter()
    for _ in range(steps):
        solver.step()
    seconds = time.perf_counter() - t0
    return {
        "particles": 0.5 * (n0 + solver.num_particles()),
        "ms_per_step": 1e3 * seconds / steps,
        "stages": {s: 1e3 * solver.timings[s] / steps for s in STAGES if s in solver.timings},
        "iterations": (solver.fixed_point["iterations"] - fp["iterations"]) / steps,
        "rebuilds": (solver.averaging.rebuilds - rebuilds) / steps,
    }


def measure(h: float, t_from: float, runs: int, steps: int, stream_mb: float = 256.0) -> dict:
    solver = flowing_silo(h, t_from)
    windows = [window(solver, steps) for _ in range(runs)]
    med = lambda f: float(np.median([f(w) for w in windows]))  # noqa: E731
    n, iterations = med(lambda w: w["particles"]), med(lambda w: w["iterations"])
    ms = med(lambda w: w["ms_per_step"])
    average = solver.averaging
    pairs, within = len(average._pairs.j), int(average._within.begin[average._runs_within])
    P = solver.particles
    tracemalloc.start()
    solver.step()
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    copy_dram, copy_fit = bandwidth(int(stream_mb * 2**20 / 8)), bandwidth(9 * len(P))
    return {
        "h": h,
        "t_from": t_from,
        "runs": runs,
        "steps_per_run": steps,
        "particles": n,
        "ms_per_step": ms,
        "stages_ms_per_step": {s: med(lambda w, s=s: w["stages"].get(s, 0.0)) for s in windows[0]["stages"]},
        "iterations_per_step": iterations,
        "rebuilds_per_100_steps": 100 * med(lambda w: w["rebuilds"]),
        "pairs_per_particle": {"within_r_plus_skin": pairs / len(P), "within_r": within / len(P)},
        "ns_per_particle_iteration": 1e6 * ms / (n * iterations),
        "bandwidth_GB_per_s": {"dram": copy_dram, "particle_array_size": copy_fit},
        "copy_bytes_per_particle_iteration": 1e-3 * ms / (n * iterations) * copy_dram["copy"] * 1e9,
        "bytes_per_particle": {
            "particles": held_bytes(P) / len(P),
            "pair_lists": held_bytes(average) / len(P),
            "step_peak": peak / len(P),
        },
    }


def report(r: dict) -> list[str]:
    b, m, pairs = r["bandwidth_GB_per_s"], r["bytes_per_particle"], r["pairs_per_particle"]
    lines = [
        f"silo h = {1e3 * r['h']:g} mm, r = 5 mm, flowing from t = {r['t_from']:g} s: "
        f"{r['particles']:.0f} particles, {r['runs']} runs x {r['steps_per_run']} steps; medians:",
        *(f"  {s:16s} {t:8.2f} ms/step" for s, t in r["stages_ms_per_step"].items()),
        f"  {'step':16s} {r['ms_per_step']:8.2f} ms/step",
        f"  fixed-point iterations {r['iterations_per_step']:.2f} per step, pair-list rebuilds "
        f"{r['rebuilds_per_100_steps']:.1f} per 100 steps, pairs per particle "
        f"{pairs['within_r_plus_skin']:.1f} (within r: {pairs['within_r']:.1f})",
        f"  {r['ns_per_particle_iteration']:.1f} ns per particle-iteration = "
        f"{r['copy_bytes_per_particle_iteration']:.0f} bytes of STREAM copy at {b['dram']['copy']:.1f} GB/s "
        f"(triad {b['dram']['triad']:.1f}; on arrays the size of the stresses: copy "
        f"{b['particle_array_size']['copy']:.1f}, triad {b['particle_array_size']['triad']:.1f})",
        f"  memory per particle: particles {m['particles']:.0f} B, pair lists {m['pair_lists']:.0f} B, "
        f"a step's peak allocation {m['step_peak']:.0f} B",
        f"silo h = {1e3 * r['h']:g} mm: {r['ms_per_step']:.2f} ms/step",
    ]
    return lines


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--h", type=float, nargs="+", default=[0.005, 0.0025], help="cell sizes [m]")
    parser.add_argument("--t-from", type=float, default=0.05, help="time after the opening [s]")
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--steps", type=int, default=100)
    parser.add_argument(
        "--stream-mb", type=float, default=256.0, help="STREAM's arrays [MB each], beyond the caches"
    )
    parser.add_argument("--json", type=Path, default=Path(__file__).with_name("silo_step.json"))
    args = parser.parse_args()
    if not args.stream_mb > 0.0:
        parser.error("--stream-mb must be > 0")
    for name in ("runs", "steps"):
        if getattr(args, name) < 1:
            parser.error(f"--{name.replace('_', '-')} must be >= 1")
    if not args.t_from > 0.0:
        parser.error("--t-from must be > 0 s")
    if MPI.COMM_WORLD.size > 1:
        parser.error("runs on one rank (benchmarks/mpi_scaling.py measures ranks)")
    results = {
        "dolfinx": dm.compat.dolfinx.__version__,
        "python": platform.python_version(),
        "ranks": 1,
        "silo": [],
    }
    for h in args.h:
        r = measure(h, args.t_from, args.runs, args.steps, args.stream_mb)
        results["silo"].append(r)
        print("\n".join(report(r)), flush=True)
    args.json.write_text(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
