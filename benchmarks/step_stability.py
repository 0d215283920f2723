"""The stability estimate of a scenario's steps: how close the run comes to the explicit limit.

Runs a scenario (with ``--set`` overrides, as the CLI takes them) and records, every
``--every`` steps, the largest ``e_p = dt^2 omega_p^2 / 4`` over the particles
(:mod:`dolfin_mpm.explicit.stability`; stable while ``<= 1``), where and when it was. Prints the
quantiles over the run and writes them to JSON. E.g. the local a = 1 collapse on h = 2.5 mm:

    python benchmarks/step_stability.py demos/column_collapse.toml --set nonlocal.radius=0 \\
        --set mesh.upper=[0.4,0.12] --set mesh.cells=[160,48] --set bodies.column.region.max=[0.1,0.1] \\
        --set bodies.column.stress.surface=0.1 --set time.end=0.6
"""

import argparse
import json
from pathlib import Path

import dolfin_mpm  # noqa: F401  (first: loads DOLFINx's libraries)

# isort: split
import numpy as np
from mpi4py import MPI

from dolfin_mpm.app import scenario
from dolfin_mpm.explicit.stability import stability_ratio
from dolfin_mpm.explicit.step import SimulationError


def record(sim, every: int) -> tuple[list[dict], str | None]:
    """Run ``sim`` to its end; the largest ``e_p`` of every ``every``-th step, with its particle and time.

    Returns the samples and, if the run went bad, what stopped it (the samples up to there kept).
    """
    s, cfg, rows = sim.solver, sim.config, []

    def sample():
        e = stability_ratio(s)
        i = int(np.argmax(e)) if len(e) else -1
        local = (
            (float(e[i]), int(s.particles.id[i]), s.particles.x[i, :2].tolist()) if i >= 0 else (-1.0, -1, [])
        )
        top = max(s.comm.allgather(local))
        rows.append({"t": s.time, "step": s.step_count, "e_max": top[0], "particle": top[1], "x": top[2]})

    schedule = [(e["time"], k) for k, e in enumerate(cfg["events"])]
    try:
        for t_target, event in [*schedule, (cfg["time"]["end"], None)]:
            s.run_until(t_target, [(every, sample)])
            if event is not None:
                sim.apply_event(event)
    except (SimulationError, ValueError) as e:  # a particle lost or outside: the samples stand
        return rows, f"step {s.step_count}, t = {s.time:.6g} s: {e}"
    return rows, None


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenario", type=Path)
    parser.add_argument(
        "--set", action="append", default=[], metavar="KEY=VALUE", help="override a scenario value"
    )
    parser.add_argument("--every", type=int, default=1, help="steps between samples (default 1)")
    parser.add_argument("--json", type=Path, default=Path("benchmarks/step_stability.json"))
    args = parser.parse_args()
    if args.every < 1:
        parser.error(f"--every must be >= 1, got {args.every}")
    sim = scenario.build(scenario.load(args.scenario, args.set))
    rows, stopped = record(sim, args.every)
    e = np.array([r["e_max"] for r in rows])
    worst = rows[int(np.argmax(e))]
    quantiles = {q: float(np.quantile(e, q)) for q in (0.5, 0.9, 0.99, 1.0)}
    result = {
        "scenario": str(args.scenario),
        "overrides": args.set,
        "dt": sim.solver.dt,
        "samples": len(rows),
        "e_max_quantiles": quantiles,
        "unstable_samples": int(np.count_nonzero(e > 1.0)),
        "worst": worst,
        "stopped": stopped,
        "last_samples": rows[-50:],
    }
    if MPI.COMM_WORLD.rank == 0:
        print(
            f"{len(rows)} steps sampled, dt = {sim.solver.dt:.4g} s: largest e_p over the particles, "
            + ", ".join(f"{100 * q:g} %: {v:.3f}" for q, v in quantiles.items())
            + f"; above 1 in {result['unstable_samples']}"
        )
        print(
            f"largest {worst['e_max']:.3f} at t = {worst['t']:.4g} s, "
            f"particle {worst['particle']} at x = {worst['x']}"
        )
        if stopped:
            print(f"the run stopped: {stopped}")
        args.json.write_text(json.dumps(result, indent=1))
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
