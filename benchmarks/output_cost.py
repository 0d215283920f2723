"""Cost of the XDMF/HDF5 output under MPI, by layout: gathered to rank 0, collective, per rank.

Times one `Output.write` (particles and grid) of the silo (``--h``: 2 mm is ~1.2e5 particles,
0.625 mm ~1.2e6) in each layout this h5py can write (`dolfin_mpm.io.xdmf.LAYOUTS`; the
collective one needs h5py built with MPI: on Debian `apt-get install python3-h5py-mpi`, which
h5py loads under `mpirun`), beside one explicit step, and rank 0's peak memory during the write
beyond what it held before (numpy's buffers, through `tracemalloc`). The gathered write holds
every rank's particles on rank 0; the other two hold rank 0's own. Medians over ``--writes``.
The same for a checkpoint of the run (`dolfin_mpm.io.checkpoint`), written and read back: its
write gathers to rank 0 where h5py is serial, and is collective otherwise; each rank reads its
own part. Writes JSON beside the script, one entry per rank count and particle count:

    mpirun -n 2 python benchmarks/output_cost.py [--h 0.002] [--writes 5]
"""

import argparse
import json
import shutil
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import dolfin_mpm as dm  # first: loads DOLFINx's libraries

# isort: split
import h5py
import numpy as np
from mpi4py import MPI

from dolfin_mpm.app.scenario import Simulation
from dolfin_mpm.io import checkpoint, xdmf

sys.path.insert(0, str(Path(__file__).parents[1] / "demos"))
import demo_silo


def timed(comm: MPI.Comm, action, repeats: int) -> float:
    """Median over ``repeats`` of the slowest rank's time for ``action()`` [s]."""
    times = []
    for _ in range(repeats):
        comm.Barrier()
        start = time.perf_counter()
        action()
        times.append(comm.allreduce(time.perf_counter() - start, MPI.MAX))
    return float(np.median(times))


def peak_bytes(comm: MPI.Comm, action) -> int:
    """The peak of what ``action()`` (collective) allocates on rank 0 beyond what it held [bytes]."""
    if comm.rank == 0:
        tracemalloc.start()
        before, _ = tracemalloc.get_traced_memory()
    action()
    peak = 0
    if comm.rank == 0:
        peak = tracemalloc.get_traced_memory()[1] - before
        tracemalloc.stop()
    return comm.bcast(peak, root=0)


def measure(comm: MPI.Comm, solver, folder: Path, layout: str, writes: int) -> dict:
    """One layout: write time, rank 0's peak memory in a write, bytes on disk per write."""
    with dm.Output(folder / layout, comm, layout=layout) as out:

        def write_again():
            out.last_time = None  # the same state again: not skipped as already written
            out.write(solver)

        seconds = timed(comm, write_again, writes)
        peak = peak_bytes(comm, write_again)
    files = sorted((folder / layout).glob("*.h5")) if comm.rank == 0 else []
    size = sum(f.stat().st_size for f in files) / (writes + 1)
    return {"write_s": seconds, "rank0_peak_bytes": peak, "bytes_per_write": comm.bcast(size, root=0)}


def measure_checkpoint(comm: MPI.Comm, solver, folder: Path, repeats: int) -> dict:
    """A checkpoint of the run: write and read time, rank 0's peak memory in each, its size."""
    sim = Simulation(config={}, solver=solver, walls={}, applied=[])
    path = folder / "checkpoint.h5"

    def write():
        checkpoint.write(path, sim, {})

    def read():
        checkpoint.read(path, comm)

    out = {"write_s": timed(comm, write, repeats), "write_rank0_peak_bytes": peak_bytes(comm, write)}
    out |= {"read_s": timed(comm, read, repeats), "read_rank0_peak_bytes": peak_bytes(comm, read)}
    return out | {"bytes": comm.bcast(path.stat().st_size if comm.rank == 0 else None, root=0)}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--h", type=float, default=0.002, help="cell size [m]")
    parser.add_argument("--writes", type=int, default=5)
    parser.add_argument("--json", type=Path, default=Path(__file__).with_name("output_cost.json"))
    args = parser.parse_args()
    comm = MPI.COMM_WORLD
    solver, _ = demo_silo.build(h=args.h, radius=2 * args.h, comm=comm)
    solver.step()
    step = timed(comm, solver.step, 3)
    folder = Path(tempfile.mkdtemp()) if comm.rank == 0 else None
    folder = comm.bcast(folder)
    layouts = [layout for layout in xdmf.LAYOUTS if layout != "collective" or h5py.get_config().mpi]
    n = solver.num_particles()
    result = {"ranks": comm.size, "particles": n, "step_s": step}
    result |= {layout: measure(comm, solver, folder, layout, args.writes) for layout in layouts}
    result["checkpoint"] = measure_checkpoint(comm, solver, folder, args.writes)
    if comm.rank != 0:
        return
    shutil.rmtree(folder)
    table = json.loads(args.json.read_text()) if args.json.exists() else {}
    table[f"{comm.size} ranks, {n} particles"] = result
    args.json.write_text(json.dumps(table, indent=2))
    print(f"{comm.size} rank(s), {n} particles; one step {1e3 * step:.1f} ms; {args.writes} writes, medians:")
    print(f"  {'layout':<11} {'write [ms]':>10} {'= steps':>8} {'rank 0 peak [MB]':>17} {'B/particle':>11}")
    for layout in layouts:
        r = result[layout]
        print(
            f"  {layout:<11} {1e3 * r['write_s']:>10.1f} {r['write_s'] / step:>8.2f} "
            f"{r['rank0_peak_bytes'] / 1e6:>17.1f} {r['rank0_peak_bytes'] / n:>11.1f}"
        )
    c = result["checkpoint"]
    print(
        f"  checkpoint: write {1e3 * c['write_s']:.1f} ms, rank 0 peak {c['write_rank0_peak_bytes'] / n:.1f} "
        f"B/particle; read {1e3 * c['read_s']:.1f} ms, rank 0 peak {c['read_rank0_peak_bytes'] / n:.1f} "
        f"B/particle; {c['bytes'] / n:.1f} B/particle on disk"
    )
    if "collective" not in layouts:
        print("  h5py here is a serial build: the collective layout is not measured")


if __name__ == "__main__":
    main()
