"""# Rigid strip footing on a weightless soil: bearing capacity

A benchmark of the reference finite-element solver against Prandtl's bearing capacity. A
rough rigid footing of width B = 1 m is pushed into a weightless half-space (a 5 m x 5 m
half model with rollers on the symmetry line and the far side, fixed at the base) under
displacement control; the mean footing pressure q = reaction / (B/2) rises to the bearing
capacity q_u = N_c c:

- cohesive soil (von Mises matched to Tresca in plane strain, sigma_y = sqrt(3) c):
  N_c = 2 + pi = 5.14 (Prandtl 1920);
- frictional soil, phi = 30 deg, with the paper's Drucker–Prager cone
  q = m (p + c cot phi) and non-associated g = q (rate-independent limit): compared with the
  Mohr–Coulomb N_c = (N_q - 1) cot phi = 30.14, N_q = exp(pi tan phi) tan^2(45 + phi/2),
  which assumes associated flow; the plastically incompressible g = q gives less;
- frictional-associated: the Drucker–Prager cone matched to Mohr–Coulomb in plane strain with
  associated flow (:class:`MohrCoulombDruckerPrager`, M = 0.832 at 30 deg), whose collapse load
  is Mohr–Coulomb's: N_c = 30.14.

The mesh is graded towards the footing edge, where the stresses are singular.

    python demos/demo_footing.py [--soil cohesive|frictional|frictional-associated] [--quick]
        [--study [mesh|time]] [--output results/footing]

``--study`` runs the MPM alone on cells of 10, 5 and 2.5 cm with 1 and 4 points per triangle
and each stress option, and prints the collapse loads as a table (the associated soil: about
2.5 hours on one core, most of it the 2.5 cm cells with four points; ``--quick``: the 10 cm
cells with one point, a minute); ``--study time`` runs the loading speed and the Courant
number, each as it is and halved. The study runs use :func:`run_mpm`'s defaults, damping
included; the single run uses the benchmark's (:data:`BENCHMARK_MPM`).
"""

import argparse
import itertools
import json
import math
import time
from pathlib import Path

import dolfin_mpm as dm  # import first: it loads DOLFINx's libraries

# isort: split
import numpy as np
from dolfinx import mesh
from mpi4py import MPI

from dolfin_mpm.explicit.options import Options
from dolfin_mpm.fe import ConvergenceError, QuasiStatic
from dolfin_mpm.post.plotting import figure

B, L = 1.0, 5.0  # footing width, size of the half model [m]
C, E, NU = 100e3, 100e6, 0.3  # cohesion [Pa], soil stiffness
PHI = 30.0  # friction angle of the frictional soil [deg]
SOILS = ("cohesive", "frictional", "frictional-associated")
SETTLEMENT = {"cohesive": 0.05, "frictional": 0.05, "frictional-associated": 0.3}  # footing push [m]
#: The MPM's push [m]: to the plateau of each soil (the associated cone dilates and needs most).
MPM_SETTLEMENT = {"cohesive": 0.03, "frictional": 0.06, "frictional-associated": 0.3}
#: The MPM's options by soil. Beside the associated footing the heave leaves nodes whose
#: triangles hold little material, whose own stable step is shorter than the step: solved on
#: their own, their velocities grow without bound on cells of 5 cm and less (a particle's volume
#: reaches zero at 13-27 cm of settlement; at Courant 0.25 the pushes on 10 and 5 cm cells end).
#: Tied to their neighbours (``light_nodes="aggregate"``) the pushes end on every mesh. At 0.5
#: the ties hold so many nodes of the heave that they stiffen it: the load at 0.3 m rises by
#: 12 % on 10 cm cells (at 0.25, by 0.5 %; ``docs/numerics.md``).
MPM_OPTIONS = {"frictional-associated": {"courant": 0.25, "light_nodes": "aggregate"}}
#: How the benchmark and the command line run each soil's MPM footing where it differs from
#: :func:`run_mpm`'s defaults: the cohesive footing undamped (the local damping drags the soil
#: that flows past it), as rigid walls (B wide on any mesh) and pushed past the FE's plateau.
BENCHMARK_MPM = {"cohesive": {"settlement": 0.05, "damping": 0.0, "footing": "walls"}}
#: The MPM study of a soil's collapse load: cell sizes h [m], points per triangle, stress options.
STUDY = {"h": (0.1, 0.05, 0.025), "ppc": (1, 4), "stress": ("cell", "particle")}
#: The time step's study at the cohesive benchmark's cells: the loading speed over the p-wave
#: speed, and the Courant number of the automatic step (None: the soil's, :data:`MPM_OPTIONS`).
TIME_STUDY = {
    "h": (0.05,),
    "ppc": (4,),
    "stress": ("cell",),
    "speed": (3e-4, 1.5e-4),
    "courant": (None, 0.25),
}
#: The head of the study's table (:func:`study_line`).
STUDY_HEAD = (
    "| h [mm] | points per triangle | stress | speed / c_p | Courant | q / c at s = 0.1 B | error "
    "| q_u / c, last quarter | error | spread |\n"
    "|---|---|---|---|---|---|---|---|---|---|"
)
#: The settlement over B at which a footing with no plateau has failed (the 10 % criterion).
FAILURE_SETTLEMENT = 0.1


def prandtl_nc(phi):
    """Prandtl's N_c = (N_q - 1) cot phi, N_q = exp(pi tan phi) tan^2(45 + phi/2); ``phi`` [deg]."""
    t = np.tan(np.radians(phi))
    return (np.exp(np.pi * t) * np.tan(np.radians(45.0 + phi / 2.0)) ** 2 - 1.0) / t


def soil(kind):
    """The soil model and its analytical bearing-capacity factor N_c."""
    if kind == "cohesive":
        return dm.VonMises(E=E, nu=NU, rho=1.0, sigma_y=np.sqrt(3.0) * C), 2.0 + np.pi
    if kind == "frictional":
        return dm.DruckerPragerViscoplastic(E=E, nu=NU, rho=1.0, phi=PHI, gamma=np.inf, c=C), prandtl_nc(PHI)
    if kind == "frictional-associated":
        return dm.MohrCoulombDruckerPrager(E=E, nu=NU, rho=1.0, phi=PHI, c=C), prandtl_nc(PHI)
    raise ValueError(f"soil must be one of {SOILS}, got {kind!r}")


def davis_capacity(material):
    """Davis's estimate of q_u / C for a cone ``q = m (p + a)`` with isochoric flow (psi = 0).

    In plane strain that cone is Mohr–Coulomb with sin phi' = m / sqrt(3) and c' = a tan phi';
    Davis (1968) replaces a non-associated soil by an associated one with tan phi* = sin phi'
    (psi = 0) and c* = c' cos phi', whose N_c gives q_u = N_c(phi*) c*.
    """
    phi_e = np.arcsin(material.m / np.sqrt(3.0))
    c_star = material.tension_limit * np.tan(phi_e) * np.cos(phi_e)
    return prandtl_nc(np.degrees(np.arctan(np.sin(phi_e)))) * c_star / C


def graded(n, length, at, fine):
    """``n + 1`` coordinates on [0, length] with spacing ~``fine`` near ``at`` growing away from it
    (sinh stretching on each side of ``at``, which is one of the coordinates)."""
    left, right = np.arcsinh(at / fine), np.arcsinh((length - at) / fine)
    n_left = round(n * left / (left + right))
    xr = at + fine * np.sinh(right * np.linspace(0.0, 1.0, n - n_left + 1))
    if n_left == 0:
        return xr
    xl = at - fine * np.sinh(left * np.linspace(1.0, 0.0, n_left + 1))
    return np.concatenate([xl, xr[1:]])


def half_space(n, fine):
    """``[0, L] x [-L, 0]``, ``n x n`` squares of four triangles, graded towards (B/2, 0)."""
    msh = mesh.create_rectangle(
        MPI.COMM_WORLD, [np.zeros(2), np.full(2, float(n))], [n, n], mesh.CellType.triangle,
        diagonal=mesh.DiagonalType.crossed,
    )  # fmt: skip
    x, depth = graded(n, L, B / 2, fine), graded(n, L, 0.0, fine)
    gx, gy = msh.geometry.x[:, 0].copy(), msh.geometry.x[:, 1].copy()
    msh.geometry.x[:, 0] = np.interp(gx, np.arange(n + 1), x)
    msh.geometry.x[:, 1] = -np.interp(n - gy, np.arange(n + 1), depth)
    return msh


def run(kind="cohesive", n=32, settlement=None, steps=25, progress=True):
    """Push the footing down by ``settlement`` [m] (default ``SETTLEMENT[kind]``) with the FE
    solver; returns the load–settlement curve and q_u."""
    material, n_c = soil(kind)
    settlement = SETTLEMENT[kind] if settlement is None else settlement
    msh = half_space(n, fine=0.02 * B)
    fe = QuasiStatic(msh, material, degree=2)
    tol = 1e-9
    footing = mesh.locate_entities_boundary(msh, 1, lambda x: (np.abs(x[1]) < tol) & (x[0] < B / 2 + tol))
    fe.fix(footing, component=1, value=-settlement)
    fe.fix(footing, component=0)  # rough
    fe.fix(mesh.locate_entities_boundary(msh, 1, lambda x: np.abs(x[0]) < tol), component=0)
    fe.fix(mesh.locate_entities_boundary(msh, 1, lambda x: np.abs(x[0] - L) < tol), component=0)
    base = mesh.locate_entities_boundary(msh, 1, lambda x: np.abs(x[1] + L) < tol)
    fe.fix(base, component=0)
    fe.fix(base, component=1)

    curve = {"settlement": [0.0], "q": [0.0], "iterations": [0]}

    def record(fe):
        curve["settlement"].append(fe.load * settlement)
        curve["q"].append(-fe.reaction(footing, 1) / (B / 2))
        curve["iterations"].append(fe.history[-1].iterations)
        if progress:
            print(f"settlement {1e3 * curve['settlement'][-1]:6.2f} mm  q/c = {curve['q'][-1] / C:6.3f}  "
                  f"({curve['iterations'][-1]} Newton iterations)")  # fmt: skip

    # Fine steps first (elastic, then first yield), coarser once the plastic zone is spread.
    loads = np.concatenate([np.linspace(0.0, 0.1, 6)[1:], np.linspace(0.1, 1.0, steps + 1)[1:]])
    try:
        fe.advance(loads, min_step=1e-4, on_step=record)
        failed_at = None
    except ConvergenceError as err:
        failed_at = err.load * settlement
        if progress:
            print(f"stopped: {err}")
    q = np.array(curve["q"])
    result = {
        "soil": kind,
        "N_c": float(n_c),
        "q_u": float(q.max()),
        "q_u_over_c": float(q.max() / C),
        "error": float(q.max() / (n_c * C) - 1.0),
        "plateau": float(q[-1] / q[-4] - 1.0) if len(q) > 4 else float("nan"),
        "failed_at": failed_at,
        "newton_mean": float(np.mean(curve["iterations"][1:])),
        "newton_max": int(np.max(curve["iterations"][1:])),
        "solve_seconds": float(sum(s.seconds for s in fe.history)),
        "dofs": int(fe.V.dofmap.index_map.size_global * 2),
        "curve": curve,
    }
    return result


def mpm_half_space(h, above=2, growth=1.25):
    """``[0, L] x [-L, above h]`` for the MPM: ``h`` squares of four triangles to 1.5 B across and
    B deep, growing by ``growth`` beyond; ``above`` empty rows over the surface for the heave."""

    def lines(core):
        x = [*np.arange(0.0, core + 0.5 * h, h)]
        while x[-1] < L - 1e-9:
            x.append(min(x[-1] + h * growth ** (len(x) - round(core / h)), L))
        return np.array(x)

    xs, ys = lines(1.5 * B), np.concatenate([-lines(B)[::-1], h * np.arange(1, above + 1)])
    msh = mesh.create_rectangle(
        MPI.COMM_WORLD, [np.zeros(2), np.array([len(xs) - 1.0, len(ys) - 1.0])], [len(xs) - 1, len(ys) - 1],
        mesh.CellType.triangle, diagonal=mesh.DiagonalType.crossed,
    )  # fmt: skip
    gx, gy = msh.geometry.x[:, 0].copy(), msh.geometry.x[:, 1].copy()
    msh.geometry.x[:, 0] = np.interp(gx, np.arange(len(xs)), xs)
    msh.geometry.x[:, 1] = np.interp(gy, np.arange(len(ys)), ys)
    return msh


def run_mpm(
    kind="cohesive", h=0.05, settlement=None, ppc=4, speed=3e-4, damping=0.1, records=40, progress=True,
    footing="nodes", **options,
):  # fmt: skip
    """The same footing with the explicit MPM, pushed down quasi-statically; returns q(settlement).

    ``settlement`` [m]: default ``MPM_SETTLEMENT[kind]``.

    The rigid footing (``footing="nodes"``) is the set of grid nodes inside it: ``x <= B/2``
    and above its base, which moves down at ``speed`` times the p-wave speed (no horizontal
    motion: rough) to ``settlement`` [m]; nodes join the set as the base passes them, so the
    footing can sink by many cells ``h`` [m]. With ``footing="walls"`` it is two rough rigid
    walls (:class:`dolfin_mpm.RigidWall`, no slip), its base and its side, moving down at the
    same speed wherever the nodes fall (cohesive, full run: q_u / c = 5.241 against 5.381 with
    the nodes, both 5.45 at 30 mm; its curve lags the nodes' by up to 0.3 c between 15 and 25 mm
    and jumps as the base passes mid-cell, so the nodes stay the default). The symmetry planes
    and the fixed base are nodal conditions on mesh lines. Local damping takes out the waves.
    ``q`` is the footing's vertical reaction over B/2, averaged over each of ``records``
    intervals. ``options``: the solver's numerical options (:class:`dolfin_mpm.explicit.options.Options`),
    e.g. ``stress="particle"``, over :data:`MPM_OPTIONS`. The local damping drags the soil that
    flows past the footing and raises its load by several per cent, more on finer cells
    (``docs/numerics.md``); :data:`BENCHMARK_MPM` has the runs that converge.

    ``q_u_over_c`` is the mean over the last quarter of the push; ``q_10_over_c`` is ``q`` at a
    settlement of :data:`FAILURE_SETTLEMENT` B (the failure load by the 10 % criterion; ``None``
    for a shorter push): where the soil dilates, the footing sinks into it and the heave
    around it rises, and the large-deformation load keeps growing past the small-strain plateau.
    """
    material, n_c = soil(kind)
    options = {**MPM_OPTIONS.get(kind, {}), **options}
    settlement = MPM_SETTLEMENT[kind] if settlement is None else settlement
    grid = dm.Grid(mpm_half_space(h, above=2 + math.ceil(settlement / h)))  # room for the heave
    tol = 1e-9
    particles = dm.seed(grid, material, ppc=ppc, where=lambda x: x[1] < tol)
    v = speed * material.p_wave_speed()
    bcs = [
        dm.SlipBC(grid.nodes_where(lambda x: (np.abs(x[0]) < tol) | (np.abs(x[0] - L) < tol)), normal=(1, 0)),
        dm.FixedBC(grid.nodes_where(lambda x: np.abs(x[1] + L) < tol)),
    ]
    if footing == "walls":
        top = (2 + math.ceil(settlement / h)) * h  # the grid's top
        walls = [  # rough rigid walls moving down at v: the base and the side, the soil on their left
            dm.RigidWall([(B / 2, 0.0), (0.0, 0.0)], np.inf, "footing base", velocity=(0.0, -v)),
            dm.RigidWall([(B / 2, top), (B / 2, 0.0)], np.inf, "footing side", velocity=(0.0, -v)),
        ]
        bcs = [*bcs, *walls]
    elif footing != "nodes":
        raise ValueError(f"footing must be 'nodes' or 'walls', got {footing!r}")
    solver = dm.Solver(grid, particles, material, bcs=bcs, damping=damping, **options)
    under = grid.node_x[:, 0] < B / 2 + tol
    nodes = np.zeros(0, dtype=np.int64)
    every = math.ceil(settlement / (v * solver.dt) / records)
    curve = {"settlement": [0.0], "q": [0.0]}
    force, start = 0.0, time.perf_counter()
    for k in range(1, every * records + 1):
        if footing == "walls":
            solver.step()
            force += sum(solver.reaction(wall)[1] for wall in walls)
        else:
            inside = np.flatnonzero(under & (grid.node_x[:, 1] > -v * (solver.time + solver.dt) - tol))
            if len(inside) != len(nodes):  # the base passed a row of nodes
                nodes = inside
                solver.bcs = [*bcs, dm.VelocityBC(nodes, velocity=(0.0, -v))]
            solver.step()
            force += solver.reaction(nodes)[1]
        if k % every == 0:
            curve["settlement"].append(v * solver.time)
            curve["q"].append(-force / every / (B / 2))
            force = 0.0
            if progress:
                s_mm, q_c = 1e3 * curve["settlement"][-1], curve["q"][-1] / C
                print(f"MPM: settlement {s_mm:6.2f} mm  q/c = {q_c:6.3f}")
    q = np.array(curve["q"])
    q_u = q[-records // 4 :].mean()  # the plateau: the mean over the last quarter
    s_mid = 0.5 * settlement / records * (2 * np.arange(1, records + 1) - 1)  # each mean's interval
    reached = settlement >= FAILURE_SETTLEMENT * B
    q_10 = np.interp(FAILURE_SETTLEMENT * B, s_mid, q[1:]) / C if reached else None
    return {
        "soil": kind,
        "N_c": float(n_c),
        "q_u_over_c": float(q_u / C),
        "error": float(q_u / (n_c * C) - 1.0),
        "q_10_over_c": None if q_10 is None else float(q_10),
        "error_10": None if q_10 is None else float(q_10 / n_c - 1.0),
        "plateau_spread": float(q[-records // 4 :].max() / q[-records // 4 :].min() - 1.0),
        "particles": len(particles),
        "steps": every * records,
        "run_seconds": time.perf_counter() - start,
        "h": h,
        "ppc": ppc,
        "speed": speed,
        "options": options,
        "curve": curve,
    }


def study_mpm(kind="frictional-associated", study=None, speed=3e-4, progress=True) -> list[dict]:
    """The MPM collapse load of ``kind`` on every combination of ``study`` (default :data:`STUDY`).

    ``study`` maps ``h``, ``ppc``, ``stress`` and, optionally, ``speed`` (default: ``speed``) and
    ``courant`` (default and ``None``: the soil's) to the values to run. One row per run: those
    five, and ``q_u_over_c``, ``error``, ``q_10_over_c``, ``error_10``, ``plateau_spread`` and
    ``steps`` of :func:`run_mpm`, or ``failed``: the message of a run that went bad.
    """
    study = {"speed": (speed,), "courant": (None,), **(STUDY if study is None else study)}
    default_courant = MPM_OPTIONS.get(kind, {}).get("courant", Options().courant)
    rows = []
    runs = itertools.product(*(study[k] for k in ("h", "ppc", "stress", "speed", "courant")))
    for h, ppc, stress, v, courant in runs:
        courant = default_courant if courant is None else courant
        row = {"h": h, "ppc": ppc, "stress": stress, "speed": v, "courant": courant}
        try:
            res = run_mpm(kind, h=h, ppc=ppc, speed=v, progress=False, stress=stress, courant=courant)
            keys = ("q_u_over_c", "error", "q_10_over_c", "error_10", "plateau_spread", "steps")
            row.update({k: res[k] for k in keys})
        except dm.SimulationError as err:
            row["failed"] = str(err)
        rows.append(row)
        if progress:
            print(study_line(row), flush=True)
    return rows


def study_line(row) -> str:
    """One run of :func:`study_mpm` as a row of :data:`STUDY_HEAD`'s table."""
    head = (
        f"| {1e3 * row['h']:g} | {row['ppc']} | `{row['stress']}` | {row['speed']:g} | {row['courant']:g} |"
    )
    if "failed" in row:
        return f"{head} stopped: {row['failed'].split(':')[0]} | | | | |"
    pct = lambda key: "—" if row[key] is None else f"{100 * row[key]:+.1f} %"  # noqa: E731
    q_10 = "—" if row["q_10_over_c"] is None else f"{row['q_10_over_c']:.2f}"
    return (
        f"{head} {q_10} | {pct('error_10')} | {row['q_u_over_c']:.2f} | {pct('error')} "
        f"| {100 * row['plateau_spread']:.1f} % |"
    )


def save(folder, fe, mpm):
    """Write both results (JSON) and their plot into ``folder``."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / f"footing_{fe['soil']}.json").write_text(json.dumps({"fe": fe, "mpm": mpm}, indent=1))
    plot([fe], folder / f"footing_{fe['soil']}.png", [mpm])


def plot(results, path, mpm=()):
    """Load–settlement curves, FE and MPM, against the analytical bearing capacities."""
    with figure(path, figsize=(6, 4)) as ax:
        colours = {}
        for res in results:
            line = ax.plot(1e3 * np.array(res["curve"]["settlement"]), np.array(res["curve"]["q"]) / C,
                           "o-", ms=3, label=f"FE, {res['soil']}")  # fmt: skip
            colours[res["soil"]] = line[0].get_color()
            ax.axhline(res["N_c"], color=colours[res["soil"]], ls="--", label=f"N_c = {res['N_c']:.2f}")
        for res in mpm:
            ax.plot(1e3 * np.array(res["curve"]["settlement"]), np.array(res["curve"]["q"]) / C, "s:", ms=3,
                    color=colours.get(res["soil"]), label=f"MPM, {res['soil']}")  # fmt: skip
        ax.set(xlabel="settlement [mm]", ylabel="mean footing pressure q / c")
        ax.legend()


def main():
    """The command line: the FE run and the MPM run of one soil, or the MPM study."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0].lstrip("# "))
    parser.add_argument("--soil", default="cohesive", choices=SOILS)
    parser.add_argument("--quick", action="store_true", help="coarse meshes, few steps")
    parser.add_argument("--output", type=Path, default=Path("results/footing"))
    parser.add_argument(
        "--study", nargs="?", const="mesh", choices=["mesh", "time"],
        help="the MPM's collapse load on 10, 5, 2.5 cm cells with 1 and 4 points (mesh, the default), "
        "or at two loading speeds and Courant numbers (time)",
    )  # fmt: skip
    args = parser.parse_args()
    if args.study:
        if args.quick:
            quick = {"mesh": {"stress": ("cell", "particle")}, "time": {"courant": (None, 0.25)}}[args.study]
            study = {"h": (0.1,), "ppc": (1,), "stress": ("cell",), **quick}
        else:
            study = {"mesh": STUDY, "time": TIME_STUDY}[args.study]
        print(STUDY_HEAD)
        rows = study_mpm(args.soil, study, speed=1e-3 if args.quick else 3e-4)
        args.output.mkdir(parents=True, exist_ok=True)
        name = f"footing_{args.soil}_study" + ("" if args.study == "mesh" else "_time")
        (args.output / f"{name}.json").write_text(json.dumps(rows, indent=1))
        return
    res = run(args.soil, 12, steps=10) if args.quick else run(args.soil)
    benchmark = BENCHMARK_MPM.get(args.soil, {})
    mpm = run_mpm(args.soil, h=0.1, ppc=1, **benchmark) if args.quick else run_mpm(args.soil, **benchmark)
    save(args.output, res, mpm)
    print(
        f"{args.soil}: q_u / c = {res['q_u_over_c']:.3f} "
        f"(N_c = {res['N_c']:.3f}, {100 * res['error']:+.1f} %),"
        f" last steps {100 * res['plateau']:+.2f} %; {res['dofs']} dofs, Newton {res['newton_mean']:.1f} "
        f"mean / {res['newton_max']} max, {res['solve_seconds']:.1f} s"
    )
    print(
        f"MPM: q_u / c = {mpm['q_u_over_c']:.3f} ({100 * mpm['error']:+.1f} %), spread over the last quarter "
        f"{100 * mpm['plateau_spread']:.1f} %; {mpm['particles']} particles, {mpm['steps']} steps, "
        f"{mpm['run_seconds']:.1f} s"
    )


if __name__ == "__main__":
    main()
