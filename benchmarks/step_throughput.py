"""Particle-steps per second of the explicit step, in total and per stage.

An elastic block of ~10^5 particles (4 per triangle) falls and bounces on a frictional
floor under gravity; each run times `--steps` steps after a warm-up, and the median of
`--runs` runs is reported. Writes the numbers to JSON.

    python benchmarks/step_throughput.py [--particles 100000] [--runs 5] [--steps 20]
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

from dolfin_mpm.solver import STAGES


def elastic_case(n_particles: int) -> dm.Solver:
    ppc = 4
    nx = round(np.sqrt(n_particles / (2 * ppc)))  # the block fills 1.0 of the 1.2 m height
    ny = round(1.2 * nx)
    msh = mesh.create_rectangle(
        MPI.COMM_WORLD, [np.zeros(2), np.array([1.0, 1.2])], [nx, ny], mesh.CellType.triangle
    )
    grid = dm.Grid(msh)
    mat = dm.LinearElastic(E=1e6, nu=0.3, rho=1500.0)
    P = dm.seed(grid, mat, ppc=ppc, where=lambda x: x[1] < 1.0 + 1e-9)
    bcs = [
        dm.FrictionalWall(grid.nodes_where(lambda x: np.isclose(x[1], 0.0)), normal=(0, -1), mu=0.4),
        dm.SlipBC(grid.nodes_where(lambda x: np.isclose(x[0], 0.0) | np.isclose(x[0], 1.0)), normal=(1, 0)),
    ]
    return dm.Solver(grid, P, mat, bcs=bcs, gravity=(0, -9.81))


def measure(n_particles: int, steps: int) -> dict:
    solver = elastic_case(n_particles)
    for _ in range(3):  # warm-up: first locate, caches
        solver.step()
    solver.timings.clear()
    t0 = time.perf_counter()
    for _ in range(steps):
        solver.step()
    total = time.perf_counter() - t0
    n = solver.num_particles()
    return {
        "particles": n,
        "total": n * steps / total,
        "stages": {s: n * steps / solver.timings[s] for s in STAGES},
        "ms_per_step": {s: 1e3 * solver.timings[s] / steps for s in STAGES},
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--particles", type=int, default=100_000)
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--json", type=Path, default=Path(__file__).with_name("step_throughput.json"))
    args = parser.parse_args()

    runs = [measure(args.particles, args.steps) for _ in range(args.runs)]
    med = lambda key, s=None: float(np.median([r[key][s] if s else r[key] for r in runs]))  # noqa: E731
    result = {
        "case": "elastic",
        "particles": runs[0]["particles"],
        "ranks": MPI.COMM_WORLD.size,
        "runs": args.runs,
        "steps_per_run": args.steps,
        "dolfinx": dm.compat.dolfinx.__version__,
        "python": platform.python_version(),
        "particle_steps_per_s": med("total"),
        "per_stage_particle_steps_per_s": {s: med("stages", s) for s in STAGES},
        "per_stage_ms_per_step": {s: med("ms_per_step", s) for s in STAGES},
    }
    if MPI.COMM_WORLD.rank == 0:
        print(
            f"{result['particles']} particles, {args.runs} runs x {args.steps} steps, "
            f"DOLFINx {result['dolfinx']}, {result['ranks']} rank(s); medians:"
        )
        for s in STAGES:
            print(
                f"  {s:12s} {result['per_stage_ms_per_step'][s]:8.2f} ms/step "
                f"{result['per_stage_particle_steps_per_s'][s]:10.2e} particle-steps/s"
            )
        print(f"elastic: {result['particle_steps_per_s']:.1e} particle-steps/s")
        args.json.write_text(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
