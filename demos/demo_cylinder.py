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
from pathlib import Path

import dolfin_mpm as dm  # import first: it loads DOLFINx's libraries

# isort: split
import numpy as np
from dolfinx import mesh
from mpi4py import MPI
from scipy.optimize import brentq

from dolfin_mpm.fe import ConvergenceError, QuasiStatic
from dolfin_mpm.plotting import figure

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


def quarter_annulus(n_radial, n_theta):
    """Triangle mesh of ``a <= r <= b``, ``0 <= theta <= pi/2``: a rectangle in (r, theta) mapped."""
    msh = mesh.create_rectangle(
        MPI.COMM_WORLD, [np.array([A, 0.0]), np.array([B, 0.5 * np.pi])], [n_radial, n_theta],
        mesh.CellType.triangle, diagonal=mesh.DiagonalType.crossed,
    )  # fmt: skip
    r, theta = msh.geometry.x[:, 0].copy(), msh.geometry.x[:, 1].copy()
    msh.geometry.x[:, 0], msh.geometry.x[:, 1] = r * np.cos(theta), r * np.sin(theta)
    return msh


def run(n_radial=10, n_theta=20, step=0.05, output=None, progress=True):
    """Load the tube to collapse; returns the load path and the errors against the analytic solution."""
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
    if output is not None:
        output = Path(output)
        output.mkdir(parents=True, exist_ok=True)
        (output / "cylinder.json").write_text(json.dumps(result, indent=1))
        plot(result, output / "cylinder.png")
    return result


def plot(result, path):
    """Pressure against outer displacement and the plastic radius, FE and Hill's solution."""
    p = np.linspace(0.0, P_LIMIT * 0.9999, 200)
    with figure(path, ncols=2, figsize=(10, 4)) as (ax1, ax2):
        ax1.plot([1e3 * outer_displacement(x) for x in p], p / 1e6, "k-", label="Hill (plane strain)")
        ax1.plot(
            1e3 * np.array(result["path"]["u_b"]), np.array(result["path"]["p"]) / 1e6, "o", label="FE, P2"
        )
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


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0].lstrip("# "))
    parser.add_argument("--quick", action="store_true", help="coarse mesh, large load steps")
    parser.add_argument("--output", type=Path, default=Path("results/cylinder"))
    args = parser.parse_args()
    res = run(5, 10, 0.1, args.output) if args.quick else run(output=args.output)
    print(f"limit pressure: FE {res['p_max'] / 1e6:.2f} MPa, exact {P_LIMIT / 1e6:.2f} MPa "
          f"({100 * res['limit_error']:+.2f} %)" + ("" if res["collapsed"] else "; NO COLLAPSE"))  # fmt: skip
    print(
        f"outer displacement vs Hill: max error {100 * res['u_b_error']:.2f} %; plastic radius max error "
        f"{100 * res['c_error']:.1f} % of a; {res['newton_mean']:.1f} Newton iterations per step, "
        f"{res['solve_seconds']:.1f} s"
    )
