"""Cost of the XDMF/HDF5 output against the step it interrupts: gathering to rank 0 or not.

The output gathers every rank's particles to rank 0, which alone writes (`dolfin_mpm.io.xdmf`). This
times one `Output.write` of the silo (``--h``, 2 mm: ~1.2e5 particles; particles and grid) on
as many ranks as the script is started with, beside one explicit step, and reports how many
steps one output costs. With h5py built for MPI it also times the alternative, each rank
writing its own slice of the same particle fields into one file collectively
(``driver="mpio"``; without the grid and the XDMF file). Debian's `python3-h5py` and PyPI's
h5py wheels are serial builds, so that part is skipped there (on Debian, `apt-get install
python3-h5py-mpi` adds the MPI build, which h5py then loads under `mpirun`).
Writes JSON beside the script (one entry per rank count):

    mpirun -n 2 python benchmarks/output_cost.py [--h 0.002] [--writes 5]
"""

import argparse
import json
import shutil
import sys
import tempfile
import time
from pathlib import Path

import dolfin_mpm as dm  # first: loads DOLFINx's libraries

# isort: split
import h5py
import numpy as np
from mpi4py import MPI

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


def collective_write(comm: MPI.Comm, path: Path, arrays: dict[str, np.ndarray]) -> None:
    """Each rank's rows of ``arrays`` into one dataset per array, written collectively."""
    with h5py.File(path, "w", driver="mpio", comm=comm) as f:
        for name, a in arrays.items():
            counts = comm.allgather(len(a))
            start = sum(counts[: comm.rank])
            dset = f.create_dataset(name, (sum(counts), *a.shape[1:]), dtype=a.dtype)
            with dset.collective:
                dset[start : start + len(a)] = a


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--h", type=float, default=0.002, help="cell size [m]")
    parser.add_argument("--writes", type=int, default=5)
    parser.add_argument("--json", type=Path, default=Path(__file__).with_name("output_cost.json"))
    args = parser.parse_args()
    comm = MPI.COMM_WORLD
    solver, _ = demo_silo.build(h=args.h, radius=2 * args.h, comm=comm)
    solver.step()
    step = timed(comm, solver.step, 5)
    folder = Path(tempfile.mkdtemp()) if comm.rank == 0 else None
    folder = comm.bcast(folder)
    with dm.Output(folder / "gathered", comm) as out:

        def write_again():
            out.last_time = None  # the same state again: not skipped as already written
            out.write(solver)

        write = timed(comm, write_again, args.writes)
    result = {
        "ranks": comm.size,
        "particles": solver.num_particles(),
        "step_s": step,
        "gathered_write_s": write,
        "h5_bytes_per_write": (folder / "gathered" / "particles.h5").stat().st_size / args.writes
        if comm.rank == 0
        else 0.0,
    }
    if h5py.get_config().mpi:
        P = solver.particles
        arrays = {"x": P.x, **dm.io.xdmf.particle_fields(P)}  # what the gathered output writes
        result["collective_particle_write_s"] = timed(
            comm, lambda: collective_write(comm, folder / "collective.h5", arrays), args.writes
        )
    if comm.rank == 0:
        shutil.rmtree(folder)
        table = json.loads(args.json.read_text()) if args.json.exists() else {}
        table[str(comm.size)] = result
        args.json.write_text(json.dumps(table, indent=2))
        r = result
        size = r["h5_bytes_per_write"] / 1e6
        print(f"{comm.size} rank(s), {r['particles']} particles, medians:")
        print(f"  one step {1e3 * step:.1f} ms; one output (gathered to rank 0, particles and grid) "
              f"{1e3 * write:.1f} ms = {write / step:.2f} steps; {size:.1f} MB of particle data")  # fmt: skip
        if "collective_particle_write_s" in r:
            collective = 1e3 * r["collective_particle_write_s"]
            print(f"  particles written collectively (h5py-mpi): {collective:.1f} ms")
        else:
            print("  h5py here is a serial build: the collective write is not measured")


if __name__ == "__main__":
    main()
