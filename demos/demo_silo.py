"""# Silo discharge: the paper's example (§4)

A plane silo, 20 cm wide and 30 cm tall, full of the paper's sand, empties through a 10 cm
outlet in the middle of its bottom. The walls and the bottom are rigid with Coulomb friction
(the paper does not give the wall friction; the default is a wall friction angle of 20°).
The background mesh goes on below the outlet, so that the material falls freely; what falls
below a catch line, or sideways under the bottom plate, leaves through a sink. The mass that
has passed the outlet plane (in free fall or in the sink) is the discharged mass.

Before the outlet opens the fill is at rest under gravity: geostatic stresses with the
at-rest ratio K0 = nu / (1 - nu), then a short damped settling phase on the closed outlet.
Time t = 0 is the opening.

Each run is stored in the results folder (JSON of the numbers, NPZ of the particles at the
map time), so studies are resumed rather than repeated:

    python demos/demo_silo.py                      # one run, h = 10 mm, r = 5 mm (~10 s)
    python demos/demo_silo.py --study meshes       # h = 10, 5, 2.5 mm, local and non-local; 1.25 non-local
    python demos/demo_silo.py --study radius       # r = 0, 2.5, 5, 10 mm on h = 10, 5 and 2.5 mm
    python demos/demo_silo.py --study weights      # cubic, constant, Gaussian at r = 5 mm
    python demos/demo_silo.py --study numerics     # the volumetric rate, the stress, the quadrature
    python demos/demo_silo.py --split 2 1          # cells halved across the flow only (--study split)
    python demos/demo_silo.py --study all --report docs/silo.md

Runs and studies also run on several MPI ranks (``mpirun -n 2 python demos/demo_silo.py
--h 0.0025``); the cells go to the ranks in vertical strips of equal fill, dealt anew by the
particles as the silo empties whenever a rank holds 5 % more than the mean.
"""

import argparse
import hashlib
import inspect
import itertools
import json
import math
import sys
import time
from pathlib import Path

import dolfin_mpm as dm  # import first: it loads DOLFINx's libraries

# isort: split
import numpy as np
from mpi4py import MPI
from scipy.spatial import cKDTree

from dolfin_mpm.averaging import LAWS, WEIGHTS
from dolfin_mpm.core.seeding import reference_points
from dolfin_mpm.explicit.options import Options
from dolfin_mpm.post.measure import bin_sums, fwhm, jump_width, rise_width
from dolfin_mpm.post.plotting import figure

SAND = {"E": 1e6, "nu": 0.3, "rho": 1500.0, "phi": 30.0, "gamma": 1e3, "N": 1.0}  # the paper's
G = 9.81


def check_geometry(width: float, height: float, outlet: float, h: float) -> None:
    """Raise ``ValueError`` naming the bad size before any work starts."""
    for name, value in (("width", width), ("height", height), ("outlet", outlet), ("h", h)):
        if not (math.isfinite(value) and value > 0.0):
            raise ValueError(f"{name} must be a positive length [m], got {value!r}")
    if outlet >= width:
        raise ValueError(f"outlet must be narrower than the silo (< width = {width} m), got {outlet}")
    if outlet < 4 * h - 1e-12:
        raise ValueError(
            f"h = {h} m cannot resolve the outlet: need at least 4 cells across it (h <= {outlet / 4} m)"
        )
    for name, length in (("width", width), ("height", height)):
        if abs(length / h - round(length / h)) > 1e-6:
            raise ValueError(f"h = {h} m must divide the {name} = {length} m into whole cells")


def check_split(split) -> tuple[int, int]:
    """``split`` as ``(kx, ky)``; ``ValueError`` unless it is two whole numbers >= 1."""
    if (
        not isinstance(split, (tuple, list))
        or len(split) != 2
        or not all(isinstance(k, (int, np.integer)) and not isinstance(k, bool) and k >= 1 for k in split)
    ):
        raise ValueError(f"split must be two whole numbers >= 1 (cuts across, up), got {split!r}")
    return int(split[0]), int(split[1])


def grid_lines(lo: float, hi: float, h: float, fine: float | None = None, zones=()) -> np.ndarray:
    """Mesh lines from ``lo`` to ``hi`` [m]: ``h`` apart, ``fine`` apart inside the ``zones``."""
    lines = [lo]
    while lines[-1] < hi - 1e-12:
        x = lines[-1]
        inside = fine is not None and any(a - 1e-12 <= x < b - 1e-12 for a, b in zones)
        nxt = min(x + (fine if inside else h), hi)
        for a, _ in zones if fine is not None else ():
            if x < a - 1e-12 < nxt:
                nxt = a  # a coarse step ends where a zone begins
        lines.append(nxt)
    return np.array(lines)


#: The solver's default Courant factor of the time step: the runs' unless a study sets another.
COURANT = Options().courant


def courant_of(run: dict) -> float:
    """The Courant factor of a stored run (:data:`COURANT` for runs stored before it was recorded)."""
    return run.get("courant") or COURANT


#: How the cells go to the ranks (:func:`build`).
PARTITIONS = ("rebalance", "strips", "dolfinx")


def build(h=0.01, radius=5e-3, weight="cubic", wall_friction=20.0, width=0.2, height=0.3, outlet=0.1, ppc=4,
          shift=0.0, edge_cell=None, edge_zone=0.04, split=(1, 1), comm=MPI.COMM_WORLD,
          partition="rebalance", rebalance=1.05, law="max", m=None, volumetric="nodal", stress="cell",
          quadrature="cell", courant=COURANT):  # fmt: skip
    """The silo on a mesh of ``h`` [m]: solver, sinks and the outlet's gate, before settling.

    The walls, the bottom plates and the gate are rigid walls as geometry
    (:class:`dolfin_mpm.RigidWall`): the outlet is ``outlet`` wide wherever the nodes fall.

    Args:
        h: cell size [m] (squares of two triangles); must divide the silo's width and height.
        radius: non-local radius r [m]; 0 for the local (viscoplastic) model.
        weight: the averaging weight.
        law: the non-local law, :data:`dolfin_mpm.averaging.LAWS`.
        m: the factor [-] of the over-non-local mix, > 1 (that law's alone; ``None`` for the others).
        volumetric, stress, quadrature: the solver's options against volumetric locking, for
            the stress a particle carries and for how a cell's force is integrated
            (:class:`dolfin_mpm.explicit.options.Options`). The nodal
            volumetric rate suits these squares of two triangles, not crossed squares
            (``docs/numerics.md``).
        wall_friction: wall and bottom friction angle [degrees], in [0, 90).
        width, height, outlet: silo sizes [m]; the outlet is centred in the bottom.
        ppc: particles per triangle.
        shift: the mesh shifted sideways by this fraction of a cell, in [0, 1): 0 puts the side
            walls and (for ``(width - outlet) / 2`` a multiple of ``h``) the outlet edges on nodes.
        edge_cell: mesh lines ``edge_cell`` [m] apart within ``edge_zone`` [m] of the outlet
            edges' x and of the bottom's y, ``h`` apart elsewhere; ``None``: ``h`` everywhere.
            The lines run through the whole mesh: squares of ``edge_cell`` only round the
            edges, columns of ``edge_cell x h`` cells up the silo's height and rows of
            ``h x edge_cell`` cells across its width.
        split: ``(kx, ky)``, whole numbers >= 1: every square of ``h`` cut into ``kx`` columns
            and ``ky`` rows, rectangles of ``h / kx x h / ky`` of two triangles each (the cells
            refined across or up the flow alone); ``(1, 1)``: squares. Not with ``edge_cell``.
        comm: the communicator the mesh is partitioned over.
        partition: on several ranks, :data:`PARTITIONS`: ``"strips"`` keeps vertical strips
            of equal fill; ``"rebalance"`` starts so and deals the strips anew by the
            particles whenever the largest rank holds more than ``rebalance`` times the mean
            (checked every 20 steps); ``"dolfinx"`` keeps DOLFINx's partition. Cuts across
            the flow cost more than an imbalance: particles cross them every step, and each
            crossing rebuilds the non-local halo and pair lists (``docs/parallel.md``).
        courant: the time step's Courant factor, in (0, 1] (default :data:`COURANT`).

    Returns:
        ``(solver, gate)``; the gate is a boundary condition in ``solver.bcs``.

    """
    check_geometry(width, height, outlet, h)
    if partition not in PARTITIONS:
        raise ValueError(f"partition must be one of {PARTITIONS}, got {partition!r}")
    if not 0.0 <= wall_friction < 90.0:
        raise ValueError(f"wall_friction must be in [0, 90) degrees, got {wall_friction}")
    if not 0.0 <= shift < 1.0:
        raise ValueError(f"shift must be in [0, 1) cells, got {shift}")
    if edge_cell is not None and not (0.0 < edge_cell <= h and shift == 0.0 and 0.0 < edge_zone < width):
        raise ValueError(
            f"edge_cell must be in (0, h = {h}] m on an unshifted mesh, with edge_zone in (0, width), "
            f"got edge_cell = {edge_cell!r}, edge_zone = {edge_zone!r}, shift = {shift}"
        )
    kx, ky = check_split(split)
    if edge_cell is not None and (kx, ky) != (1, 1):
        raise ValueError(f"split must be (1, 1) with edge_cell, got {tuple(split)}")
    x0, x1 = 0.5 * (width - outlet), 0.5 * (width + outlet)  # outlet edges
    drop = 0.5 * outlet  # free fall below the outlet down to the catch line
    rows_below = math.ceil(drop / h) + 1
    # On several ranks the cells go to them in vertical strips of equal fill: the flow is
    # symmetric about the axis, so on two ranks the halves keep equal shares as it empties (on
    # more, the inner strips empty faster, and a rebalance deals the strips anew).
    fill = lambda y: (y > 0.0) & (y < height)  # noqa: E731
    axes = (0,)
    corners = [
        (-shift * h, -rows_below * h),
        (width + (shift > 0) * (1 - shift) * h, height + h),
    ]  # spare row
    if edge_cell is None:
        cells = (kx * (round(width / h) + (shift > 0)), ky * (rows_below + round(height / h) + 1))
        share = (lambda c: fill(c[1])) if partition != "dolfinx" else None
        msh = dm.partition.create_rectangle(comm, corners, cells, weight=share, axes=axes)
    else:  # made in cell indices, then its lines are put where they belong
        zones = [(x0 - edge_zone, x0 + edge_zone), (x1 - edge_zone, x1 + edge_zone)]
        xs = grid_lines(corners[0][0], corners[1][0], h, edge_cell, zones)
        ys = grid_lines(corners[0][1], corners[1][1], h, edge_cell, [(-edge_zone, edge_zone)])
        at = lambda lines, i: np.interp(i, np.arange(len(lines)), lines)  # noqa: E731
        cells = (len(xs) - 1, len(ys) - 1)
        share = (lambda c: fill(at(ys, c[1]))) if partition != "dolfinx" else None
        msh = dm.partition.create_rectangle(comm, [(0.0, 0.0), cells], cells, weight=share, axes=axes)
        msh.geometry.x[:, 0], msh.geometry.x[:, 1] = (
            at(xs, msh.geometry.x[:, 0]),
            at(ys, msh.geometry.x[:, 1]),
        )
    grid = dm.Grid(msh)
    sand = dm.DruckerPragerViscoplastic(**SAND)
    inside = lambda x: (x[0] > 0.0) & (x[0] < width) & (x[1] > 0.0) & (x[1] < height)  # noqa: E731
    P = dm.seed(grid, sand, ppc=ppc, where=inside)
    # Geostatic stress: sigma_yy = -rho g depth, sigma_xx = sigma_zz = K0 sigma_yy.
    K0 = SAND["nu"] / (1.0 - SAND["nu"])
    P.sigma = dm.geostatic_stress(P.x, SAND["rho"], G, height, K0)

    mu = math.tan(math.radians(wall_friction))
    top = height + h
    walls = [  # each with the material on its left, going from its first point to its second
        dm.RigidWall([(0.0, top), (0.0, 0.0)], mu, "left wall"),
        dm.RigidWall([(0.0, 0.0), (x0, 0.0)], mu, "left plate"),
        dm.RigidWall([(x1, 0.0), (width, 0.0)], mu, "right plate"),
        dm.RigidWall([(width, 0.0), (width, top)], mu, "right wall"),
    ]
    gate = dm.RigidWall([(x0, 0.0), (x1, 0.0)], mu, "gate")
    sink = dm.Sink(
        "discharged", region=lambda x: (x[1] < -drop) | ((x[1] < 0.0) & ((x[0] < x0) | (x[0] > x1)))
    )
    averaging = dm.NonlocalAverage(radius, weight, law=dm.NonlocalLaw(law, m))  # r = 0: the local model
    solver = dm.Solver(
        grid, P, sand, bcs=[*walls, gate], gravity=(0.0, -G), sinks=[sink], averaging=averaging,
        volumetric=volumetric, stress=stress, quadrature=quadrature, courant=courant,
        rebalance=rebalance if partition == "rebalance" else np.inf,
    )  # fmt: skip
    solver.partition_axes = axes
    return solver, gate


def discharged_mass(solver) -> float:
    """Mass that has passed the outlet plane y = 0: in free fall or in the sink [kg/m], all ranks."""
    P = solver.particles
    return solver.comm.allreduce(float(P.mass[P.x[:, 1] < 0.0].sum()) + solver.sinks["discharged"].mass)


#: Heights [m] of the speed profiles across the bands: just above the outlet edge (the band
#: that rises from it along the stagnant zone), at the stagnant zone's mid-height (the same
#: band above the flow's acceleration into the opening: the zone over the plate reaches about
#: 4 cm up the wall) and at the silo's mid-height (the band between the material sliding down
#: the wall and the core).
BAND_HEIGHTS = {"edge": 0.01, "stagnant": 0.02, "wall": 0.15}


class Monitor:
    """What a run records at each call: the discharged mass and the ranks' particle imbalance
    (:meth:`~dolfin_mpm.Solver.imbalance`); every ``xdmf_every``-th call the
    XDMF output; from ``t_profile`` on, the profiles of e_vp_bar and v_y across the silo at
    the height ``y_c`` and of the speed at :data:`BAND_HEIGHTS`; from :data:`T_STEADY` on, the
    mass flux down through the outlet plane (strips of one cell, bins of half a cell) and the
    count of its points at p = 0, summed for time averages.
    """

    def __init__(self, output, h, width, y_c, t_profile, xdmf_every=5):
        self.output, self.xdmf_every, self.t, self.mass, self.imbalance = output, xdmf_every, [], [], []
        self.h, self.y_c, self.t_profile = h, y_c, t_profile
        self.edges = np.linspace(0.0, width, round(2 * width / h) + 1)
        self.centres = 0.5 * (self.edges[1:] + self.edges[:-1])  # of the bins [m]
        self.sums = np.zeros((3, len(self.edges) - 1))  # count, e_vp_bar, v_y
        self.band_sums = {name: np.zeros((2, len(self.edges) - 1)) for name in BAND_HEIGHTS}  # count, speed
        self.flux_sums, self.flux_records = np.zeros(len(self.edges) - 1), 0  # momentum down, records
        self.free_sums = np.zeros((2, len(self.edges) - 1))  # points, points at p = 0, in the same strip

    def write(self, solver):
        if self.output is not None and len(self.t) % self.xdmf_every == 0:
            self.output.write(solver)
        self.t.append(solver.time)
        self.mass.append(discharged_mass(solver))
        self.imbalance.append(solver.imbalance())
        P = solver.particles
        if solver.time >= self.t_profile - 1e-12:
            strip = np.abs(P.x[:, 1] - self.y_c) < 0.5 * self.h
            e_bar = P.state["eps_vp_rate_nonlocal"]
            self.sums += bin_sums(P.x[strip, 0], self.edges, e_bar[strip], P.v[strip, 1])
            speed = np.hypot(P.v[:, 0], P.v[:, 1])
            for name, y in BAND_HEIGHTS.items():
                strip = np.abs(P.x[:, 1] - y) < 0.5 * self.h
                self.band_sums[name] += bin_sums(P.x[strip, 0], self.edges, speed[strip])
        if solver.time >= T_STEADY - 1e-12:
            strip = np.abs(P.x[:, 1]) < 0.5 * self.h
            self.flux_sums += bin_sums(P.x[strip, 0], self.edges, -P.mass[strip] * P.v[strip, 1])[1]
            self.flux_records += 1
            free = np.einsum("pii->p", P.sigma[strip]) >= 0.0  # p = 0: the cone's apex, stress free
            self.free_sums += bin_sums(P.x[strip, 0], self.edges, free.astype(np.float64))

    def profiles(self, comm):
        """Bin centres [m] and the time-averaged e_vp_bar [1/s] and v_y [m/s] in each bin."""
        count, e, v = comm.allreduce(self.sums, MPI.SUM)
        seen = count > 0  # bins no particle visited are left out
        return self.centres[seen], e[seen] / count[seen], v[seen] / count[seen]

    def outlet_flux(self, comm):
        """Bin centres [m] and the time-averaged mass flux density down through y = 0 [kg/s/m²].

        The momentum ``-m v_y`` of the strip ``|y| < h / 2`` in each bin over the strip's area;
        its integral across the outlet is the flow rate.
        """
        total = comm.allreduce(self.flux_sums, MPI.SUM)
        return self.centres, total / max(self.flux_records, 1) / (self.h * np.diff(self.edges))

    def outlet_points(self, comm):
        """Bin centres [m], and the outlet strip's point records and those at p = 0 in each bin."""
        count, free = comm.allreduce(self.free_sums, MPI.SUM)
        return self.centres, count, free

    def band_profiles(self, comm) -> dict:
        """The time-averaged speed [m/s] across each band's height: ``{name: (x, speed)}``."""
        out = {}
        for name, sums in self.band_sums.items():
            count, speed = comm.allreduce(sums, MPI.SUM)
            seen = count > 0
            out[name] = (self.centres[seen], speed[seen] / count[seen])
        return out


def settle_and_open(solver, gate, t_settle: float, progress=True) -> float:
    """Damped settling on the closed outlet for ``t_settle`` [s], then the gate removed at t = 0.

    Returns the kinetic energy [J] (per metre in 2D) left at the opening.
    """
    solver.time = -math.ceil(t_settle / solver.dt) * solver.dt  # whole steps: the opening is at t = 0
    solver.damping = 0.2
    solver.run(0.0, progress=progress)
    solver.damping = 0.0
    solver.bcs = [bc for bc in solver.bcs if bc is not gate]
    return solver.energies()["kinetic"]


def run(h=0.01, radius=5e-3, weight="cubic", wall_friction=20.0, width=0.2, height=0.3, outlet=0.1,
        ppc=4, shift=0.0, edge_cell=None, split=(1, 1), t_end=0.25, t_settle=0.02, output=None,
        interval=0.005, progress=True, comm=MPI.COMM_WORLD, law="max", volumetric="nodal",
        stress="cell", quadrature="cell", partition="rebalance", m=None, courant=COURANT):  # fmt: skip
    """Settle the fill, open the outlet at t = 0 and discharge until ``t_end`` [s].

    Args:
        h, radius, weight, wall_friction, width, height, outlet, ppc, shift, edge_cell, split, comm,
            law, m, volumetric, stress, quadrature, partition, courant: as for :func:`build`.
        t_end: end of the discharge [s].
        t_settle: length of the damped settling phase before the opening [s].
        output: folder for the XDMF series (particles and grid), or ``None``.
        interval: time between records of the discharged mass [s]; XDMF every fifth.

    Returns:
        dict: the discharged mass against time, the flow rate, the particles at ``t_end``
        (positions and non-local rate e_vp_bar, of all ranks on every rank), the
        time-averaged profiles across the silo at
        the height ``y_c`` over the last fifth of the run, the time-averaged flux through the
        outlet plane (``profile_flux``, bin centres and flux density) and its ``outlet_shares``
        by distance from the edges (:func:`outlet_shares`) with the share of the points passing
        there stress free (:func:`outlet_stress_free`), and the run's statistics.

    """
    for name, value in (("t_end", t_end), ("interval", interval)):
        if not value > 0.0:
            raise ValueError(f"{name} must be > 0 s, got {value!r}")
    if not t_settle >= 0.0:
        raise ValueError(f"t_settle must be >= 0 s, got {t_settle!r}")
    solver, gate = build(
        h, radius, weight, wall_friction, width, height, outlet, ppc, shift, edge_cell, split=split,
        comm=comm, partition=partition, law=law, m=m,
        volumetric=volumetric, stress=stress, quadrature=quadrature, courant=courant,
    )  # fmt: skip
    m0 = solver.total_mass()
    t0 = time.perf_counter()
    kinetic_at_opening = settle_and_open(solver, gate, t_settle, progress)
    # ## Discharge
    xdmf = dm.Output(output, solver.comm) if output is not None else None
    y_c = 0.5 * outlet
    monitor = Monitor(xdmf, h, width, y_c, t_profile=t_end - 0.2 * t_end)
    try:
        solver.run(t_end, output=monitor, output_interval=interval, progress=progress)
        if xdmf is not None:
            xdmf.write(solver)  # the last state, if the fifth-record cadence missed it
    finally:
        if xdmf is not None:
            xdmf.close()
    elapsed = time.perf_counter() - t0
    P, comm = solver.particles, solver.comm
    t, mass = np.array(monitor.t), np.array(monitor.mass)
    x_c, e_c, v_c = monitor.profiles(comm)
    bands = monitor.band_profiles(comm)
    x_f, flux = monitor.outlet_flux(comm)
    fp = solver.fixed_point
    e_vp_bar = P.state["eps_vp_rate_nonlocal"]
    gather = lambda a: np.concatenate(comm.allgather(a))  # noqa: E731  (all ranks' particles)
    return {
        "h": h,
        "radius": radius,
        "weight": weight,
        "law": law,
        "m": m,
        "volumetric": volumetric,
        "stress": stress,
        "quadrature": quadrature,
        "courant": courant,
        "ppc": ppc,
        "wall_friction": wall_friction,
        "shift": shift,
        "edge_cell": edge_cell,
        "split": None if tuple(split) == (1, 1) else list(split),
        "t": t,
        "discharged": mass,
        "flow_rate": flow_rate(t, mass),
        "mass_initial": m0,
        "mass_final": solver.total_mass() + comm.allreduce(solver.sinks["discharged"].mass),
        "kinetic_at_opening": kinetic_at_opening,
        "profile_x": x_c,
        "profile_e_vp_bar": e_c,
        "profile_v_y": v_c,
        **{f"profile_speed_{name}": np.array(xs) for name, xs in bands.items()},  # (x, speed)
        "profile_flux": np.array([x_f, flux]),
        "outlet_shares": outlet_shares(x_f, flux, 0.5 * (width - outlet), 0.5 * (width + outlet)),
        "outlet_stress_free": outlet_stress_free(
            *monitor.outlet_points(comm), 0.5 * (width - outlet), 0.5 * (width + outlet)
        ),
        **velocity_bands(bands, width),
        "y_c": y_c,
        "x": gather(P.x[:, :2]),  # the particles at t_end
        "e_vp_bar": gather(e_vp_bar),
        "e_vp_bar_max": comm.allreduce(float(e_vp_bar[P.x[:, 1] > 0.0].max(initial=0.0)), MPI.MAX),
        "particles": solver.num_particles(),
        "steps": solver.step_count,
        "dt": solver.dt,
        "seconds": elapsed,
        "code": code_version(),
        "ranks": comm.size,
        "imbalance": max(monitor.imbalance),  # over the discharge's records
        "repartitions": solver.repartitions,
        "rebalance_seconds": solver.timings.get("rebalance", 0.0),
        "mean_iterations": fp["iterations"] / fp["steps"] if fp["steps"] else 1.0,
        "max_iterations": fp["max_iterations"],
        "unconverged": fp["unconverged"],
        "wall_stops": comm.allreduce(solver.state.wall_stops),
        **stagnant_zones(solver, width, outlet, h),
        **stress_noise(gather(P.x[:, :2]), gather(-np.einsum("pii->p", P.sigma) / 3.0), height),
    }


def stress_noise(x, p, height=0.3) -> dict:
    """How much of the pressure field is noise, from all particles ``x`` [m] and pressures ``p`` [Pa].

    Of the particles above the outlet (y > 0): ``roughness``, the median of ``|p - median p of
    its 6 nearest neighbours|`` over the mean pressure; ``stress_free``, the share at ``p = 0``
    of those above y = 5 cm and more than 2 cm below the free surface (the top particle of
    their 1 cm column); ``p_max_over_rho_g_H``, the largest pressure over ``rho g H``.
    """
    above = x[:, 1] > 0.0
    x, p = x[above], p[above]
    _, near = cKDTree(x).query(x, k=7)
    roughness = np.median(np.abs(p - np.median(p[near[:, 1:]], axis=1))) / np.mean(np.abs(p))
    column = np.floor(x[:, 0] / 0.01).astype(int)
    top = np.zeros(column.max() + 1)
    np.maximum.at(top, column, x[:, 1])
    deep = (x[:, 1] > 0.05) & (x[:, 1] < top[column] - 0.02)
    return {
        "roughness": float(roughness),
        "stress_free": float(np.mean(p[deep] <= 0.0)),
        "p_max_over_rho_g_H": float(p.max() / (SAND["rho"] * G * height)),
    }


def stagnant_zones(solver, width=0.2, outlet=0.1, h=0.01) -> dict:
    """What the bottom friction holds at rest, from the particles now (all ranks).

    ``corner_speed``: median speed [m/s] in the bottom corners (3 cm squares), where a frictional
    bottom holds stagnant zones; ``base_slip``: median horizontal speed [m/s] of the layer one
    cell deep over the bottom plates; ``outlet_angle``: mean angle [degrees] from the vertical of
    the velocity of the material crossing the outlet plane (within one cell of it).
    """
    P, comm = solver.particles, solver.comm
    x, v = P.x[:, :2], P.v
    gather = lambda a: np.concatenate(comm.allgather(a))  # noqa: E731
    plates = (x[:, 0] < 0.5 * (width - outlet)) | (x[:, 0] > 0.5 * (width + outlet))
    corner = (x[:, 1] > 0.0) & (x[:, 1] < 0.03) & ((x[:, 0] < 0.03) | (x[:, 0] > width - 0.03))
    base = (x[:, 1] > 0.0) & (x[:, 1] < h) & plates
    crossing = (np.abs(x[:, 1]) < h) & ~plates
    angle = np.degrees(np.arctan2(np.abs(v[crossing, 0]), np.maximum(-v[crossing, 1], 1e-12)))
    median = lambda a: float(np.median(a)) if a.size else float("nan")  # noqa: E731
    return {
        "corner_speed": median(gather(np.hypot(v[corner, 0], v[corner, 1]))),
        "base_slip": median(gather(np.abs(v[base, 0]))),
        "outlet_angle": float(np.mean(gather(angle))) if comm.allreduce(angle.size) else float("nan"),
    }


def velocity_bands(bands: dict, width=0.2) -> dict:
    """Band widths [m] from the time-averaged speed across the left half at :data:`BAND_HEIGHTS`.

    ``edge_band_width``, ``stagnant_band_width`` and ``wall_band_width``: the 10-90 % width of
    the steepest jump of the speed (:func:`dolfin_mpm.post.measure.jump_width`) across the left
    half at the height of each, taken horizontally (the edge and stagnant bands cross that line
    obliquely, the same on every mesh); ``*_band_x``: where the jump is [m].
    """
    out = {}
    for name, (x, speed) in bands.items():
        left = x < 0.5 * width
        w, at = jump_width(x[left], speed[left])
        out[f"{name}_band_width"], out[f"{name}_band_x"] = w, at
    return out


def band_widths(result, width=0.2, y_band=0.15, y_edge=0.01) -> dict:
    """Widths [m] across the left half of the silo, from the particles and profiles of a run.

    ``band`` and ``edge``: full width at half maximum of the e_vp_bar peak at t_end across the
    left half at the heights ``y_band`` (mid-height: the band between the material resting on
    the wall and the flowing core) and ``y_edge`` (just above the bottom: the band that rises
    from the outlet edge), from the particles of a 1 cm strip in bins of half a cell;
    ``edge_x``: where that peak is. ``channel``: the distance over which the time-averaged
    downward velocity at ``y_c`` rises from 10 % to 90 % from the wall to the axis.
    """
    xv, v = result["profile_x"], result["profile_v_y"]
    left = xv < 0.5 * width
    band, _ = _section_peak(result, width, y_band)
    edge, edge_x = _section_peak(result, width, y_edge)
    return {"band": band, "edge": edge, "edge_x": edge_x, "channel": rise_width(xv[left], -v[left])}


def _section_peak(result, width, y) -> tuple[float, float]:
    """FWHM [m] and place [m] of the e_vp_bar peak at t_end across the left half at height ``y``."""
    x, e = result["x"], result["e_vp_bar"]
    strip = (np.abs(x[:, 1] - y) < 0.005) & (x[:, 0] < 0.5 * width)
    edges = np.arange(0.0, 0.5 * width + 1e-9, 0.5 * result["h"])
    count, total = bin_sums(x[strip, 0], edges, e[strip])
    mean = total[count > 0] / count[count > 0]
    centres = 0.5 * (edges[1:] + edges[:-1])[count > 0]
    return fwhm(centres, mean), float(centres[np.argmax(mean)])


#: From this time [s] on the discharge is steady: the flow rate and the outlet's flux are taken over it.
T_STEADY = 0.1
#: Distances [m] from the nearer outlet edge that split the outlet for :func:`outlet_shares`.
OUTLET_BANDS = (0.0, 0.01, 0.02, 0.03, np.inf)


def outlet_shares(x, flux, x0, x1) -> list[float]:
    """The flow rate [kg/s/m] through each band of the outlet ``[x0, x1]`` [m] by distance from its
    nearer edge (:data:`OUTLET_BANDS`), from the flux density ``flux`` [kg/s/m²] at the bin
    centres ``x`` [m] (equal bins): where across the opening the material passes.
    """
    dx = x[1] - x[0]
    return [float(flux[band].sum() * dx) for band in outlet_bands(x, x0, x1)]


def outlet_stress_free(x, count, free, x0, x1) -> list[float | None]:
    """The share of the outlet strip's points at p = 0 (stress free) in each band of the outlet
    ``[x0, x1]`` [m] by distance from its nearer edge (:data:`OUTLET_BANDS`), from the bins'
    point records ``count`` and stress-free records ``free`` at their centres ``x`` [m]; ``None``
    where no point passed.
    """
    shares: list[float | None] = []
    for band in outlet_bands(x, x0, x1):
        n = count[band].sum()
        shares.append(float(free[band].sum() / n) if n > 0 else None)
    return shares


def outlet_bands(x, x0, x1) -> list[np.ndarray]:
    """Masks of the points ``x`` [m] in each band of the outlet ``[x0, x1]`` [m] by distance from
    its nearer edge (:data:`OUTLET_BANDS`); those over the plates are in none."""
    d = np.minimum(x - x0, x1 - x)  # < 0: over a plate
    return [(d >= lo) & (d < hi) for lo, hi in itertools.pairwise(OUTLET_BANDS)]


def outlet_band_names() -> list[str]:
    """The names of the bands of :data:`OUTLET_BANDS`: ``"0-1 cm"``, ..., ``"beyond 3 cm"``."""
    bands = [f"{1e2 * lo:g}-{1e2 * hi:g} cm" for lo, hi in itertools.pairwise(OUTLET_BANDS[:-1])]
    return [*bands, f"beyond {1e2 * OUTLET_BANDS[-2]:g} cm"]


def flow_rate(t, mass, t_from=T_STEADY):
    """Steady mass flow rate [kg/s per metre]: slope of the discharged mass after ``t_from``."""
    late = t >= t_from
    if late.sum() < 3:
        return float("nan")
    return float(np.polyfit(t[late], mass[late], 1)[0])


def beverloo(outlet=0.1, rho=SAND["rho"], C=(0.58, 1.5)):
    """2D Beverloo law W = C rho sqrt(g) D^(3/2) (continuum, d -> 0) [kg/s per metre]."""
    return tuple(c * rho * math.sqrt(G) * outlet**1.5 for c in C)


# ## Studies: each run is stored once and reused

H_STUDY = 0.005  # the mesh of the radius and weight studies [m]
MESHES = (0.01, 0.005, 0.0025)  # the meshes of the mesh studies [m]
STUDIES = {
    "meshes": [
        *(dict(h=h, radius=r) for r in (0.0, 5e-3) for h in (0.01, 0.005, 0.0025)),
        dict(h=0.00125, radius=5e-3),  # 70 min on two ranks
    ],
    "radius": [dict(h=h, radius=r) for h in MESHES for r in (0.0, 2.5e-3, 5e-3, 10e-3)],
    "weights": [dict(h=H_STUDY, radius=5e-3, weight=w) for w in ("cubic", "constant", "gaussian")],
    "friction": [dict(h=0.01, wall_friction=a) for a in (0.0, 10.0, 20.0, 30.0)],
    "shift": [dict(h=h, radius=0.0, shift=s) for h in (0.01, 0.005) for s in (0.0, 0.5)],
    "edges": [dict(h=0.01, radius=0.0, edge_cell=e) for e in (None, 0.005, 0.0025)],
    # The cells refined across the flow or up it alone (the uniform meshes: the meshes study).
    "split": [
        *(dict(h=0.01, radius=0.0, split=k) for k in ((2, 1), (4, 1), (8, 1), (1, 2), (1, 4))),
        *(dict(h=0.01, radius=5e-3, split=k) for k in ((2, 1), (4, 1), (8, 1), (1, 2))),
        *(dict(h=0.005, radius=5e-3, split=k) for k in ((2, 1), (1, 2))),
    ],
    # The options against locking and stress noise, each on and off (the last: the default).
    "numerics": [
        dict(h=h, volumetric=v, stress=s, quadrature=q)
        for h in (0.01, 0.005)
        for v, s, q in (
            ("cell", "particle", "particle"),
            ("cell", "cell", "particle"),
            ("nodal", "particle", "particle"),
            ("nodal", "cell", "particle"),
            ("nodal", "cell", "cell"),
        )
    ],
    # The time step: the Courant factor halved twice from the default (once on h = 2.5 mm).
    "timestep": [
        *(
            dict(h=h, radius=r, courant=c)
            for h in (0.01, 0.005)
            for r in (0.0, 5e-3)
            for c in (COURANT, COURANT / 2, COURANT / 4)
        ),
        *(dict(h=0.0025, radius=5e-3, courant=c) for c in (COURANT, COURANT / 2)),
    ],
    # The points per triangle on fixed meshes: h = 10 mm with 16 has the points of h = 5 mm with 4.
    "points": [
        *(dict(h=h, radius=r, ppc=p) for h in (0.01, 0.005) for r in (0.0, 5e-3) for p in (4, 9, 16)),
        *(dict(h=0.01, radius=5e-3, ppc=p) for p in (36, 64)),
        dict(h=0.01, radius=0.0, ppc=64),
        *(dict(h=0.0025, radius=5e-3, ppc=p) for p in (4, 9)),  # 9: 16 min on two ranks
        *(dict(h=0.005, radius=10e-3, ppc=p) for p in (4, 9)),
        # r = 2.5 mm with about 57 points within r, as 9 per triangle give r = 5 mm on h = 5 mm.
        *(dict(h=0.005, radius=2.5e-3, ppc=p) for p in (4, 36)),
        *(dict(h=0.0025, radius=2.5e-3, ppc=p) for p in (4, 9)),
    ],
    # The non-local laws with the positive-definite weight beside the local model.
    "laws": [
        *(dict(h=h, radius=0.0) for h in MESHES),
        # Not the over-non-local mix: sure of one solution only below m = 1.01-1.05 (numerics.md).
        *(
            dict(h=h, radius=5e-3, weight="wendland", law=law)
            for law in ("max", "paper", "overstress")
            for h in MESHES
        ),
        *(
            dict(h=h, radius=10e-3, weight="wendland", law=law)
            for law in ("paper", "overstress")
            for h in MESHES
        ),
    ],
}
ARRAYS = (
    "t", "discharged", "x", "e_vp_bar", "profile_x", "profile_e_vp_bar", "profile_v_y",
    *(f"profile_speed_{name}" for name in BAND_HEIGHTS), "profile_flux",
)  # fmt: skip


def run_key(
    h=0.01, radius=5e-3, weight="cubic", wall_friction=20.0, shift=0.0, edge_cell=None, split=(1, 1),
    law="max", m=None, volumetric="nodal", stress="cell", quadrature="cell", courant=COURANT, ppc=4,
) -> str:  # fmt: skip
    """Name of a stored run: the study parameters; every other setting is :func:`run`'s default."""
    shifted = f"_shift{shift:g}" if shift else ""
    edges = f"_edges{1e3 * edge_cell:g}mm" if edge_cell else ""
    edges += f"_split{split[0]}x{split[1]}" if split is not None and tuple(split) != (1, 1) else ""
    rule = f"_{law}" + (f"_m{m:g}" if m is not None else "") if law != "max" and radius > 0 else ""
    numerics = (
        (f"_{volumetric}-volumetric" if volumetric != "nodal" else "")
        + (f"_{stress}-stress" if stress != "cell" else "")
        + (f"_{quadrature}-quadrature" if quadrature != "cell" else "")
    )
    step = f"_courant{courant:g}" if courant != COURANT else ""
    points = f"_ppc{ppc}" if ppc != 4 else ""
    rest = f"{shifted}{edges}{rule}{numerics}{step}{points}"
    return f"h{1e3 * h:g}mm_r{1e3 * radius:g}mm_{weight}_wall{wall_friction:g}{rest}"


#: The parameters that name a stored run.
RUN_PARAMS = tuple(inspect.signature(run_key).parameters)


def stored_run(folder: Path, **params) -> dict | None:
    """The stored result of the run with ``params`` in ``folder/runs``, ``None`` if there is none."""
    runs, key = Path(folder) / "runs", run_key(**params)
    if not (runs / f"{key}.json").exists():
        return None
    result = json.loads((runs / f"{key}.json").read_text())
    if "stress" not in result:  # stored before these options: another solver's numerics
        return None
    if result.get("quadrature", "particle") != params.get("quadrature", "cell"):  # an older default's
        return None
    with np.load(runs / f"{key}.npz") as arrays:
        result.update({name: arrays[name] for name in ARRAYS if name in arrays})  # older runs: fewer
    return result


def code_version() -> str:
    """A fingerprint of the code a run is made with: the package's sources and this demo's."""
    digest = hashlib.sha256()
    package = Path(dm.__file__).parent
    for path in sorted([*package.rglob("*.py"), *package.rglob("*.c"), Path(__file__)]):
        digest.update(path.read_bytes())
    return digest.hexdigest()[:12]


def cached_run(folder: Path, xdmf=False, progress=True, force=False, **params) -> dict:
    """The result of :func:`run` with ``params``, from ``folder/runs`` or computed and stored there.

    A stored run made by other code (:func:`code_version`) is reused, and said so; ``force``
    runs it again. The numbers go to ``<key>.json``, the arrays to ``<key>.npz``, each written
    (by rank 0) under a temporary name and then renamed, so an interrupted study never leaves
    half a result.
    """
    stored = None if force else stored_run(folder, **params)
    if MPI.COMM_WORLD.bcast(stored is not None, root=0):
        made_by = stored.get("code") if stored is not None else None
        if MPI.COMM_WORLD.rank == 0 and made_by != code_version():
            made_by = made_by or "not recorded"
            print(f"{run_key(**params)}: the stored run is reused (its code {made_by}, now {code_version()}; "
                  "--force runs it again)", flush=True)  # fmt: skip
        return stored
    runs, key = Path(folder) / "runs", run_key(**params)
    runs.mkdir(parents=True, exist_ok=True)
    result = run(**params, output=runs / key if xdmf else None, progress=progress)
    if MPI.COMM_WORLD.rank > 0:
        return result
    tmp = runs / f"{key}.tmp.npz"
    np.savez_compressed(tmp, **{name: result[name] for name in ARRAYS})
    tmp.rename(runs / f"{key}.npz")
    tmp = runs / f"{key}.json.tmp"
    tmp.write_text(json.dumps({k: v for k, v in result.items() if k not in ARRAYS}, indent=1))
    tmp.rename(runs / f"{key}.json")
    return result


# ## Figures and the report


def plot_maps(results, path: Path, width=0.2, outlet=0.1) -> None:
    """The paper's Fig. 1: e_vp_bar over the particles at t_end, one panel per run."""
    size = (3.4 * len(results) + 0.8, 5.2)
    with figure(path, dpi=130, tight=False, ncols=len(results), figsize=size, sharey=True) as axes:
        axes = np.atleast_1d(axes)
        fig = axes[0].figure
        vmax = max(np.percentile(r["e_vp_bar"][r["x"][:, 1] > 0.0], 99.5) for r in results)
        x0, x1 = 0.5 * (width - outlet), 0.5 * (width + outlet)
        for ax, r in zip(axes, results):
            x = 100 * r["x"]
            dot = (0.35 * r["h"] * 100 * 72 * 3.0 / (100 * width)) ** 2  # about the particle spacing
            sc = ax.scatter(
                x[:, 0], x[:, 1], c=r["e_vp_bar"], s=dot, cmap="jet", vmin=0.0, vmax=vmax, linewidths=0
            )
            ax.plot(
                [0, 0, 100 * x0],
                [30, 0, 0],
                "k-",
                [100 * x1, 100 * width, 100 * width],
                [0, 0, 30],
                "k-",
                lw=1.5,
            )
            ax.set_title(f"h = {1e3 * r['h']:g} mm, r = {1e3 * r['radius']:g} mm", fontsize=10)
            ax.set_xlabel("x [cm]")
            ax.set_aspect("equal")
            ax.set_xlim(-1, 100 * width + 1)
            ax.set_ylim(-5, 30.5)
        axes[0].set_ylabel("y [cm]")
        fig.colorbar(sc, ax=axes.tolist(), shrink=0.8, label="e_vp_bar [1/s]")
        # The full name needs the width of several panels.
        what = "non-local equivalent viscoplastic strain rate" if len(results) > 1 else "e_vp_bar"
        fig.suptitle(f"{what} at t = {results[0]['t'][-1]:.2f} s")


def plot_discharge(results, path: Path, outlet=0.1) -> None:
    """Discharged mass against time, with the Beverloo band."""
    with figure(path, dpi=130, figsize=(6, 4.2)) as ax:
        t = np.linspace(0.0, max(r["t"][-1] for r in results), 50)
        lo, hi = beverloo(outlet)
        ax.fill_between(
            t, lo * t, hi * t, color="0.85", label=f"Beverloo, C = 0.58-1.5 ({lo:.0f}-{hi:.0f} kg/s/m)"
        )
        for r in results:
            label = f"h = {1e3 * r['h']:g} mm, r = {1e3 * r['radius']:g} mm: {r['flow_rate']:.0f} kg/s/m"
            ax.plot(r["t"], r["discharged"], label=label)
        ax.set_xlabel("time since the opening [s]")
        ax.set_ylabel("discharged mass [kg/m]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)


def plot_radius(results, path: Path) -> None:
    """Flow rate against the non-local radius, a line for each mesh."""
    with figure(path, dpi=130, figsize=(5, 3.6)) as ax:
        for h in sorted({r["h"] for r in results}, reverse=True):
            rs = sorted((r for r in results if r["h"] == h), key=lambda r: r["radius"])
            ax.plot(
                [1e3 * r["radius"] for r in rs],
                [r["flow_rate"] for r in rs],
                "o-",
                label=f"h = {1e3 * h:g} mm",
            )
        ax.set_xlabel("non-local radius r [mm] (0: local)")
        ax.set_ylabel("flow rate [kg/s/m]")
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)


def plot_profiles(results, path: Path) -> None:
    """Time-averaged e_vp_bar and downward velocity across the silo at the height y_c."""
    with figure(path, dpi=130, ncols=2, figsize=(11, 4), sharex=True) as axes:
        for r in results:
            style = "-" if r["radius"] > 0 else "--"
            label = f"h = {1e3 * r['h']:g} mm, r = {1e3 * r['radius']:g} mm"
            axes[0].plot(100 * r["profile_x"], r["profile_e_vp_bar"], style, label=label)
            axes[1].plot(100 * r["profile_x"], -r["profile_v_y"], style, label=label)
        axes[0].set_ylabel("e_vp_bar [1/s]")
        axes[1].set_ylabel("downward velocity [m/s]")
        for ax in axes:
            ax.set_xlabel(f"x [cm] at y = {100 * results[0]['y_c']:g} cm")
            ax.grid(alpha=0.3)
        axes[1].legend(fontsize=7)


def friction_lines(runs) -> list[str]:
    """What the friction study shows, as Markdown lines, from its runs."""
    by = {r["wall_friction"]: r for r in runs}
    if not {0.0, 20.0, 30.0} <= set(by):
        return []
    f0, f20, f30 = by[0.0], by[20.0], by[30.0]
    return [
        f"The flow rate rises with the wall friction, {f0['flow_rate']:.0f} kg/s/m at 0° to "
        f"{f20['flow_rate']:.0f} at 20° and {f30['flow_rate']:.0f} at 30°, with the walls as geometry as "
        "it did with walls of nodes: the outlet's edge nodes are not its cause. The bottom's friction "
        "sets the flow pattern. A frictionless bottom cannot hold stagnant zones: the corners flow "
        f"(median speed {f0['corner_speed']:.3f} m/s against {f20['corner_speed']:.3f} m/s at 20°), the "
        f"base layer slides to the outlet ({f0['base_slip']:.3f} against {f20['base_slip']:.4f} m/s) and "
        f"the material crosses the outlet at {f0['outlet_angle']:.0f}° from the vertical instead of "
        f"{f20['outlet_angle']:.0f}°, as into a flat hopper of half-angle 90°. With friction the stagnant "
        "zones form a steeper hopper of their own, and steeper hoppers discharge faster (Nedderman, "
        "*Statics and kinematics of granular materials*, 1992, ch. 10; the flow pattern's dependence on "
        "wall friction and hopper angle: González-Montellano, Ayuga & Ooi, Granular Matter 13, 2011). "
        "Beverloo's independence of wall friction holds once the stagnant zones exist: from 20° to 30° "
        f"the flow rate changes by {f30['flow_rate'] / f20['flow_rate'] - 1:+.3f}, within this mesh's "
        "error (see the meshes study). A frictionless bottom is an idealisation no experiment has."
    ]


def mesh_fit(runs, label) -> list[str]:
    """Lines of Markdown: ``Q = A (D - c h)^(3/2)`` fitted to the runs of three or more meshes.

    ``c`` is the width the outlet loses per cell; ``Q(h -> 0) = A D^(3/2)`` is the extrapolation.
    """
    if len(runs) < 3:
        return []
    h, Q = np.array([r["h"] for r in runs]), np.array([r["flow_rate"] for r in runs])
    slope, intercept = np.polyfit(h, Q ** (2 / 3), 1)  # Q^(2/3) = A^(2/3) (D - c h)
    c, Q0 = -slope * 0.1 / intercept, intercept**1.5
    misfit = np.max(np.abs((intercept + slope * h) ** 1.5 / Q - 1))
    return [
        f"- {label}: fit Q = A (D - c h)^(3/2) over h = "
        + " / ".join(f"{1e3 * x:g}" for x in h)
        + f" mm: c = {c:.2f}, Q(h -> 0) = {Q0:.1f} kg/s/m (largest misfit {100 * misfit:.1f} %); "
        f"Q(5 mm) / Q(10 mm) - 1 = {_ratio(runs, 0.005, 0.01):+.3f}"
    ]


def _ratio(runs, h_fine, h_coarse) -> float:
    q = {round(1e4 * r["h"]): r["flow_rate"] for r in runs}
    return q.get(round(1e4 * h_fine), np.nan) / q.get(round(1e4 * h_coarse), np.nan) - 1


def edge_lines(runs, uniform) -> list[str]:
    """Lines of Markdown: the flow rate with the cells refined at the outlet edges only."""
    local = {round(1e5 * r["h"]): r["flow_rate"] for r in uniform if r["radius"] == 0}
    out, changes = [], []
    for r in sorted(runs, key=lambda r: -(r.get("edge_cell") or r["h"])):
        e = r.get("edge_cell")
        if e:
            same = local.get(round(1e5 * e))
            than = ""
            if same:
                changes.append((e, r["flow_rate"] / same - 1))
                than = f" (uniform h = {1e3 * e:g} mm: {same:.1f}, {changes[-1][1]:+.1%})"
            out.append(
                f"- h = {1e3 * r['h']:g} mm, lines {1e3 * e:g} mm apart within 4 cm of the outlet edges "
                f"and the bottom: {r['flow_rate']:.1f} kg/s/m{than}, {r['particles']} particles"
            )
    if not changes:
        return out
    near = [f"{1e3 * e:g} mm" for e, d in changes if abs(d) <= 0.03]
    far = [f"{1e3 * e:g} mm ({d:+.1%})" for e, d in changes if abs(d) > 0.03]
    coarse = ", ".join(sorted({f"{1e3 * r['h']:g} mm" for r in runs if r.get("edge_cell")}))
    said = (
        f"- Refined along lines through the outlet edges, the {coarse} mesh gives the flow rate of "
        f"the uniform mesh of its edge cells to 3 % with edge cells of {', '.join(near) or 'no size'}"
    )
    if far:
        said += f", not with {', '.join(far)}: see docs/numerics.md."
    return [*out, said + ("" if far else ": the cells at the outlet edges set the flow rate.")]


def noise_lines(runs) -> list[str]:
    """The numerics study: the stress noise and the flow rate of each option pair."""
    return [
        "| h [mm] | volumetric | stress | quadrature | roughness | stress free | max p / (rho g H) "
        "| flow rate [kg/s/m] |",
        "|---|---|---|---|---|---|---|---|",
        *(
            f"| {1e3 * r['h']:g} | {r['volumetric']} | {r['stress']} | {r.get('quadrature', 'particle')} "
            f"| {r['roughness']:.3f} "
            f"| {r['stress_free']:.3f} | {r['p_max_over_rho_g_H']:.2f} | {r['flow_rate']:.1f} |"
            for r in runs
        ),
        "",
        "roughness: median over the particles above the outlet of |p - the median p of the 6 "
        "nearest neighbours|, over the mean p; stress free: the share at p = 0 of the particles "
        "above y = 5 cm and more than 2 cm below the free surface; both at t = 0.25 s, r = 5 mm. "
        "Goals: roughness and stress free <= 0.05, max p <= 1.5 rho g H.",
    ]


def shift_lines(runs) -> list[str]:
    """Lines of Markdown: the flow rate of each mesh with and without the half-cell shift."""
    q = {(round(1e4 * r["h"]), r.get("shift", 0.0)): r["flow_rate"] for r in runs}
    out = []
    for h in sorted({k[0] for k in q}, reverse=True):
        if (h, 0.0) in q and (h, 0.5) in q:
            out.append(
                f"- h = {h / 10:g} mm: {q[h, 0.0]:.1f} kg/s/m with the outlet edges and side walls on "
                f"nodes, {q[h, 0.5]:.1f} kg/s/m shifted by half a cell ({q[h, 0.5] / q[h, 0.0] - 1:+.3f})"
            )
    return out


def ranks(r) -> str:
    """`` on N ranks`` for a run on N > 1 MPI ranks, else nothing."""
    n = r.get("ranks", 1)
    return f" on {n} ranks" if n > 1 else ""


def _spread(values) -> str:
    """``largest / smallest - 1`` in per cent; ``-`` where a run lacks the value (NaN)."""
    if any(math.isnan(v) for v in values):
        return "-"
    return f"{100 * (max(values) / min(values) - 1):.0f} %"


def _mm(run: dict, name: str) -> str:
    """The run's width ``name`` [m] in mm to 0.1; ``-`` where it was stored before it was measured."""
    width = run.get(name, math.nan)
    return "-" if math.isnan(width) else f"{1e3 * width:.1f}"


def _change(before: float, after: float) -> str:
    """``after / before - 1`` in per cent, signed; ``-`` where a run lacks the value (NaN)."""
    if math.isnan(before) or math.isnan(after):
        return "-"
    return f"{100.0 * (after / before - 1.0):+.1f} %"


def stored_variants(folder: Path, params: dict, name: str, values) -> list[dict]:
    """The stored runs that ``params`` names with only ``name`` changed, to each of ``values`` in turn."""
    found = [stored_run(folder, **{**params, name: value}) for value in values]
    return [r for r in found if r is not None]


def mesh_runs(folder: Path, params: dict) -> list[dict]:
    """The stored runs of the model of ``params`` on h halved or doubled up to three times, coarsest first."""
    return stored_variants(folder, params, "h", [params["h"] * 2.0**k for k in range(3, -4, -1)])


def points_within(h: float, radius: float, ppc: int) -> float:
    """Points within ``radius`` [m] of a point, ``2 pi ppc (r / h)^2`` (two triangles to a square h)."""
    return 2.0 * math.pi * ppc * (radius / h) ** 2


#: The points per triangle a run is compared with (squares: see ``dm.seed``).
PPC = (1, 4, 9, 16, 36, 64)


def points_runs(folder: Path, params: dict) -> list[dict]:
    """The stored runs of the model and mesh of ``params``: its own count and :data:`PPC`, fewest first."""
    return stored_variants(folder, params, "ppc", sorted({*PPC, params.get("ppc", 4)}))


def points_advice(runs, ppc: int) -> list[str]:
    """The flow rate of one model and mesh against its points per triangle, or what to run to see it.

    ``runs``: :func:`points_runs`; ``ppc``: the run's own count. Each change is from the next
    smaller count stored.
    """
    if len(runs) < 2:
        more = PPC[PPC.index(ppc) + 1] if ppc in PPC[:-1] else (math.isqrt(ppc) + 1) ** 2
        return [
            f"  {ppc} points per triangle: the points are a discretisation of their own (on h = 10 and 5 mm "
            f"4 per triangle left the flow rate 1.5-3 % below 9, docs/numerics.md); run again with "
            f"--ppc {more} to see how far this one moves"
        ]
    change = lambda b, r: "" if b is None else f" ({_change(b['flow_rate'], r['flow_rate'])})"  # noqa: E731
    rates = ", ".join(
        f"{r.get('ppc', 4)}: {r['flow_rate']:.1f}{change(b, r)}" for b, r in zip([None, *runs], runs)
    )
    return [f"  this model and mesh with other points per triangle: flow rate [kg/s/m] {rates}"]


def mesh_lines(runs) -> list[str]:
    """What a single run is worth: the same model on the other meshes stored, and the changes.

    ``runs``: :func:`mesh_runs`; each number's change is from the next coarser mesh stored (one
    halving of h, or more where a mesh is missing). With one mesh alone, what to run to see
    whether it converges.
    """
    names = ("flow_rate", "edge_band_width", "stagnant_band_width", "wall_band_width")
    value = lambda r, name: r.get(name, math.nan)  # noqa: E731  (older runs lack the stagnant band)
    lines = [
        "  this model on the meshes stored: h [mm]: flow rate [kg/s/m], edge / stagnant / wall band [mm]"
        " (the change of each from the next coarser mesh stored)"
    ]
    for before, r in zip([None, *runs], runs):
        bands = " / ".join(_mm(r, name) for name in names[1:])
        change = ""
        if before is not None:
            change = "   (" + ", ".join(_change(value(before, n), value(r, n)) for n in names) + ")"
        lines.append(f"    {1e3 * r['h']:g}: {r['flow_rate']:.1f}, {bands}{change}")
    if len(runs) == 1:
        h = runs[0]["h"]
        lines.append(
            f"  one mesh alone: these numbers are the mesh's until a finer one is compared (run again with"
            f" --h {h / 2:g} and the same options); the published mesh study is in docs/convergence.md"
        )
    return lines


def code_line(runs) -> str:
    """Which code made the stored runs (:func:`code_version`), against the code now."""
    made = {}
    for r in runs:
        made.setdefault(r.get("code", "not recorded"), set()).add(
            run_key(**{k: r[k] for k in RUN_PARAMS if k in r})
        )
    now = code_version()
    parts = [
        f"{len(keys)} by {code}{' (this code)' if code == now else ''}" for code, keys in sorted(made.items())
    ]
    return f"Code of the stored runs: {', '.join(parts)}; this code is {now}."


def report(folder: Path, path: Path) -> str:
    """Tables and figures of the stored runs of each study as Markdown in ``path``.

    Runs not stored yet are listed as missing; nothing is computed here.
    """
    images = path.parent / "images"
    images.mkdir(parents=True, exist_ok=True)
    stored = {name: {run_key(**p): stored_run(folder, **p) for p in todo} for name, todo in STUDIES.items()}
    studies = {name: [r for r in runs.values() if r is not None] for name, runs in stored.items()}
    missing = {name: [key for key, r in runs.items() if r is None] for name, runs in stored.items()}
    lo, hi = beverloo()
    out = [
        "# Silo discharge",
        "",
        "The paper's example (§4): a plane silo 20 cm wide and 30 cm tall, a 10 cm outlet in the "
        "middle of the bottom, the paper's sand (rho = 1500 kg/m³, E = 1 MPa, nu = 0.3, phi = 30°, "
        "gamma = 1000 1/s, N = 1), cubic weight and r = 5 mm unless stated, wall and bottom "
        "friction angle 20°, 4 particles per triangle, squares of two triangles of side h. "
        "Geostatic stresses (K0 = nu / (1 - nu)), 0.02 s of damped settling on the closed outlet, "
        "opening at t = 0, discharge to t = 0.25 s. The numerics, unless a study varies them: the "
        "nodal volumetric rate, the cell-mean stress and the cell quadrature (`docs/numerics.md`).",
        "",
        "- flow rate: slope of the mass that passed the outlet plane, fitted over t >= 0.1 s.",
        "- band, edge band: full width at half maximum of the e_vp_bar peak across the left half "
        "at t = 0.25 s, at mid-height (y = 15 cm: the band between the material resting on the "
        "wall and the flowing core) and at y = 1 cm (the band that rises from the outlet edge, "
        "which is at x = 50 mm; the x [mm] of the peak follows the width). Particles of a 1 cm "
        "strip, bins of half a cell. channel: at y = 5 cm, the distance over which the downward "
        "velocity (time-averaged over the last 0.05 s) rises from 10 % to 90 % from the wall to "
        "the axis.",
        "",
        "Regenerate with `python demos/demo_silo.py --study all --report docs/silo.md`; each run is "
        "stored in `results/silo/runs` and reused (`--force` runs them again).",
        "",
        code_line([r for runs in studies.values() for r in runs]),
        "",
    ]

    def row(r):
        w = band_widths(r)
        shifted = f" (shifted {r['shift']:g} h)" if r.get("shift") else ""
        shifted += f" ({1e3 * r['edge_cell']:g} at the edges)" if r.get("edge_cell") else ""
        shifted += f" (split {r['split'][0]} x {r['split'][1]})" if r.get("split") else ""
        shifted += f" (Courant {courant_of(r):g})" if courant_of(r) != COURANT else ""
        shifted += f" ({r['ppc']} per triangle)" if r.get("ppc", 4) != 4 else ""
        return (
            f"| {1e3 * r['h']:g}{shifted} | {1e3 * r['radius']:g} | {r['weight']} | {r['wall_friction']:g} "
            f"| {r['flow_rate']:.1f} | {r['e_vp_bar_max']:.1f} "
            f"| {1e3 * w['band']:.1f} | {1e3 * w['edge']:.1f} at {1e3 * w['edge_x']:.0f} "
            f"| {1e3 * w['channel']:.1f} "
            f"| {r['particles']} | {r['steps']} | {r['mean_iterations']:.2f} | {r['seconds']:.0f}{ranks(r)} |"
        )

    header = [
        "| h [mm] | r [mm] | weight | wall friction [°] | flow rate [kg/s/m] | max e_vp_bar [1/s] "
        "| band [mm] | edge band [mm] | channel [mm] | particles at end | steps | iterations/step "
        "| time [s] |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, runs in studies.items():
        table = [*header, *(row(r) for r in runs), ""] if name != "numerics" else []  # its own below
        out += [f"## Study: {name}", "", *table]
        if missing[name]:
            out += ["Not run yet: " + ", ".join(f"`{key}`" for key in missing[name]) + ".", ""]
        if len(runs) < 2:
            continue
        if name == "meshes":
            nonlocal_ = [r for r in runs if r["radius"] > 0]
            local = [r for r in runs if r["radius"] == 0]
            plot_maps(nonlocal_, images / "silo_maps.png")
            plot_discharge(runs, images / "silo_discharge.png")
            plot_profiles(runs, images / "silo_profiles.png")
            for label, rs in (("non-local", nonlocal_), ("local", local)):
                widths = [band_widths(r) for r in rs]
                edge, band = [w["edge"] for w in widths], [w["band"] for w in widths]
                edge_mm = " / ".join(f"{1e3 * w:.1f}" for w in edge)
                h_mm = " / ".join(f"{1e3 * r['h']:g}" for r in rs)
                out.append(
                    f"- {label}: edge band {edge_mm} mm on h = {h_mm} mm; largest / smallest - 1 "
                    f"across the meshes: edge band {_spread(edge)}, band at mid-height {_spread(band)}, "
                    f"flow rate {_spread([r['flow_rate'] for r in rs])}"
                )
            out += [
                "- The band column measures the largest e_vp_bar peak at mid-height: where no band "
                "forms there (the non-local runs so far), it is the width of a weak bump, not of a "
                "band; compare the maps. The edge band is the band of the paper's Fig. 1.",
                f"- Beverloo (2D, d -> 0, C = 0.58-1.5): {lo:.0f}-{hi:.0f} kg/s/m.",
                "",
                "![e_vp_bar maps](images/silo_maps.png)",
                "",
                "![discharge](images/silo_discharge.png)",
                "",
                "![profiles](images/silo_profiles.png)",
                "",
            ]
            out += [*mesh_fit(local, "local"), *mesh_fit(nonlocal_, "non-local"), ""]
        if name == "shift":
            out += [*shift_lines(runs), ""]
        if name == "numerics":
            out += [*noise_lines(runs), ""]
        if name == "edges":
            out += [*edge_lines(runs, studies["meshes"]), ""]
        if name == "split":
            out += [*split_lines(runs), ""]
        if name == "timestep":
            out += [*timestep_lines(runs), ""]
        if name == "points":
            out += [*points_lines(runs, studies["meshes"]), ""]
        if name == "friction":
            out += [
                "| wall friction [°] | flow rate [kg/s/m] | corner speed [m/s] | base slip [m/s] "
                "| outlet angle [°] |",
                "|---|---|---|---|---|",
                *(
                    f"| {r['wall_friction']:g} | {r['flow_rate']:.1f} | {r['corner_speed']:.4f} "
                    f"| {r['base_slip']:.4f} | {r['outlet_angle']:.1f} |"
                    for r in runs
                ),
                "",
                "corner speed: median speed in the bottom corners (3 cm squares) at t = 0.25 s; base "
                "slip: median horizontal speed of the layer one cell deep over the plates; outlet "
                "angle: mean angle from the vertical of the velocity crossing the outlet plane.",
                "",
                *friction_lines(runs),
                "",
            ]
        if name == "radius":
            plot_radius(runs, images / "silo_radius.png")
            out += ["![flow rate against r](images/silo_radius.png)", ""]
        if name == "laws":
            out += law_lines(runs)
            paper = [r for r in runs if r.get("law") == "paper" and r["radius"] == 5e-3]
            if paper:
                plot_maps(paper, images / "silo_maps_paper.png")
                out += ["![e_vp_bar maps, the paper's law](images/silo_maps_paper.png)", ""]
    text = "\n".join(out)
    path.write_text(text)
    every = {run_key(**p): r for name, todo in STUDIES.items() for p, r in zip(todo, stored[name].values())}
    write_json([r for r in every.values() if r is not None], path.with_suffix(".json"))
    return text


#: What ``docs/silo.json`` gives of each run (lengths in m, the flow rate in kg/s/m).
JSON_FIELDS = (
    "h", "radius", "weight", "wall_friction", "law", "m", "shift", "edge_cell", "split", "volumetric",
    "stress", "quadrature", "courant", "flow_rate", "edge_band_width", "stagnant_band_width",
    "wall_band_width", "channel_width", "mean_iterations", "max_iterations", "unconverged", "particles",
    "steps",
)  # fmt: skip
#: The numerics every study but the numerics study runs with (:func:`run`'s defaults).
NUMERICS = dict(volumetric="nodal", stress="cell", quadrature="cell")


def write_json(runs, path: Path) -> None:
    """The stored runs as JSON in ``path``, listed by study.

    The keys: ``default_law``, ``numerics``, ``runs``, ``numerics_runs``, ``split_runs`` and
    ``timestep_runs``. Each run gives :data:`JSON_FIELDS`; ``runs`` are those with the default numerics
    (:data:`NUMERICS`, also given) on squares at the default time step, ``numerics_runs`` the
    numerics study's others, ``split_runs`` those on rectangles (the ``split`` study),
    ``timestep_runs`` those at another Courant factor (the ``timestep`` study). ``law`` is that
    of the non-local runs (``"local"`` for r = 0); the velocity band widths are given for the runs
    that recorded the speed across the bands.
    """
    rows = {"runs": [], "numerics_runs": [], "split_runs": [], "timestep_runs": []}
    for r in runs:
        row = {"channel_width": band_widths(r)["channel"], **NUMERICS, **r, "courant": courant_of(r)}
        row["law"] = r.get("law", "max") if r["radius"] > 0 else "local"
        listed = "runs" if all(row[k] == v for k, v in NUMERICS.items()) else "numerics_runs"
        listed = "split_runs" if row.get("split") else listed
        listed = "timestep_runs" if row["courant"] != COURANT else listed
        rows[listed].append({k: row[k] for k in JSON_FIELDS if row.get(k) is not None})
    path.write_text(json.dumps({"default_law": "max", "numerics": NUMERICS, **rows}, indent=1))


def points_lines(runs, meshes) -> list[str]:
    """Lines of Markdown: each mesh and model against the points per triangle, with the changes.

    ``meshes``: the mesh study's runs (4 points per triangle), against which a run with
    ``4 k^2`` per triangle on ``h`` is set beside the one with 4 on ``h / k``: the same points,
    a finer grid.
    """
    out = [
        "| model | h [mm] | points per triangle | spacing [mm] | points within r | flow rate [kg/s/m] "
        "| edge band [mm] | stagnant band [mm] | wall band [mm] | iterations/step | time [s] |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    changes, groups = [], {}
    for r in runs:
        groups.setdefault((r["radius"], r["h"]), []).append(r)
    for (radius, h), rs in groups.items():
        rs = sorted(rs, key=lambda r: r.get("ppc", 4))
        model = "local" if radius == 0 else f"r = {1e3 * radius:g} mm"
        for r in rs:
            ppc = r.get("ppc", 4)
            within = f"{points_within(h, radius, ppc):.0f}" if radius > 0 else "-"
            out.append(
                f"| {model} | {1e3 * h:g} | {ppc} | {1e3 * h / math.sqrt(2 * ppc):.2f} | {within} "
                f"| {r['flow_rate']:.1f} | {_mm(r, 'edge_band_width')} | {_mm(r, 'stagnant_band_width')} "
                f"| {_mm(r, 'wall_band_width')} | {r['mean_iterations']:.2f} | {r['seconds']:.0f}{ranks(r)} |"
            )
        steps = " -> ".join(str(r.get("ppc", 4)) for r in rs)
        rates = ", ".join(_change(a["flow_rate"], b["flow_rate"]) for a, b in itertools.pairwise(rs))
        changes.append(f"- {model}, h = {1e3 * h:g} mm, {steps} per triangle: flow rate {rates}")
        for r in rs:
            k = math.isqrt(r.get("ppc", 4) // 4)  # 4 k^2 per triangle: the points of 4 on h / k
            if k < 2 or 4 * k * k != r["ppc"]:
                continue
            for m in (m for m in meshes if m["radius"] == radius and math.isclose(m["h"], h / k)):
                changes.append(
                    f"- {model}, the same points on a grid {k} times finer: {r['ppc']} per triangle on "
                    f"h = {1e3 * h:g} mm {r['flow_rate']:.1f}, 4 on h = {1e3 * m['h']:g} mm "
                    f"{m['flow_rate']:.1f} kg/s/m ({_change(r['flow_rate'], m['flow_rate'])})"
                )
    return [
        *out,
        "",
        "spacing: of the points, h / sqrt(2 ppc); points within r: 2 pi ppc (r / h)^2, the points "
        "a non-local average sums over.",
        "",
        *changes,
    ]


def timestep_lines(runs) -> list[str]:
    """Lines of Markdown: each mesh and model against the Courant factor, with the changes.

    The change of each number is from the second smallest factor to the smallest; runs stored
    before a number was measured show ``-``.
    """
    out = [
        "| model | h [mm] | Courant | dt [s] | flow rate [kg/s/m] | edge band [mm] | stagnant band [mm] "
        "| wall band [mm] | channel [mm] | iterations/step | unconverged steps |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    changes = []
    groups = {}
    for r in runs:
        groups.setdefault((r["radius"], r["h"]), []).append(r)
    for (radius, h), rs in groups.items():
        rs = sorted(rs, key=lambda r: -courant_of(r))
        model = "local" if radius == 0 else f"r = {1e3 * radius:g} mm"
        for r in rs:
            dt = f"{r['dt']:.3g}" if "dt" in r else "-"  # stored before the step was recorded
            out.append(
                f"| {model} | {1e3 * h:g} | {courant_of(r):g} | {dt} "
                f"| {r['flow_rate']:.1f} | {_mm(r, 'edge_band_width')} "
                f"| {_mm(r, 'stagnant_band_width')} | {_mm(r, 'wall_band_width')} "
                f"| {1e3 * band_widths(r)['channel']:.1f} | {r['mean_iterations']:.2f} | {r['unconverged']} |"
            )
        if len(rs) >= 2:
            a, b = rs[-2], rs[-1]
            change = lambda key: _change(a.get(key, math.nan), b.get(key, math.nan))  # noqa: E731
            factors = f"Courant {courant_of(a):g} -> {courant_of(b):g}"
            changes.append(
                f"- {model}, h = {1e3 * h:g} mm, {factors}: "
                f"flow rate {change('flow_rate')}, edge band {change('edge_band_width')}, "
                f"stagnant band {change('stagnant_band_width')}, wall band {change('wall_band_width')}"
            )
    return [
        *out,
        "",
        "Band widths: the 10-90 % rise of the speed across the band (the velocity, not e_vp_bar), "
        "at y = 1 cm beside the outlet edge, at y = 2 cm (the stagnant zone's mid-height) and at "
        "the silo's mid-height along the wall.",
        "",
        *changes,
    ]


def split_lines(runs) -> list[str]:
    """Lines of Markdown: each run's cells across and up, its flux split across the outlet."""
    bands = outlet_band_names()
    out = [
        f"| model | cells across x up [mm] | {' | '.join(bands)} | flow rate [kg/s/m] |",
        "|---|---|" + "---|" * (len(bands) + 1),
    ]
    for r in runs:
        kx, ky = r.get("split") or (1, 1)
        shares = r.get("outlet_shares")
        parts = (
            " | ".join(f"{q:.1f}" for q in shares) if shares is not None else " | ".join(["-"] * len(bands))
        )
        model = "local" if r["radius"] == 0 else f"r = {1e3 * r['radius']:g} mm"
        cells = f"{1e3 * r['h'] / kx:g} x {1e3 * r['h'] / ky:g}"
        out.append(f"| {model} | {cells} | {parts} | {r['flow_rate']:.1f} |")
    return [
        *out,
        "",
        "Each square of h cut into KX columns and KY rows (`--split KX KY`): the flux through the "
        "outlet plane by distance from the nearer edge, in kg/s/m over both edges; the uniform "
        "meshes are the meshes study's.",
    ]


def law_lines(runs) -> list[str]:
    """Lines of Markdown: the laws' table (velocity band widths) and their spreads over the meshes."""
    out = [
        "| law | r [mm] | weight | h [mm] | flow rate [kg/s/m] | edge band [mm] | stagnant band [mm] "
        "| wall band [mm] | iterations/step | unconverged steps |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    groups = {}
    for r in runs:
        law = law_label(r)
        groups.setdefault((law, r["radius"], r["weight"]), []).append(r)
        out.append(
            f"| {law} | {1e3 * r['radius']:g} | {r['weight']} | {1e3 * r['h']:g} | {r['flow_rate']:.1f} "
            f"| {_mm(r, 'edge_band_width')} "
            f"| {_mm(r, 'stagnant_band_width')} "
            f"| {_mm(r, 'wall_band_width')} "
            f"| {r['mean_iterations']:.2f} | {r['unconverged']} |"
        )
    out += [
        "",
        "edge band, stagnant band, wall band: the 10-90 % width of the steepest jump of the "
        "time-averaged speed (t = 0.2-0.25 s) across the left half at y = 1 cm (the band that rises "
        "from the outlet edge along the stagnant zone, crossed obliquely), at y = 2 cm (the same band "
        "at the stagnant zone's mid-height) and at y = 15 cm (between the material sliding down the "
        "wall and the core), bins of half a cell; the jump ends where the speed's slope has fallen "
        "to a tenth of its steepest (`dolfin_mpm.post.measure.jump_width`). Runs stored before the "
        "stagnant band was measured show nan there.",
        "",
    ]
    for (law, radius, weight), rs in groups.items():
        if len(rs) > 1:
            fine = [r for r in rs if r["h"] <= 0.005]
            spread = lambda key, sel=rs: _spread([r.get(key, math.nan) for r in sel])  # noqa: E731
            meshes = " / ".join(f"{1e3 * r['h']:g}" for r in rs)
            out.append(
                f"- {law}, r = {1e3 * radius:g} mm ({weight}): spread over h = "
                f"{meshes} mm: flow rate {spread('flow_rate')}, "
                f"edge band {spread('edge_band_width')}, stagnant band {spread('stagnant_band_width')}, "
                f"wall band {spread('wall_band_width')}"
                + (
                    f"; over h <= 5 mm: flow rate {spread('flow_rate', fine)}, edge band "
                    f"{spread('edge_band_width', fine)}, "
                    f"stagnant band {spread('stagnant_band_width', fine)}, "
                    f"wall band {spread('wall_band_width', fine)}"
                    if len(fine) > 1
                    else ""
                )
            )
    out += ["", *claim_lines(groups)]
    return [*out, ""]


def law_label(run) -> str:
    """The law of a stored run as the tables name it: ``local``, ``max``, ``overnonlocal m = 1.3``."""
    if run["radius"] == 0:
        return "local"
    law = run.get("law", "max")
    return f"{law} m = {run['m']:g}" if run.get("m") is not None else law


def claim_lines(groups) -> list[str]:
    """Whether a law keeps the paper's claim on the stored runs: lines of Markdown.

    The goal: on h = 5, 2.5 and 1.25 mm, band widths within 20 % of each other (largest /
    smallest - 1), flow rates within 5 %, every step converged.
    """
    out = []
    for (law, radius, weight), rs in groups.items():
        if law == "local":
            continue
        fine = {round(1e5 * r["h"]): r for r in rs if r["h"] <= 0.005 + 1e-12}
        lacking = [f"{h / 100:g}" for h in (500, 250, 125) if h not in fine]
        converged = all(r["unconverged"] == 0 for r in rs)
        within = len(fine) > 1 and all(
            max(v) / min(v) - 1.0 <= goal
            for key, goal in (("edge_band_width", 0.2), ("wall_band_width", 0.2), ("flow_rate", 0.05))
            for v in [[r[key] for r in fine.values()]]
        )
        verdict = "meets" if within and converged and not lacking else "does not meet"
        why = [f"no run on h = {', '.join(lacking)} mm"] if lacking else []
        why += [] if converged else [f"{sum(r['unconverged'] for r in rs)} unconverged steps"]
        why += [] if within or len(fine) < 2 else ["widths or flow rates beyond the goal"]
        out.append(
            f"- {law}, r = {1e3 * radius:g} mm ({weight}) {verdict} the goal "
            f"(bands within 20 %, flow rate within 5 % on h = 5 / 2.5 / 1.25 mm, every step converged)"
            + (f": {'; '.join(why)}." if why else ".")
        )
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0].lstrip("# "))
    parser.add_argument("--study", choices=[*STUDIES, "all"], help="run a study instead of one run")
    parser.add_argument("--h", type=float, default=0.01, help="cell size [m]")
    parser.add_argument("--radius", type=float, default=5e-3, help="non-local radius r [m]")
    parser.add_argument("--weight", default="cubic", choices=list(WEIGHTS))
    parser.add_argument("--law", default="max", choices=list(LAWS), help="the non-local law")
    parser.add_argument("--m", type=float, help="the factor m > 1 of law overnonlocal")
    parser.add_argument("--wall-friction", type=float, default=20.0, help="wall friction angle [deg]")
    parser.add_argument(
        "--shift", type=float, default=0.0, help="mesh shifted sideways by this part of a cell"
    )
    parser.add_argument(
        "--split",
        type=int,
        nargs=2,
        default=(1, 1),
        metavar=("KX", "KY"),
        help="cut each square of h into KX columns and KY rows (cells refined across or up alone)",
    )
    parser.add_argument("--volumetric", default="nodal", choices=["cell", "nodal"], help="volumetric rate")
    parser.add_argument("--stress", default="cell", choices=["cell", "particle"], help="stress carried")
    parser.add_argument(
        "--quadrature", default="cell", choices=["particle", "cell"], help="how R integrates a cell"
    )
    parser.add_argument(
        "--courant", type=float, default=COURANT, help="the time step's Courant factor, in (0, 1]"
    )
    parser.add_argument("--ppc", type=int, default=4, help="points per triangle: 1, 4, 9, 16, ...")
    parser.add_argument("--output", type=Path, default=Path("results/silo"))
    parser.add_argument("--report", type=Path, help="write the Markdown report of the stored studies here")
    parser.add_argument("--force", action="store_true", help="run again the runs that are stored")
    args = parser.parse_args()
    try:
        dm.NonlocalAverage(args.radius, args.weight, law=dm.NonlocalLaw(args.law, args.m))
    except ValueError as e:
        parser.error(f"--radius, --weight, --law, --m: {e}")
    try:
        Options(courant=args.courant)
    except ValueError as e:
        parser.error(f"--courant: {e}")
    try:
        reference_points(2, args.ppc)
    except ValueError as e:
        parser.error(f"--ppc: {e}")
    if min(args.split) < 1:
        parser.error(f"--split: KX and KY must be whole numbers >= 1, got {' '.join(map(str, args.split))}")
    if args.study is None and args.report is None:
        todo = [
            dict(
                h=args.h,
                radius=args.radius,
                weight=args.weight,
                wall_friction=args.wall_friction,
                shift=args.shift,
                split=tuple(args.split),
                law=args.law,
                m=args.m,
                volumetric=args.volumetric,
                stress=args.stress,
                quadrature=args.quadrature,
                courant=args.courant,
                ppc=args.ppc,
            )
        ]
    elif args.study is None:
        todo = []  # the report of what is stored
    else:
        todo = [p for name in (STUDIES if args.study == "all" else [args.study]) for p in STUDIES[name]]
    lo, hi = beverloo()
    for params in todo:
        try:
            r = cached_run(args.output, xdmf=True, force=args.force, **params)
        except dm.SimulationError as e:  # a run that went bad: what it wrote stays, no traceback
            sys.exit(f"error: {run_key(**params)}: {e}")
        if MPI.COMM_WORLD.rank > 0:
            continue
        key = run_key(**params)
        if args.study is None:
            plot_maps([r], args.output / f"{key}_map.png")
            plot_discharge([r], args.output / f"{key}_discharge.png")
            print(f"wrote {args.output}/{key}_map.png, {key}_discharge.png and runs/{key}/*.xdmf")
        print(
            f"{key}: flow rate {r['flow_rate']:.1f} kg/s/m (Beverloo {lo:.0f}-{hi:.0f}), "
            f"max e_vp_bar {r['e_vp_bar_max']:.1f} 1/s, {r['particles']} particles, {r['steps']} steps, "
            f"{r['seconds']:.0f} s{ranks(r)}, {r['mean_iterations']:.2f} iterations per step"
        )
        bands = outlet_band_names()
        if "outlet_shares" in r:  # stored runs made before it have none
            print(
                "  through the outlet by distance from its edges: "
                + ", ".join(f"{b} {q:.1f}" for b, q in zip(bands, r["outlet_shares"]))
                + f" kg/s/m (sum {sum(r['outlet_shares']):.1f})"
            )
        if "outlet_stress_free" in r:  # stored runs made before it have none
            print(
                "  stress free (p = 0) there: "
                + ", ".join(
                    f"{b} {'-' if f is None else f'{100 * f:.0f} %'}"
                    for b, f in zip(bands, r["outlet_stress_free"])
                )
            )
        if args.study is None:
            print("\n".join(mesh_lines(mesh_runs(args.output, params))))
            print("\n".join(points_advice(points_runs(args.output, params), args.ppc)))
    if args.report is not None and MPI.COMM_WORLD.rank == 0:
        report(args.output, args.report)
        print(f"wrote {args.report}")


if __name__ == "__main__":
    main()
