# # A 3D silo: the paper's sand through a square outlet
#
# The paper's plane silo (`demo_silo.py`) made a box: 20 x 20 cm, 30 cm of fill, a square
# outlet of 10 x 10 cm in the middle of the flat bottom, on tetrahedra (cubes of h, six each).
# The paper's sand, the walls and plates as facets with 20° friction (the outlet is 10 cm
# wide wherever the nodes fall), the non-local average over spheres of radius r, geostatic
# stresses, 0.02 s of damped settling on the closed outlet, then the discharge. The flow rate
# is set against Beverloo's law for a square outlet.
#
#     python demos/demo_silo3d.py                     # h = 10 mm, r = 5 mm, to t = 0.25 s
#     mpirun -n 2 python demos/demo_silo3d.py --h 0.02 --t-end 0.1
#
# Writes `particles.xdmf` / `grid.xdmf` (ParaView) and `section.png`, the particles of the
# vertical mid-section coloured by their speed, to `--output`.
"""A 3D silo: the paper's sand through a square outlet in a flat bottom."""

import argparse
import math
import sys
import time
from pathlib import Path

import dolfin_mpm as dm  # import first: it loads DOLFINx's libraries

# isort: split
import numpy as np
from mpi4py import MPI

sys.path.insert(0, str(Path(__file__).parent))
from demo_silo import SAND, G, check_geometry, flow_rate, settle_and_open  # the plane silo's

from dolfin_mpm.post.plotting import figure

#: Beverloo's law for a square outlet of side D (continuum, grains -> 0): W = C rho sqrt(g) D^(5/2)
#: with C = 0.58-0.64 for circles of diameter D (Beverloo, Leniger & van de Velde 1961; Nedderman,
#: Statics and kinematics of granular materials, 1992), carried over through the area and the
#: hydraulic diameter (W ~ A sqrt(D_h)): a square has 4 / pi the circle's A sqrt(D_h).
BEVERLOO_C = tuple(c * 4.0 / math.pi for c in (0.58, 0.64))


def facet(corners, material) -> np.ndarray:
    """The corners of a facet in the order that puts ``material`` (a point) on its front side."""
    corners = np.asarray(corners, dtype=np.float64)
    in_front = dm.RigidWall(corners).distance(np.atleast_2d(material))[0] > 0.0
    return corners if in_front else corners[::-1]


def build(h=0.01, radius=5e-3, wall_friction=20.0, width=0.2, height=0.3, outlet=0.1, ppc=4,
          comm=MPI.COMM_WORLD):  # fmt: skip
    """The silo on cubes of ``h`` [m]: solver and the outlet's gate, before settling.

    Args:
        h: cell size [m]; must divide the width and the height, 4 cells at least across the outlet.
        radius: non-local radius r [m]; 0 for the local model.
        wall_friction: wall and bottom friction angle [degrees], in [0, 90).
        width, height, outlet: the box's side, the fill's height and the outlet's side [m].
        ppc: particles per tetrahedron.
        comm: on several ranks the cells go to them in slabs across x of equal fill.

    Returns:
        ``(solver, gate)``; the gate is a rigid wall in ``solver.bcs``.

    """
    check_geometry(width, height, outlet, h)
    if not 0.0 <= wall_friction < 90.0:
        raise ValueError(f"wall_friction must be in [0, 90) degrees, got {wall_friction}")
    a, b = 0.5 * (width - outlet), 0.5 * (width + outlet)  # the outlet is [a, b] x [a, b]
    drop = 0.5 * outlet  # free fall below the outlet down to the catch plane
    below = math.ceil(drop / h) + 1
    n = round(width / h)
    corners = [(0.0, 0.0, -below * h), (width, width, height + h)]
    fill = lambda c: (c[2] > 0.0) & (c[2] < height)  # noqa: E731
    msh = dm.partition.create_box(
        comm, corners, (n, n, below + round(height / h) + 1), weight=fill, axes=(0,)
    )
    grid = dm.Grid(msh)
    sand = dm.DruckerPragerViscoplastic(**SAND)
    inside = lambda x: (x[2] > 0.0) & (x[2] < height)  # noqa: E731
    P = dm.seed(grid, sand, ppc=ppc, where=inside)
    P.sigma = dm.geostatic_stress(P.x, SAND["rho"], G, height, SAND["nu"] / (1.0 - SAND["nu"]), gdim=3)

    mu, top, W = math.tan(math.radians(wall_friction)), height + h, width
    middle = (0.5 * W, 0.5 * W, 0.5 * height)
    rect = lambda x0, x1, y0, y1: [(x0, y0, 0.0), (x1, y0, 0.0), (x1, y1, 0.0), (x0, y1, 0.0)]  # noqa: E731
    sides = {
        "wall x = 0": [(0, 0, 0), (0, W, 0), (0, W, top), (0, 0, top)],
        "wall x = W": [(W, 0, 0), (W, W, 0), (W, W, top), (W, 0, top)],
        "wall y = 0": [(0, 0, 0), (W, 0, 0), (W, 0, top), (0, 0, top)],
        "wall y = W": [(0, W, 0), (W, W, 0), (W, W, top), (0, W, top)],
        # the bottom round the outlet, in four convex plates
        "plate x < a": rect(0, a, 0, W), "plate x > b": rect(b, W, 0, W),
        "plate y < a": rect(a, b, 0, a), "plate y > b": rect(a, b, b, W),
    }  # fmt: skip
    walls = [dm.RigidWall(facet(c, middle), mu, name) for name, c in sides.items()]
    gate = dm.RigidWall(facet(rect(a, b, a, b), middle), mu, "gate")
    off = lambda x: (x[0] < a) | (x[0] > b) | (x[1] < a) | (x[1] > b)  # noqa: E731
    sink = dm.Sink("discharged", region=lambda x: (x[2] < -drop) | ((x[2] < 0.0) & off(x)))
    averaging = dm.NonlocalAverage(radius, "cubic")
    solver = dm.Solver(
        grid, P, sand, bcs=[*walls, gate], gravity=(0.0, 0.0, -G), sinks=[sink], averaging=averaging,
        volumetric="nodal", quadrature="cell",  # the plane silo's options
        rebalance=1.05,  # under MPI: the slabs dealt anew as the inner ones empty faster
    )  # fmt: skip
    solver.partition_axes = (0,)  # slabs again: cuts across the flow would cost more
    return solver, gate


def discharged_mass(solver) -> float:
    """Mass that has passed the outlet plane z = 0: in free fall or in the sink [kg], all ranks."""
    P = solver.particles
    return solver.comm.allreduce(float(P.mass[P.x[:, 2] < 0.0].sum()) + solver.sinks["discharged"].mass)


class Monitor:
    """The discharged mass at each call; the XDMF output every ``xdmf_every``-th call."""

    def __init__(self, output, xdmf_every=5):
        self.output, self.xdmf_every, self.t, self.mass = output, xdmf_every, [], []

    def write(self, solver):
        if self.output is not None and len(self.t) % self.xdmf_every == 0:
            self.output.write(solver)
        self.t.append(solver.time)
        self.mass.append(discharged_mass(solver))


def run(h=0.01, radius=5e-3, wall_friction=20.0, width=0.2, height=0.3, outlet=0.1, ppc=4, t_end=0.25,
        t_settle=0.02, output=None, interval=0.005, progress=True, comm=MPI.COMM_WORLD):  # fmt: skip
    """Settle, open the outlet at t = 0 and discharge until ``t_end`` [s].

    Returns:
        dict: the discharged mass [kg] against time [s], the flow rate [kg/s] (fitted from
        t = 0.4 ``t_end`` on), the masses at the start and the end, the kinetic energy at the
        opening, the particles, steps, fixed-point counts and wall time.

    """
    for name, value in (("t_end", t_end), ("interval", interval)):
        if not value > 0.0:
            raise ValueError(f"{name} must be > 0 s, got {value!r}")
    solver, gate = build(h, radius, wall_friction, width, height, outlet, ppc, comm)
    m0 = solver.total_mass()
    t0 = time.perf_counter()
    kinetic = settle_and_open(solver, gate, t_settle, progress)  # damped, on the closed outlet
    # ## Discharge
    xdmf = dm.Output(output, solver.comm) if output is not None else None
    monitor = Monitor(xdmf)
    try:
        solver.run(t_end, output=monitor, output_interval=interval, progress=progress)
        if xdmf is not None:
            xdmf.write(solver)
    finally:
        if xdmf is not None:
            xdmf.close()
    t, mass = np.array(monitor.t), np.array(monitor.mass)
    fp = solver.fixed_point
    return {
        "h": h, "radius": radius, "t": t, "discharged": mass, "flow_rate": flow_rate(t, mass, 0.4 * t_end),
        "mass_initial": m0,
        "mass_final": solver.total_mass() + solver.comm.allreduce(solver.sinks["discharged"].mass),
        "kinetic_at_opening": kinetic, "particles": solver.num_particles(), "steps": solver.step_count,
        "iterations": fp["iterations"] / max(fp["steps"], 1), "unconverged": fp["unconverged"],
        "seconds": time.perf_counter() - t0, "solver": solver,
    }  # fmt: skip


def plot_section(solver, h: float, path: Path, width=0.2, outlet=0.1) -> None:
    """The particles within half a cell of the mid-plane y = width / 2, coloured by their speed."""
    P, comm = solver.particles, solver.comm
    near = np.abs(P.x[:, 1] - 0.5 * width) < 0.5 * h
    x = comm.gather(P.x[near], root=0)
    speed = comm.gather(np.linalg.norm(P.v[near], axis=1), root=0)
    if comm.rank != 0:
        return
    x, speed = 100 * np.concatenate(x), np.concatenate(speed)
    a, b = 50 * (width - outlet), 50 * (width + outlet)
    with figure(path, dpi=150, figsize=(4.6, 6)) as ax:
        sc = ax.scatter(x[:, 0], x[:, 2], c=speed, s=4, cmap="viridis", linewidths=0)
        ax.plot([0, 0, a], [32, 0, 0], "k-", [b, 100 * width, 100 * width], [0, 0, 32], "k-", lw=1.5)
        ax.set(
            xlabel="x [cm]", ylabel="z [cm]", title=f"section y = {50 * width:g} cm, t = {solver.time:.3f} s"
        )
        ax.set_aspect("equal")
        ax.figure.colorbar(sc, ax=ax, label="speed [m/s]")


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--h", type=float, default=0.01, help="cell size [m]")
    parser.add_argument("--radius", type=float, default=5e-3, help="non-local radius r [m]")
    parser.add_argument("--t-end", type=float, default=0.25, help="end of the discharge [s]")
    parser.add_argument("--output", type=Path, default=Path("results/silo3d"))
    args = parser.parse_args()
    r = run(h=args.h, radius=args.radius, t_end=args.t_end, output=args.output)
    solver = r.pop("solver")
    plot_section(solver, args.h, args.output / "section.png")
    if MPI.COMM_WORLD.rank == 0:
        lo, hi = (c * SAND["rho"] * math.sqrt(G) * 0.1**2.5 for c in BEVERLOO_C)
        print(
            f"h = {1e3 * args.h:g} mm, r = {1e3 * args.radius:g} mm: {r['particles']} particles, "
            f"{r['steps']} steps, {r['iterations']:.2f} iterations per step, {r['seconds']:.0f} s "
            f"on {MPI.COMM_WORLD.size} rank(s); flow rate {r['flow_rate']:.2f} kg/s "
            f"(Beverloo, square outlet: {lo:.2f}-{hi:.2f} kg/s); mass kept to "
            f"{abs(r['mass_final'] / r['mass_initial'] - 1):.1e}; results in {args.output}"
        )


if __name__ == "__main__":
    main()
