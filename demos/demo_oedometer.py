"""# Oedometer: the K0 branch and the active limit of the Drucker–Prager soil

A benchmark of the reference finite-element solver with the paper's Drucker–Prager cone
(rate-independent limit, g = q) and a cohesion c. A soil sample between rigid, frictionless
side walls is compressed from the top: the lateral strain is zero, and the horizontal stress
follows the vertical one (compression positive, sigma_h = sigma_zz by symmetry)

- elastically with the at-rest ratio  sigma_h / sigma_v = K0 = nu / (1 - nu),
- on the cone q = m (p + c cot phi) once it is reached, where p = (sigma_v + 2 sigma_h) / 3
  and q = sigma_v - sigma_h give  sigma_h = ((3 - m) sigma_v - 3 m c cot phi) / (3 + 2 m):
  the ratio tends to the active limit K_a = (3 - m) / (3 + 2 m).

    python demos/demo_oedometer.py [--output results/oedometer]
"""

import argparse
import json
import math
from pathlib import Path

import dolfin_mpm as dm  # import first: it loads DOLFINx's libraries

# isort: split
import numpy as np
from dolfinx import mesh
from mpi4py import MPI

from dolfin_mpm.fe import QuasiStatic
from dolfin_mpm.post.plotting import figure

SOIL = dm.DruckerPragerViscoplastic(E=10e6, nu=0.3, rho=1.0, phi=20.0, gamma=np.inf, c=10e3)
K0 = SOIL.nu / (1 - SOIL.nu)
K_ACTIVE = (3 - SOIL.m) / (3 + 2 * SOIL.m)


def horizontal_stress(sigma_v):
    """Analytical sigma_h [Pa] for vertical stresses ``sigma_v`` [Pa] (compression positive)."""
    a, m = SOIL.tension_limit, SOIL.m
    sigma_v_yield = m * a / ((1 - K0) - m * (1 + 2 * K0) / 3)
    plastic = ((3 - m) * sigma_v - 3 * m * a) / (3 + 2 * m)
    return np.where(sigma_v <= sigma_v_yield, K0 * sigma_v, plastic), sigma_v_yield


def run(strain=0.03, steps=30, progress=True):
    """Compress a 1 m sample by ``strain`` with the FE solver; returns the stress path and its error."""
    msh = mesh.create_rectangle(MPI.COMM_WORLD, [np.zeros(2), np.ones(2)], [2, 2], mesh.CellType.triangle)
    fe = QuasiStatic(msh, SOIL, degree=2)
    side = mesh.locate_entities_boundary(msh, 1, lambda x: np.isclose(x[0], 0.0) | np.isclose(x[0], 1.0))
    fe.fix(side, component=0)
    fe.fix(mesh.locate_entities_boundary(msh, 1, lambda x: np.isclose(x[1], 0.0)), component=1)
    fe.fix(mesh.locate_entities_boundary(msh, 1, lambda x: np.isclose(x[1], 1.0)), component=1, value=-strain)

    path = {"sigma_v": [0.0], "sigma_h": [0.0], "sigma_z": [0.0]}

    def record(fe):
        s = -fe.sigma.mean(axis=0)  # uniform state; compression positive
        path["sigma_v"].append(s[1, 1])
        path["sigma_h"].append(s[0, 0])
        path["sigma_z"].append(s[2, 2])

    fe.advance(np.linspace(0.0, 1.0, steps + 1)[1:], min_step=1e-4, on_step=record)
    sigma_v, sigma_h = np.array(path["sigma_v"]), np.array(path["sigma_h"])
    exact, sigma_v_yield = horizontal_stress(sigma_v)
    result = {
        "K0": K0,
        "K0_fe": float(sigma_h[1] / sigma_v[1]),
        "K_active": K_ACTIVE,
        "K_final_fe": float(sigma_h[-1] / sigma_v[-1]),
        "sigma_v_yield": float(sigma_v_yield),
        "error": float(np.max(np.abs(sigma_h - exact)) / sigma_v.max()),
        "sigma_z_equals_sigma_h": float(np.max(np.abs(np.array(path["sigma_z"]) - sigma_h)) / sigma_v.max()),
        "newton_mean": float(np.mean([s.iterations for s in fe.history])),
        "solve_seconds": float(sum(s.seconds for s in fe.history)),
        "path": path,
    }
    if progress:
        print(
            f"K0: FE {result['K0_fe']:.6f}, exact {K0:.6f}; final ratio {result['K_final_fe']:.4f} -> active "
            f"limit {K_ACTIVE:.4f}; max |sigma_h - exact| / sigma_v,max = {result['error']:.1e}"
        )
    return result


def run_mpm(strain=0.03, ppc=4, speed=1e-4, damping=0.1, records=30):
    """The same sample with the explicit MPM, compressed quasi-statically; returns its stress path.

    A 1 m column on 2 x 2 squares of four triangles; the top nodes move down at ``speed`` times
    the p-wave speed until the sample is shortened by ``strain``. The stresses are the
    particle means at ``records`` moments. The MPM's strain is logarithmic, the FE's small:
    the stress path sigma_h(sigma_v) is the same for both.
    """
    msh = mesh.create_rectangle(
        MPI.COMM_WORLD, [np.zeros(2), np.ones(2)], [2, 2], mesh.CellType.triangle,
        diagonal=mesh.DiagonalType.crossed,
    )  # fmt: skip
    grid = dm.Grid(msh)
    particles = dm.seed(grid, SOIL, ppc=ppc)
    v = speed * SOIL.p_wave_speed()
    bcs = [
        dm.SlipBC(grid.nodes_where(lambda x: np.isclose(x[0], 0.0) | np.isclose(x[0], 1.0)), normal=(1, 0)),
        dm.SlipBC(grid.nodes_where(lambda x: np.isclose(x[1], 0.0)), normal=(0, 1)),
        dm.VelocityBC(grid.nodes_where(lambda x: np.isclose(x[1], 1.0)), velocity=(np.nan, -v)),
    ]
    solver = dm.Solver(grid, particles, SOIL, bcs=bcs, damping=damping)
    every = math.ceil(-np.log(1.0 - strain) / (v * solver.dt) / records)
    path = {"sigma_v": [0.0], "sigma_h": [0.0]}
    for k in range(1, every * records + 1):
        solver.step()
        if k % every == 0:
            s = -particles.sigma.mean(axis=0)
            path["sigma_v"].append(s[1, 1])
            path["sigma_h"].append(s[0, 0])
    sigma_v, sigma_h = np.array(path["sigma_v"]), np.array(path["sigma_h"])
    return {
        "K0_mpm": float(sigma_h[1] / sigma_v[1]),
        "K_final_mpm": float(sigma_h[-1] / sigma_v[-1]),
        "error": float(np.max(np.abs(sigma_h - horizontal_stress(sigma_v)[0])) / sigma_v.max()),
        "particles": len(particles),
        "steps": every * records,
        "path": path,
    }


def save(folder, fe, mpm):
    """Write both results (JSON) and their plot into ``folder``."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "oedometer.json").write_text(json.dumps({"fe": fe, "mpm": mpm}, indent=1))
    plot(fe, folder / "oedometer.png", mpm)


def plot(result, path, mpm=None):
    """Stress path sigma_h against sigma_v: FE, MPM and analytic."""
    sv = np.linspace(0.0, max(result["path"]["sigma_v"]), 200)
    with figure(path, figsize=(5, 4)) as ax:
        ax.plot(sv / 1e3, horizontal_stress(sv)[0] / 1e3, "k-", label="K0 branch, then the cone")
        for res, style, label in ((result, "o", "FE"), (mpm, "x", "MPM")):
            if res is not None:
                path_kpa = {k: np.array(v) / 1e3 for k, v in res["path"].items()}
                ax.plot(path_kpa["sigma_v"], path_kpa["sigma_h"], style, label=label)
        ax.plot(sv / 1e3, K_ACTIVE * sv / 1e3, "k:", label=f"K_a = {K_ACTIVE:.3f}")
        ax.set(xlabel="vertical stress [kPa]", ylabel="horizontal stress [kPa]")
        ax.legend()


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0].lstrip("# "))
    parser.add_argument("--output", type=Path, default=Path("results/oedometer"))
    fe, mpm = run(), run_mpm()
    save(parser.parse_args().output, fe, mpm)
    print(f"MPM: K0 {mpm['K0_mpm']:.6f}; max |sigma_h - exact| / sigma_v,max = {mpm['error']:.1e} "
          f"({mpm['steps']} steps)")  # fmt: skip
