"""# Hopper discharge: inclined walls on an unstructured mesh

This demo shows how to put walls where the geometry is, independent of the mesh: a plane wedge
hopper whose walls, inclined at ``beta`` from the vertical, meet an outlet of width ``D``, on a
triangle mesh with no line along the walls (a Delaunay triangulation of jittered points). The
walls are :class:`dolfin_mpm.RigidWall` segments with Coulomb friction; the outlet is closed by
a third one, the gate, during a damped settling phase and opened at t = 0.

The fill is the paper's sand (local model by default, ``--radius`` for the non-local one). The
flow rate is the slope of the mass that has passed the outlet plane, fitted over the second
half of the run; a mesh study gives it on each mesh and its change between the two finest:

    python demos/demo_hopper.py                    # h = 10 and 5 mm (~2 min)
    python demos/demo_hopper.py --h 0.01           # one mesh

For comparison, a flat-bottomed slot of the same width discharges at Beverloo's
``W = C rho sqrt(g) D^(3/2)``, ``C = 0.58-1.5``; a hopper steeper than the stagnant zones of a
flat bottom (about 60° from the horizontal for this sand) discharges faster.
"""

import argparse
import math
import time

import dolfin_mpm as dm  # import first: it loads DOLFINx's libraries

# isort: split
import numpy as np
from mpi4py import MPI

from dolfin_mpm.core import compat

SAND = {"E": 1e6, "nu": 0.3, "rho": 1500.0, "phi": 30.0, "gamma": 1e3, "N": 1.0}  # the paper's
G = 9.81


def unstructured_rectangle(comm, lower, upper, h, jitter=0.3, seed=1):
    """A Delaunay triangulation of ``[lower, upper]`` with vertices ``h`` [m] apart, moved at random
    by up to ``jitter * h`` (those on the boundary along it): no mesh line is straight for long."""
    cells, x = np.zeros((0, 3), np.int64), np.zeros((0, 2))
    if comm.rank == 0:
        from scipy.spatial import Delaunay

        nx, ny = (max(1, round((b - a) / h)) for a, b in zip(lower, upper))
        X, Y = np.meshgrid(np.linspace(lower[0], upper[0], nx + 1), np.linspace(lower[1], upper[1], ny + 1))
        x = np.c_[X.ravel(), Y.ravel()]
        rng = np.random.default_rng(seed)
        shift = rng.uniform(-jitter, jitter, x.shape) * np.array(
            [(upper[0] - lower[0]) / nx, (upper[1] - lower[1]) / ny]
        )
        on_x = np.isclose(x[:, 0], lower[0]) | np.isclose(x[:, 0], upper[0])
        on_y = np.isclose(x[:, 1], lower[1]) | np.isclose(x[:, 1], upper[1])
        shift[on_x, 0] = 0.0
        shift[on_y, 1] = 0.0
        x = x + shift
        cells = Delaunay(x).simplices.astype(np.int64)
    return compat.create_mesh(comm, cells, x)


def build(h=0.01, D=0.08, beta=30.0, height=0.2, wall_friction=20.0, radius=0.0, ppc=4, comm=MPI.COMM_WORLD):
    """The hopper on a mesh of ``h`` [m]: the solver and the gate, before settling.

    Args:
        h: mesh spacing [m]; at least 4 across the outlet.
        D: outlet width [m].
        beta: wall angle from the vertical [degrees], in (0, 60].
        height: height of the fill above the outlet [m].
        wall_friction: wall friction angle [degrees], in [0, 90).
        radius: non-local radius r [m]; 0: the local model.
        ppc: particles per triangle.

    """
    for name, value in (("h", h), ("D", D), ("height", height)):
        if not (math.isfinite(value) and value > 0.0):
            raise ValueError(f"{name} must be a positive length [m], got {value!r}")
    if not 0.0 < beta <= 60.0:
        raise ValueError(f"beta must be in (0, 60] degrees, got {beta}")
    if not 0.0 <= wall_friction < 90.0:
        raise ValueError(f"wall_friction must be in [0, 90) degrees, got {wall_friction}")
    if D < 4 * h - 1e-12:
        raise ValueError(
            f"h = {h} m cannot resolve the outlet: need at least 4 cells across it (h <= {D / 4} m)"
        )
    t = math.tan(math.radians(beta))
    top = height + 2 * h  # the walls go on above the fill
    x0, x1 = -0.5 * D, 0.5 * D  # the outlet's edges
    half = 0.5 * D + top * t  # half the width at the top of the walls
    drop = 0.5 * D  # free fall below the outlet down to the catch line
    grid = dm.Grid(unstructured_rectangle(comm, (-half - h, -drop - 2 * h), (half + h, top + h), h))

    def inside(x):  # the wedge up to the fill height
        return (x[1] > 0.0) & (x[1] < height) & (np.abs(x[0]) < 0.5 * D + x[1] * t)

    sand = dm.DruckerPragerViscoplastic(**SAND)
    P = dm.seed(grid, sand, ppc=ppc, where=inside)
    K0 = SAND["nu"] / (1.0 - SAND["nu"])
    P.sigma = dm.geostatic_stress(P.x, SAND["rho"], G, height, K0)
    mu = math.tan(math.radians(wall_friction))
    walls = [  # the material on the left, going from the first point to the second
        dm.RigidWall([(-half, top), (x0, 0.0)], mu, "left wall"),
        dm.RigidWall([(x1, 0.0), (half, top)], mu, "right wall"),
    ]
    gate = dm.RigidWall([(x0, 0.0), (x1, 0.0)], mu, "gate")
    sink = dm.Sink("discharged", region=lambda x: x[1] < -drop)
    solver = dm.Solver(
        grid, P, sand, bcs=[*walls, gate], gravity=(0.0, -G), sinks=[sink],
        averaging=dm.NonlocalAverage(radius, "cubic"),
    )  # fmt: skip
    return solver, gate


def discharged_mass(solver) -> float:
    """Mass that has passed the outlet plane y = 0 [kg/m], all ranks."""
    P = solver.particles
    return solver.comm.allreduce(float(P.mass[P.x[:, 1] < 0.0].sum()) + solver.sinks["discharged"].mass)


def run(h=0.01, t_end=0.2, t_settle=0.02, interval=0.005, progress=True, **sizes) -> dict:
    """Settle, open the gate at t = 0, discharge until ``t_end`` [s]; the flow rate [kg/s/m]."""
    solver, gate = build(h, **sizes)
    m0, start = solver.total_mass(), time.perf_counter()
    solver.time = -math.ceil(t_settle / solver.dt) * solver.dt
    solver.damping = 0.2
    solver.run(0.0, progress=progress)
    solver.damping = 0.0
    solver.bcs = [bc for bc in solver.bcs if bc is not gate]
    t, mass = [], []

    class Record:
        def write(self, s):
            t.append(s.time)
            mass.append(discharged_mass(s))

    solver.run(t_end, output=Record(), output_interval=interval, progress=progress)
    t, mass = np.array(t), np.array(mass)
    late = t >= 0.5 * t_end
    return {
        "h": h,
        "flow_rate": float(np.polyfit(t[late], mass[late], 1)[0]),
        "discharged": float(mass[-1]),
        "mass_error": abs(solver.total_mass() + solver.comm.allreduce(solver.sinks["discharged"].mass) - m0)
        / m0,
        "particles": solver.num_particles(),
        "wall_stops": solver.comm.allreduce(solver.state.wall_stops),
        "seconds": time.perf_counter() - start,
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0].lstrip("# "))
    parser.add_argument("--h", type=float, nargs="+", default=[0.01, 0.005], help="mesh spacings [m]")
    parser.add_argument("--radius", type=float, default=0.0, help="non-local radius r [m]")
    parser.add_argument("--t-end", type=float, default=0.2, help="end of the discharge [s]")
    args = parser.parse_args()
    results = [run(h, t_end=args.t_end, radius=args.radius) for h in args.h]
    if MPI.COMM_WORLD.rank > 0:
        return
    for r in results:
        print(
            f"h = {1e3 * r['h']:g} mm: flow rate {r['flow_rate']:.1f} kg/s/m, {r['particles']} particles, "
            f"{r['wall_stops']} moves stopped at a wall, {r['seconds']:.0f} s"
        )
    # ## Verification
    # The mass is conserved to round-off; the flow rate's change between the two finest meshes
    # is its mesh error (the number to quote with it).
    if len(results) > 1:
        a, b = results[-2], results[-1]
        change = b["flow_rate"] / a["flow_rate"] - 1
        print(f"mesh study: flow rate {b['flow_rate']:.1f} kg/s/m, change {change:+.3f}")


if __name__ == "__main__":
    main()
