"""Particle-steps per second of the explicit step, in total and per stage.

A block of ~10^5 particles (4 per triangle) settles on a frictional floor under gravity,
either linear elastic (`elastic`) or the paper's Drucker–Prager sand with the non-local
fixed-point loop, r = 2h, cubic weight (`dp-nonlocal`). Each run times `--steps` steps after
a warm-up; the median of `--runs` runs is reported, per stage of the step (the stages do not
overlap and add up to the step). Writes the numbers to JSON.

    python benchmarks/step_throughput.py [--case all] [--particles 100000] [--runs 5] [--steps 20]
"""

import argparse
import json
import platform
import time
from pathlib import Path

import dolfin_mpm as dm  # first: loads DOLFINx's libraries

# isort: split
import numpy as np
from dolfinx import mesh
from mpi4py import MPI

from dolfin_mpm.explicit.step import STAGES


def block_case(n_particles: int, material, **solver_args) -> dm.Solver:
    ppc = 4
    nx = round(np.sqrt(n_particles / (2 * ppc)))  # the block fills 1.0 of the 1.2 m height
    ny = round(1.2 * nx)
    msh = mesh.create_rectangle(
        MPI.COMM_WORLD, [np.zeros(2), np.array([1.0, 1.2])], [nx, ny], mesh.CellType.triangle
    )
    grid = dm.Grid(msh)
    P = dm.seed(grid, material, ppc=ppc, where=lambda x: x[1] < 1.0 + 1e-9)
    bcs = [
        dm.FrictionalWall(grid.nodes_where(lambda x: np.isclose(x[1], 0.0)), normal=(0, -1), mu=0.4),
        dm.SlipBC(grid.nodes_where(lambda x: np.isclose(x[0], 0.0) | np.isclose(x[0], 1.0)), normal=(1, 0)),
    ]
    if solver_args.pop("nonlocal_cells", None):
        solver_args["averaging"] = dm.NonlocalAverage(2.0 / nx, "cubic")  # r = 2h
    return dm.Solver(grid, P, material, bcs=bcs, gravity=(0, -9.81), **solver_args)


CASES = {
    "elastic": lambda n: block_case(n, dm.LinearElastic(E=1e6, nu=0.3, rho=1500.0)),
    # The paper's sand, r = 2h, cubic weight: the fixed-point loop runs every step.
    "dp-nonlocal": lambda n: block_case(
        n, dm.DruckerPragerViscoplastic(E=1e6, nu=0.3, rho=1500.0, phi=30.0, gamma=1e3), nonlocal_cells=2
    ),
}


def measure(case: str, n_particles: int, steps: int) -> dict:
    solver = CASES[case](n_particles)
    for _ in range(3):  # warm-up: first locate, caches
        solver.step()
    solver.timings.clear()
    t0 = time.perf_counter()
    for _ in range(steps):
        solver.step()
    total = time.perf_counter() - t0
    n = solver.num_particles()
    stages = [s for s in STAGES if s in solver.timings]  # they do not overlap: their sum is the step
    fp = solver.fixed_point
    return {
        "particles": n,
        "total": n * steps / total,
        "stages": {s: n * steps / solver.timings[s] for s in stages},
        "ms_per_step": {s: 1e3 * solver.timings[s] / steps for s in stages},
        "ms_per_step_sum_of_stages": 1e3 * solver.timer.total / steps,
        "ms_per_step_measured": 1e3 * total / steps,
        "mean_iterations": fp["iterations"] / fp["steps"] if fp["steps"] else 0.0,
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--case", choices=[*CASES, "all"], default="all")
    parser.add_argument("--particles", type=int, default=100_000)
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--json", type=Path, default=Path(__file__).with_name("step_throughput.json"))
    args = parser.parse_args()

    results = {}
    for case in CASES if args.case == "all" else [args.case]:
        runs = [measure(case, args.particles, args.steps) for _ in range(args.runs)]
        med = lambda key, s=None: float(np.median([r[key][s] if s else r[key] for r in runs]))  # noqa: E731
        stages = list(runs[0]["stages"])
        result = {
            "particles": runs[0]["particles"],
            "ranks": MPI.COMM_WORLD.size,
            "runs": args.runs,
            "steps_per_run": args.steps,
            "dolfinx": dm.compat.dolfinx.__version__,
            "python": platform.python_version(),
            "particle_steps_per_s": med("total"),
            "per_stage_particle_steps_per_s": {s: med("stages", s) for s in stages},
            "per_stage_ms_per_step": {s: med("ms_per_step", s) for s in stages},
            "ms_per_step_sum_of_stages": med("ms_per_step_sum_of_stages"),
            "ms_per_step_measured": med("ms_per_step_measured"),
            "mean_fixed_point_iterations": med("mean_iterations"),
        }
        results[case] = result
        if MPI.COMM_WORLD.rank == 0:
            print(
                f"{case}: {result['particles']} particles, {args.runs} runs x {args.steps} steps, "
                f"DOLFINx {result['dolfinx']}, {result['ranks']} rank(s); medians:"
            )
            for s in stages:
                print(
                    f"  {s:14s} {result['per_stage_ms_per_step'][s]:8.2f} ms/step "
                    f"{result['per_stage_particle_steps_per_s'][s]:10.2e} particle-steps/s"
                )
            print(
                f"  {'sum of stages':14s} {result['ms_per_step_sum_of_stages']:8.2f} ms/step "
                f"(step measured around the calls: {result['ms_per_step_measured']:.2f})"
            )
            if result["mean_fixed_point_iterations"]:
                print(f"  mean fixed-point iterations per step: {result['mean_fixed_point_iterations']:.1f}")
            print(f"{case}: {result['particle_steps_per_s']:.1e} particle-steps/s")
    if MPI.COMM_WORLD.rank == 0:
        args.json.write_text(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
