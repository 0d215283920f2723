"""# Thick-walled cylinder under internal pressure (von Mises, perfectly plastic)

A benchmark of the reference finite-element solver against the classical solution (Hill,
*The Mathematical Theory of Plasticity*, 1950). A long tube, inner radius a = 100 mm, outer
radius b = 200 mm, steel with E = 210 GPa, nu = 0.3 and yield stress sigma_y = 240 MPa, is
loaded by an internal pressure p in plane strain. A quarter of the section is meshed, with
rollers on the two symmetry planes.

With the plane-strain yield condition sigma_theta - sigma_r = 2k, k = sigma_y / sqrt(3), the
plastic zone a <= r <= c grows with

    p(c) = k (2 ln(c / a) + 1 - c^2 / b^2),

from the elastic limit p_e = k (1 - a^2 / b^2) = 103.9 MPa (c = a) to the limit pressure
p_lim = 2 k ln(b / a) = 192.1 MPa (c = b), and the outer radius moves by

    u_b = 2 (1 - nu^2) k c^2 / (E b).

The limit pressure is exact; the curve p(c) assumes sigma_z = (sigma_r + sigma_theta) / 2 in
the plastic zone, exact only for an incompressible material, so with nu = 0.3 it is a close
approximation and the comparison of the curve is looser than that of the limit.

    python demos/demo_cylinder.py [--quick] [--output results/cylinder]
"""

import argparse
import json
import math
import time
from pathlib import Path

import dolfin_mpm as dm  # import first: it loads DOLFINx's libraries

# isort: split
import numpy as np
from dolfinx import mesh
from mpi4py import MPI
from scipy.optimize import brentq

from dolfin_mpm.fe import ConvergenceError, QuasiStatic
from dolfin_mpm.post.plotting import figure

A, B = 0.1, 0.2  # inner and outer radius [m]
STEEL = dm.VonMises(E=210e9, nu=0.3, rho=7850.0, sigma_y=240e6)
K = STEEL.sigma_y / np.sqrt(3.0)
P_ELASTIC = K * (1 - A**2 / B**2)
P_LIMIT = 2 * K * np.log(B / A)


def pressure_of_radius(c):
    """Internal pressure [Pa] at which the plastic zone reaches radius ``c`` [m]."""
    return K * (2 * np.log(c / A) + 1 - c**2 / B**2)


def plastic_radius(p):
    """Radius [m] of the plastic zone at pressure ``p`` [Pa] (``a`` below the elastic limit)."""
    if p <= P_ELASTIC:
        return A
    return brentq(lambda c: pressure_of_radius(c) - p, A, B, xtol=1e-12)


def outer_displacement(p):
    """Radial displacement of the outer surface [m] at pressure ``p`` [Pa]."""
    if p <= P_ELASTIC:  # Lame: u(b) = 2 (1 - nu^2) p a^2 b / (E (b^2 - a^2))
        return 2 * (1 - STEEL.nu**2) * p * A**2 * B / (STEEL.E * (B**2 - A**2))
    return 2 * (1 - STEEL.nu**2) * K * plastic_radius(p) ** 2 / (STEEL.E * B)


def quarter_annulus(n_radial, n_theta, r_max=B):
    """Triangle mesh of ``a <= r <= r_max``, ``0 <= theta <= pi/2``: a rectangle in (r, theta) mapped."""
    msh = mesh.create_rectangle(
        MPI.COMM_WORLD, [np.array([A, 0.0]), np.array([r_max, 0.5 * np.pi])], [n_radial, n_theta],
        mesh.CellType.triangle, diagonal=mesh.DiagonalType.crossed,
    )  # fmt: skip
    r, theta = msh.geometry.x[:, 0].copy(), msh.geometry.x[:, 1].copy()
    msh.geometry.x[:, 0], msh.geometry.x[:, 1] = r * np.cos(theta), r * np.sin(theta)
    return msh


def run(n_radial=10, n_theta=20, step=0.05, progress=True):
    """Load the tube to collapse with the FE solver; returns the load path and its errors."""
    msh = quarter_annulus(n_radial, n_theta)
    fe = QuasiStatic(msh, STEEL, degree=2)
    radius = lambda x: np.hypot(x[0], x[1])  # noqa: E731
    tol = 1e-6 * A
    fe.fix(mesh.locate_entities_boundary(msh, 1, lambda x: np.abs(x[1]) < tol), component=1)
    fe.fix(mesh.locate_entities_boundary(msh, 1, lambda x: np.abs(x[0]) < tol), component=0)
    fe.pressure(mesh.locate_entities_boundary(msh, 1, lambda x: np.abs(radius(x) - A) < tol), P_LIMIT)

    # Radius of every quadrature point, for the extent of the plastic zone.
    owned = msh.topology.index_map(2).size_local
    centre = mesh.compute_midpoints(msh, 2, np.arange(owned, dtype=np.int32))
    r_cell = np.hypot(centre[:, 0], centre[:, 1])
    nodes = fe.V.tabulate_dof_coordinates()
    outer_dof = 2 * int(np.argmin(np.hypot(nodes[:, 0] - B, nodes[:, 1])))  # u_x at (b, 0): u_b

    path = {"p": [0.0], "u_b": [0.0], "c": [A], "iterations": [0]}

    def record(fe):
        eps_p = fe.cell_average(fe.state["eps_p"])[:owned]
        plastic = eps_p > 1e-12
        path["p"].append(fe.load * P_LIMIT)
        path["u_b"].append(float(fe.u.x.array[outer_dof]))
        path["c"].append(float(r_cell[plastic].max()) if plastic.any() else A)
        path["iterations"].append(fe.history[-1].iterations)
        if progress:
            print(
                f"p = {path['p'][-1] / 1e6:7.2f} MPa  u_b = {1e3 * path['u_b'][-1]:.5f} mm  plastic to "
                f"r = {1e3 * path['c'][-1]:.1f} mm  ({path['iterations'][-1]} Newton iterations)"
            )

    # Up to the limit in steps, then on beyond it: the step is cut in halves until Newton
    # fails within 1e-3 p_lim of the last converged pressure, the FE limit pressure.
    loads = np.append(np.arange(step, 1.0 - 0.5 * step, step), 1.0 + 1.5 * step)
    try:
        fe.advance(loads, min_step=1e-3, on_step=record)
        collapsed = False
    except ConvergenceError:
        collapsed = True
    p, u_b, c = np.array(path["p"]), np.array(path["u_b"]), np.array(path["c"])
    below = (p > 0) & (p <= 0.99 * P_LIMIT)
    u_exact = np.array([outer_displacement(x) for x in p[below]])
    result = {
        "p_limit": float(P_LIMIT),
        "p_max": float(p.max()),
        "limit_error": float(p.max() / P_LIMIT - 1.0),
        "collapsed": collapsed,
        "u_b_error": float(np.max(np.abs(u_b[below] / u_exact - 1.0))),
        "c_error": float(np.max(np.abs(c[below] - [plastic_radius(x) for x in p[below]])) / A),
        "newton_mean": float(np.mean(path["iterations"][1:])),
        "solve_seconds": float(sum(s.seconds for s in fe.history)),
        "cells": int(owned),
        "path": path,
    }  # fmt: skip
    return result


def run_mpm(n_radial=10, n_theta=20, ppc=4, speed=3e-5, damping=0.1, u_max=1e-3, records=50, progress=True):
    """The same tube with the explicit MPM, loaded quasi-statically; returns its load path.

    The grid is the FE mesh continued by two cell layers beyond r = b, room for the outer
    surface to move; the material fills a <= r <= b with ``ppc`` particles per triangle. The
    inner nodes move out radially at ``speed`` times the p-wave speed up to ``u_max`` [m]: by
    symmetry a uniform radial displacement of the bore is the load of a uniform pressure, which
    is then the radial reaction of the bore's nodes over its arc, ``p = sum F_c . e_r / (pi a / 2)``.
    Local damping takes out the elastic waves. One step's contact force is an impulse over
    ``dt``, so ``p`` is averaged over each of ``records`` intervals; ``u_b`` is the radial
    velocity of the node at (b, 0) integrated in time.
    """
    dr = (B - A) / n_radial
    msh = quarter_annulus(n_radial + 2, n_theta, r_max=B + 2 * dr)
    grid = dm.Grid(msh)
    radius = lambda x: np.hypot(x[0], x[1])  # noqa: E731
    tol = 1e-6 * A
    particles = dm.seed(grid, STEEL, ppc=ppc, where=lambda x: radius(x) < B + tol)
    bore = grid.nodes_where(lambda x: np.abs(radius(x) - A) < tol)
    e_r = grid.node_x[bore, :2] / A
    v_bore = speed * STEEL.p_wave_speed()
    bcs = [
        dm.SlipBC(grid.nodes_where(lambda x: np.abs(x[1]) < tol), normal=(0, 1)),
        dm.SlipBC(grid.nodes_where(lambda x: np.abs(x[0]) < tol), normal=(1, 0)),
        dm.VelocityBC(bore, velocity=v_bore * e_r),
    ]
    outer = grid.nodes_where(lambda x: (np.abs(x[0] - B) < tol) & (np.abs(x[1]) < tol))
    solver = dm.Solver(grid, particles, STEEL, bcs=bcs, damping=damping)
    n_steps = records * math.ceil(u_max / (v_bore * solver.dt) / records)
    path = {"u_a": [0.0], "u_b": [0.0], "p": [0.0]}
    u_b, force = 0.0, 0.0
    start = time.perf_counter()
    for k in range(1, n_steps + 1):
        solver.step()
        u_b += solver.dt * grid.velocity.x.array.reshape(-1, 2)[outer, 0].sum()
        force += (grid.f_contact.x.array.reshape(-1, 2)[bore] * e_r).sum()
        if k % (n_steps // records) == 0:
            path["u_a"].append(v_bore * solver.time)
            path["u_b"].append(float(u_b))
            path["p"].append(force / (n_steps // records) / (0.5 * np.pi * A))
            force = 0.0
            if progress:
                print(f"MPM: u_a = {1e3 * path['u_a'][-1]:.4f} mm  u_b = {1e3 * u_b:.5f} mm  "
                      f"p = {path['p'][-1] / 1e6:7.2f} MPa")  # fmt: skip
    u_a, p, u_b = (np.array(path[k]) for k in ("u_a", "p", "u_b"))
    # Fully plastic from u_a ~ 2 u_b(p_lim) = 0.47 mm (Hill); the plateau is the mean beyond.
    plateau = u_a >= 0.6 * u_max
    p_grid = np.linspace(0.0, P_LIMIT, 400)[:-1]
    p_hill = np.interp(u_b, [outer_displacement(x) for x in p_grid], p_grid, right=P_LIMIT)
    return {
        "p_limit": float(P_LIMIT),
        "p_plateau": float(p[plateau].mean()),
        "limit_error": float(p[plateau].mean() / P_LIMIT - 1.0),
        "plateau_spread": float((p[plateau].max() - p[plateau].min()) / P_LIMIT),
        "path_error": float(np.max(np.abs(p[~plateau] - p_hill[~plateau])) / P_LIMIT),
        "particles": len(particles),
        "steps": n_steps,
        "run_seconds": time.perf_counter() - start,
        "path": path,
    }


#: The mesh and time-step study: cells across the wall x along the quarter (the FE mesh; the
#: MPM's grid is it continued beyond b), and the MPM's loading speed over the p-wave speed (the
#: bore moves ``u_max`` in proportionally more steps).
STUDY = {"mesh": ((5, 10), (10, 20), (20, 40)), "speed": (3e-5, 1.5e-5)}
#: The head of the study's table (:func:`study_lines`).
STUDY_HEAD = (
    "| cells (across x along) | FE: p_max / p_lim - 1 | MPM speed / c_p | MPM: plateau / p_lim - 1 "
    "| plateau spread | p(u_b) before it vs Hill | particles | steps |\n"
    "|---|---|---|---|---|---|---|---|"
)


def study(mesh_study=None, progress=True) -> list[dict]:
    """The limit pressure's dependence on the mesh (FE and MPM) and on the MPM's loading speed.

    ``mesh_study``: as :data:`STUDY` (its default). One row per mesh: ``n_radial``, ``n_theta``,
    the FE's ``fe_limit_error`` and, per speed, the MPM's ``limit_error``, ``plateau_spread``,
    ``path_error``, ``particles`` and ``steps`` (relative to ``p_lim``).
    """
    mesh_study = STUDY if mesh_study is None else mesh_study
    rows = []
    for n_radial, n_theta in mesh_study["mesh"]:
        fe = run(n_radial, n_theta, progress=False)
        row = {"n_radial": n_radial, "n_theta": n_theta, "fe_limit_error": fe["limit_error"], "mpm": []}
        for speed in mesh_study["speed"]:
            mpm = run_mpm(n_radial, n_theta, speed=speed, progress=False)
            keys = ("limit_error", "plateau_spread", "path_error", "particles", "steps")
            row["mpm"].append({"speed": speed, **{k: mpm[k] for k in keys}})
        rows.append(row)
        if progress:
            print("\n".join(study_lines(row)), flush=True)
    return rows


def study_lines(row) -> list[str]:
    """One mesh of :func:`study` as rows of :data:`STUDY_HEAD`'s table, one per MPM speed."""
    pct = lambda x: f"{100 * x:+.2f} %"  # noqa: E731
    lines = []
    for k, m in enumerate(row["mpm"]):
        head = f"| {row['n_radial']} x {row['n_theta']} | {pct(row['fe_limit_error'])}" if k == 0 else "| |"
        lines.append(
            f"{head} | {m['speed']:g} | {pct(m['limit_error'])} | {100 * m['plateau_spread']:.1f} % "
            f"| {100 * m['path_error']:.1f} % | {m['particles']} | {m['steps']} |"
        )
    return lines


def save(folder, fe, mpm):
    """Write both results (JSON) and their plot into ``folder``."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "cylinder.json").write_text(json.dumps({"fe": fe, "mpm": mpm}, indent=1))
    plot(fe, folder / "cylinder.png", mpm)


def plot(result, path, mpm=None):
    """Pressure against outer displacement and the plastic radius, FE and Hill's solution."""
    p = np.linspace(0.0, P_LIMIT * 0.9999, 200)
    with figure(path, ncols=2, figsize=(10, 4)) as (ax1, ax2):
        ax1.plot([1e3 * outer_displacement(x) for x in p], p / 1e6, "k-", label="Hill (plane strain)")
        ax1.plot(
            1e3 * np.array(result["path"]["u_b"]), np.array(result["path"]["p"]) / 1e6, "o", label="FE, P2"
        )
        if mpm is not None:
            ax1.plot(1e3 * np.array(mpm["path"]["u_b"]), np.array(mpm["path"]["p"]) / 1e6, "s-", ms=3,
                     label="MPM, quasi-static")  # fmt: skip
        ax1.axhline(P_LIMIT / 1e6, color="gray", ls="--", label="limit 2k ln(b/a)")
        ax1.set(xlabel="outer displacement u_b [mm]", ylabel="internal pressure p [MPa]")
        ax1.legend()
        ax2.plot(p / 1e6, [1e3 * plastic_radius(x) for x in p], "k-", label="Hill")
        ax2.plot(
            np.array(result["path"]["p"]) / 1e6,
            1e3 * np.array(result["path"]["c"]),
            "o",
            label="FE (cell centres)",
        )
        ax2.set(xlabel="internal pressure p [MPa]", ylabel="plastic radius c [mm]")
        ax2.legend()


def main():
    """The command line: the FE run and the MPM run, or the mesh and time-step study."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0].lstrip("# "))
    parser.add_argument("--quick", action="store_true", help="coarse mesh, large load steps")
    parser.add_argument("--output", type=Path, default=Path("results/cylinder"))
    parser.add_argument(
        "--study",
        action="store_true",
        help="the limit pressure on three meshes, the MPM at two loading speeds",
    )
    args = parser.parse_args()
    if args.study:
        print(STUDY_HEAD)
        rows = study({"mesh": ((5, 10),), "speed": (3e-5,)} if args.quick else None)
        args.output.mkdir(parents=True, exist_ok=True)
        (args.output / "cylinder_study.json").write_text(json.dumps(rows, indent=1))
        return
    res = run(5, 10, 0.1) if args.quick else run()
    mpm = run_mpm(5, 10) if args.quick else run_mpm()
    save(args.output, res, mpm)
    print(f"limit pressure: FE {res['p_max'] / 1e6:.2f} MPa, exact {P_LIMIT / 1e6:.2f} MPa "
          f"({100 * res['limit_error']:+.2f} %)" + ("" if res["collapsed"] else "; NO COLLAPSE"))  # fmt: skip
    print(
        f"outer displacement vs Hill: max error {100 * res['u_b_error']:.2f} %; plastic radius max error "
        f"{100 * res['c_error']:.1f} % of a; {res['newton_mean']:.1f} Newton iterations per step, "
        f"{res['solve_seconds']:.1f} s"
    )
    print(
        f"MPM: plateau {mpm['p_plateau'] / 1e6:.2f} MPa ({100 * mpm['limit_error']:+.2f} %, spread "
        f"{100 * mpm['plateau_spread']:.1f} % of p_lim); p against Hill's p(u_b) before it within "
        f"{100 * mpm['path_error']:.1f} % of p_lim; {mpm['particles']} particles, {mpm['steps']} steps, "
        f"{mpm['run_seconds']:.1f} s"
    )


if __name__ == "__main__":
    main()
