"""Strong scaling of the paper's silo step (Drucker–Prager, non-local r = 2h, outlet open).

The same silo on ``--h`` (2 mm: ~1.2e5 particles) on as many ranks as the script is started
with. The outlet opens at the start; each run times ``--steps`` steps once ``--warmup`` steps
have set the fill flowing (particles then cross the partition, and halos and pair lists are
rebuilt as they move), and the median of ``--runs`` runs is kept. The cells go to the ranks as
``--partition`` says (:data:`demo_silo.PARTITIONS`; by default dealt anew by the particles when
a rank holds 5 % more than the mean). Prints the time per step, the share spent migrating
particles, exchanging non-local halos and rebalancing, and the speed-up against the one-rank
entry of the JSON file, which collects one entry per rank count:

    mpirun -n 1 python benchmarks/mpi_scaling.py
    mpirun -n 2 python benchmarks/mpi_scaling.py
    mpirun -n 2 python benchmarks/mpi_scaling.py --independent

``--independent`` runs the whole one-rank silo on every rank at once, each on its own: no
communication and perfect balance, so ``N t(1 rank alone) / t(N side by side)`` is the most
the machine's shared memory bandwidth and clocks allow N ranks to gain.

On a shared machine a run's time drifts by tens of percent from one minute to the next, and a
two-rank run suffers more (it needs every core). So each start adds its runs to the samples of
its rank count in the JSON file (``--fresh``: starts them anew), and the figures are medians over
the samples: started in turn, the rank counts see the same drift,

    for i in 1 2 3 4 5; do mpirun -n 1 python benchmarks/mpi_scaling.py --runs 1
                           mpirun -n 2 python benchmarks/mpi_scaling.py --runs 1; done

and the speed-up printed is the median of the ratios of the samples taken side by side (the
k-th of one rank over the k-th of N). The time of each stage of the step on the slowest rank
shows where the ranks lose against one (``stages_ms``).
"""

import argparse
import json
import sys
import time
from pathlib import Path

import dolfin_mpm as dm  # first: loads DOLFINx's libraries

# isort: split
import numpy as np
from mpi4py import MPI

from dolfin_mpm.explicit.step import STAGES

sys.path.insert(0, str(Path(__file__).parents[1] / "demos"))
import demo_silo


def measure(h: float, warmup: int, steps: int, comm: MPI.Comm, partition: str) -> dict:
    """Timings of one run on ``comm``; barriers and maxima over all ranks of COMM_WORLD."""
    solver, gate = demo_silo.build(h=h, radius=2 * h, comm=comm, partition=partition)
    solver.bcs = [bc for bc in solver.bcs if bc is not gate]  # discharging: particles cross ranks
    solver.run_until(0.0, steps=warmup)  # the run loop: it rebalances
    solver.timings.clear()
    repartitions = solver.repartitions
    rebuilds = solver.averaging.rebuilds
    halo_before = getattr(solver.averaging, "halo_seconds", 0.0)  # serial: no halo
    world = MPI.COMM_WORLD
    world.Barrier()
    start = time.perf_counter()
    solver.run_until(0.0, steps=steps)
    world.Barrier()
    total = time.perf_counter() - start
    halo = world.allreduce(getattr(solver.averaging, "halo_seconds", 0.0) - halo_before, MPI.MAX)
    migrate = world.allreduce(solver.timings.get("migrate", 0.0), MPI.MAX)
    rebalance = world.allreduce(solver.timings.get("rebalance", 0.0), MPI.MAX)
    stages = {k: 1e3 * world.allreduce(solver.timings.get(k, 0.0), MPI.MAX) / steps for k in STAGES}
    return {
        "particles": solver.num_particles(),
        "ms_per_step": 1e3 * total / steps,
        "migrate_ms_per_step": 1e3 * migrate / steps,
        "halo_ms_per_step": 1e3 * halo / steps,
        "rebalance_ms_per_step": 1e3 * rebalance / steps,
        "repartitions": solver.repartitions - repartitions,
        "particles_per_rank_max": world.allreduce(len(solver.particles), MPI.MAX),
        "pair_rebuilds": world.allreduce(solver.averaging.rebuilds - rebuilds, MPI.MAX),
        "stages_ms": {k: v for k, v in stages.items() if v > 0.0},
    }


def times(table: dict, key: str) -> list[float]:
    """The ms/step of each sample of the entry ``key``."""
    return [s["ms_per_step"] for s in table[key]["samples"]]


def speed_up(one: list[float], many: list[float]) -> float:
    """Median over the samples taken side by side of ``t(1 rank) / t(N ranks)`` [ms/step each]."""
    k = min(len(one), len(many))
    return float(np.median(np.array(one[-k:]) / np.array(many[-k:])))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--h", type=float, default=0.002, help="cell size [m]")
    parser.add_argument("--warmup", type=int, default=400, help="steps before the timing")
    parser.add_argument("--steps", type=int, default=50)
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--independent", action="store_true", help="one whole silo per rank, side by side")
    parser.add_argument("--partition", default="rebalance", choices=demo_silo.PARTITIONS)
    parser.add_argument("--json", type=Path, default=Path(__file__).with_name("mpi_scaling.json"))
    parser.add_argument("--fresh", action="store_true", help="forget the samples of earlier starts")
    args = parser.parse_args()
    if args.runs < 1 or args.steps < 1 or args.warmup < 0:
        parser.error("--runs and --steps must be >= 1, --warmup >= 0")
    comm = MPI.COMM_WORLD
    run_comm = MPI.COMM_SELF if args.independent else comm
    runs = [measure(args.h, args.warmup, args.steps, run_comm, args.partition) for _ in range(args.runs)]
    if comm.rank > 0:
        return
    table = json.loads(args.json.read_text()) if args.json.exists() else {}
    run = (args.h, args.warmup, args.steps)
    table = {
        k: v for k, v in table.items() if (v.get("h"), v.get("warmup"), v.get("steps_per_run")) == run
    }  # one silo and state per file
    key = f"{comm.size} independent" if args.independent else str(comm.size)
    key += f" {args.partition}" if comm.size > 1 and not args.independent else ""
    samples = [] if args.fresh or key not in table else table[key]["samples"]
    samples += runs
    r = {k: float(np.median([s[k] for s in samples])) for k in samples[0] if k != "stages_ms"}
    r["stages_ms"] = {k: float(np.median([s["stages_ms"].get(k, 0.0) for s in samples]))
                      for k in samples[-1]["stages_ms"]}  # fmt: skip
    r.update(ranks=comm.size, warmup=args.warmup, steps_per_run=args.steps, h=args.h,
             partition=args.partition, dolfinx=dm.compat.dolfinx.__version__, samples=samples)  # fmt: skip
    table[key] = r
    args.json.write_text(json.dumps(table, indent=2))
    n = len(samples)
    if args.independent:
        print(f"{comm.size} one-rank silos side by side, {r['particles']:.0f} particles each: "
              f"{r['ms_per_step']:.1f} ms/step (slowest; median of {n} runs)")  # fmt: skip
        if "1" in table:
            ceiling = comm.size * speed_up(times(table, "1"), times(table, key))
            print(f"  the machine's ceiling for the speed-up on {comm.size} ranks: {ceiling:.2f}")
        return
    most = r["particles_per_rank_max"]
    print(f"{comm.size} rank(s), {r['particles']:.0f} particles (at most {most:.0f} on one rank), "
          f"median of {n} runs of {args.steps} steps after {args.warmup}:")  # fmt: skip
    print(f"  {r['ms_per_step']:8.1f} ms/step, of which migration {r['migrate_ms_per_step']:.1f} "
          f"and halo exchange {r['halo_ms_per_step']:.1f} ms (slowest rank); "
          f"{r['pair_rebuilds']:.0f} pair-list rebuilds; {r['repartitions']:.0f} repartitions, "
          f"{r['rebalance_ms_per_step']:.2f} ms/step")  # fmt: skip
    print("  stages [ms/step, slowest rank]: " + ", ".join(f"{k} {v:.2f}" for k, v in r["stages_ms"].items()))
    if "1" in table and comm.size > 1:
        pairs = min(n, len(times(table, "1")))
        print(
            f"  speed-up on {comm.size} ranks: {speed_up(times(table, '1'), times(table, key)):.2f} "
            f"(median over {pairs} pairs of runs side by side)"
        )


if __name__ == "__main__":
    main()
