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
        [--output results/footing]
"""

import argparse
import json
from pathlib import Path

import dolfin_mpm as dm  # import first: it loads DOLFINx's libraries

# isort: split
import numpy as np
from dolfinx import mesh
from mpi4py import MPI

from dolfin_mpm.fe import ConvergenceError, QuasiStatic
from dolfin_mpm.plotting import figure

B, L = 1.0, 5.0  # footing width, size of the half model [m]
C, E, NU = 100e3, 100e6, 0.3  # cohesion [Pa], soil stiffness
PHI = 30.0  # friction angle of the frictional soil [deg]
SOILS = ("cohesive", "frictional", "frictional-associated")
SETTLEMENT = {"cohesive": 0.05, "frictional": 0.05, "frictional-associated": 0.3}  # footing push [m]


def soil(kind):
    """The soil model and its analytical bearing-capacity factor N_c."""
    if kind == "cohesive":
        return dm.VonMises(E=E, nu=NU, rho=1.0, sigma_y=np.sqrt(3.0) * C), 2.0 + np.pi
    if kind in ("frictional", "frictional-associated"):
        t = np.tan(np.radians(PHI))
        n_q = np.exp(np.pi * t) * np.tan(np.radians(45.0 + PHI / 2.0)) ** 2
        if kind == "frictional":
            mat = dm.DruckerPragerViscoplastic(E=E, nu=NU, rho=1.0, phi=PHI, gamma=np.inf, c=C)
        else:
            mat = dm.MohrCoulombDruckerPrager(E=E, nu=NU, rho=1.0, phi=PHI, c=C)
        return mat, (n_q - 1.0) / t
    raise ValueError(f"soil must be one of {SOILS}, got {kind!r}")


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


def run(kind="cohesive", n=32, settlement=None, steps=25, output=None, progress=True):
    """Push the footing down by ``settlement`` [m] (default ``SETTLEMENT[kind]``); returns the
    load–settlement curve and q_u."""
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
    if output is not None:
        output = Path(output)
        output.mkdir(parents=True, exist_ok=True)
        (output / f"footing_{kind}.json").write_text(json.dumps(result, indent=1))
        plot([result], output / f"footing_{kind}.png")
    return result


def plot(results, path):
    """Load–settlement curves against the analytical bearing capacities."""
    with figure(path, figsize=(6, 4)) as ax:
        for res in results:
            line = ax.plot(1e3 * np.array(res["curve"]["settlement"]), np.array(res["curve"]["q"]) / C,
                           "o-", ms=3, label=f"FE, {res['soil']}")  # fmt: skip
            ax.axhline(res["N_c"], color=line[0].get_color(), ls="--", label=f"N_c = {res['N_c']:.2f}")
        ax.set(xlabel="settlement [mm]", ylabel="mean footing pressure q / c")
        ax.legend()


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0].lstrip("# "))
    parser.add_argument("--soil", default="cohesive", choices=SOILS)
    parser.add_argument("--quick", action="store_true", help="coarse mesh, few steps")
    parser.add_argument("--output", type=Path, default=Path("results/footing"))
    args = parser.parse_args()
    res = (
        run(args.soil, 12, steps=10, output=args.output) if args.quick else run(args.soil, output=args.output)
    )
    print(
        f"{args.soil}: q_u / c = {res['q_u_over_c']:.3f} "
        f"(N_c = {res['N_c']:.3f}, {100 * res['error']:+.1f} %),"
        f" last steps {100 * res['plateau']:+.2f} %; {res['dofs']} dofs, Newton {res['newton_mean']:.1f} "
        f"mean / {res['newton_max']} max, {res['solve_seconds']:.1f} s"
    )
