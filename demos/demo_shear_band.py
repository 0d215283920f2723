"""# Shear band in a granular layer: does its width depend on the mesh?

The paper's central claim is that the non-local viscoplastic strain rate makes the width of
shear bands a property of the material (the radius r) rather than of the mesh. This demo
checks it on the simplest specimen that forms one band: a layer of the paper's sand, height
H, in a direct-shear box: the bottom plate and the lower parts of the side walls are fixed,
the top plate and the upper parts move at the speed V.

The layer starts under an isotropic pressure p0. In a weak layer of fixed thickness at
mid-height (the same on every mesh, so that only the mesh changes between runs) the
horizontal and out-of-plane stresses are 10 % lower (the imperfection): that layer has a lower
pressure and so a lower strength, q = m p, yields first, and the band forms along it. The side
walls impose the jump of velocity at mid-height; material passes through the walls into a
sink. The profiles are taken over the middle half of the width.

Three meshes, h, h/2 and h/4, each with the local model (r = 0) and the non-local one. Over
the second half of the run three profiles across the layer are measured: the applied
viscoplastic strain, the non-local rate e_vp_bar (time-averaged), both by their full width
at half maximum (FWHM), and the mean horizontal velocity, by the distance over which it
rises from 10 % to 90 % of the plate speed.

    python demos/demo_shear_band.py [--cells 10 20 40] [--radius 4e-3] [--weight wendland --law overstress]
                                    [--output results/shear_band]
"""

import argparse
import json
import time
from pathlib import Path

import dolfin_mpm as dm  # import first: it loads DOLFINx's libraries

# isort: split
import numpy as np
from dolfinx import mesh
from mpi4py import MPI

from dolfin_mpm.post.measure import bin_sums, fwhm, rise_width
from dolfin_mpm.post.plotting import figure

H = 0.02  # layer height and width [m]
SAND = {"E": 1e6, "nu": 0.3, "rho": 1500.0, "phi": 30.0, "gamma": 1e3, "N": 1.0}  # the paper's


def run(
    cells, radius, weight="cubic", shear=0.05, rate=5.0, p0=1e4, imperfection=0.1, weak=2e-3, progress=False,
    law="max",
):  # fmt: skip
    """Shear a layer of ``cells`` x ``cells`` squares (two triangles each) to the strain ``shear``.

    Args:
        cells: cells across the layer height H.
        radius: non-local radius r [m]; 0 for the local model.
        weight: the averaging weight.
        shear: imposed shear strain at the end, ``rate * t_end``.
        rate: imposed shear rate [1/s] (plate speed / H).
        p0: initial pressure [Pa].
        imperfection: relative drop of sigma_xx and sigma_zz in the weak layer.
        weak: thickness of the weak layer [m], centred at mid-height.
        law: the non-local law (:class:`dolfin_mpm.NonlocalLaw` or its name).

    Returns:
        dict with the profiles across the layer (bin centres ``y`` relative to mid-height)
        and the measured widths [m].

    """
    comm = MPI.COMM_WORLD
    if comm.size > 1:
        raise RuntimeError("this demo bins particles on one rank; run it serially")
    h = H / cells
    # ## Grid, material and particles under the initial stress
    # Two spare columns of cells on each side: material pushed through a wall ends in a sink.
    grid = dm.Grid(
        mesh.create_rectangle(
            comm,
            [np.array([-2 * h, 0.0]), np.array([H + 2 * h, H])],
            [cells + 4, cells],
            mesh.CellType.triangle,
        )
    )
    sand = dm.DruckerPragerViscoplastic(**SAND)
    P = dm.seed(grid, sand, ppc=4, where=lambda x: (x[0] > 0.0) & (x[0] < H))
    P.sigma[:] = -p0 * np.eye(3)
    y_mid = 0.5 * H
    in_weak = np.abs(P.x[:, 1] - y_mid) < 0.5 * weak
    P.sigma[in_weak, 0, 0] *= 1.0 - imperfection
    P.sigma[in_weak, 2, 2] *= 1.0 - imperfection

    # ## The box: bottom plate and lower walls fixed, top plate and upper walls at V = rate H
    # (the wall nodes at mid-height at V / 2)
    V = rate * H
    sides = grid.nodes_where(lambda x: np.isclose(x[0], 0.0) | np.isclose(x[0], H))
    y_side = grid.node_x[sides, 1]
    side_v = np.c_[V * np.where(np.isclose(y_side, y_mid), 0.5, y_side > y_mid), np.full(len(sides), np.nan)]
    bcs = [
        dm.VelocityBC(sides, side_v),
        dm.VelocityBC(grid.nodes_where(lambda x: np.isclose(x[1], 0.0)), (0.0, 0.0)),
        dm.VelocityBC(grid.nodes_where(lambda x: np.isclose(x[1], H)), (V, 0.0)),
    ]
    averaging = dm.NonlocalAverage(radius, weight, law=law) if radius > 0 else None
    beyond_walls = dm.Sink("beyond walls", region=lambda x: (x[0] < -0.5 * h) | (x[0] > H + 0.5 * h))
    solver = dm.Solver(grid, P, sand, bcs=bcs, averaging=averaging, sinks=[beyond_walls])

    # ## Time loop; the second half accumulates the band's profiles
    t_end = shear / rate
    n_steps = int(np.ceil(t_end / solver.dt))
    eps0 = None
    t0 = time.perf_counter()
    for k in range(1, n_steps + 1):
        solver.step()
        if k == n_steps // 2:
            eps0, x_mid, t_mid = P.state["eps_vp"].copy(), P.x[:, 0].copy(), solver.time
            e_bar_sum = np.zeros(len(P))
            ids = P.id.copy()
        if eps0 is not None:  # accumulate over the particles present since mid-run
            e_bar_sum[np.searchsorted(ids, P.id)] += P.state["eps_vp_rate_nonlocal"] * solver.dt
        if progress and k % 200 == 0:
            print(f"  h = {1e3 * h:.3g} mm, r = {1e3 * radius:.3g} mm: step {k}/{n_steps}", flush=True)
    elapsed = time.perf_counter() - t0

    # ## Profiles across the layer over the middle half of the width
    middle = (P.x[:, 0] > 0.25 * H) & (P.x[:, 0] < 0.75 * H)
    edges = np.arange(0.0, H + 1e-12, 0.5 * h)
    y = 0.5 * (edges[1:] + edges[:-1])

    def profile(values):
        count, total = bin_sums(P.x[middle, 1], edges, values[middle])
        return total / np.maximum(count, 1)

    since_mid = np.searchsorted(ids, P.id)
    eps = profile(P.state["eps_vp"] - eps0[since_mid])
    e_bar = profile(e_bar_sum[since_mid])
    vx = profile((P.x[:, 0] - x_mid[since_mid]) / (solver.time - t_mid))  # mean velocity
    fp = solver.fixed_point
    return {
        "h": h,
        "radius": radius,
        "y": y - y_mid,
        "eps_vp": eps,
        "e_vp_bar": e_bar,
        "vx": vx / V,
        "width_eps_vp": fwhm(y, eps),
        "width_e_vp_bar": fwhm(y, e_bar),
        "width_velocity": rise_width(y, vx / V),
        "particles": len(P),
        "steps": n_steps,
        "seconds": elapsed,
        "mean_iterations": fp["iterations"] / fp["steps"] if fp["steps"] else 1.0,
        "max_iterations": fp["max_iterations"],
        "unconverged": fp["unconverged"],
    }


def study(cells=(10, 20, 40), radius=4e-3, weight="cubic", progress=True, **kwargs):
    """Local and non-local runs on each mesh; returns ``{"local": [...], "nonlocal": [...]}``."""
    return {
        name: [run(n, r, weight, progress=progress, **kwargs) for n in cells]
        for name, r in (("local", 0.0), ("nonlocal", radius))
    }


def table(results) -> str:
    lines = [
        "model     h [mm]  FWHM eps_vp [mm]  FWHM e_vp_bar [mm]  velocity 10-90% [mm]  iterations  time [s]"
    ]
    for name, runs in results.items():
        for r in runs:
            lines.append(
                f"{name:8s} {1e3 * r['h']:7.3f} {1e3 * r['width_eps_vp']:17.2f} "
                f"{1e3 * r['width_e_vp_bar']:19.2f} {1e3 * r['width_velocity']:21.2f} "
                f"{r['mean_iterations']:11.2f} {r['seconds']:9.1f}"
            )
    for name, runs in results.items():
        spread = [
            f"{key} {100 * (max(w) / min(w) - 1):.0f} %"
            for key in ("width_eps_vp", "width_e_vp_bar", "width_velocity")
            for w in [[r[key] for r in runs]]
        ]
        lines.append(f"{name}: largest / smallest width - 1 across the meshes: " + ", ".join(spread))
    return "\n".join(lines)


def plot(results, path: Path) -> None:
    with figure(path, dpi=130, ncols=3, figsize=(13, 4.2), sharey=True) as axes:
        labels = ("viscoplastic strain, 2nd half", "time-averaged e_vp_bar", "mean v_x / V, 2nd half")
        for ax, key, label in zip(axes, ("eps_vp", "e_vp_bar", "vx"), labels):
            for name, style in (("local", "--"), ("nonlocal", "-")):
                for r in results[name]:
                    f = r[key] / (r[key].max() if key != "vx" else 1.0)
                    ax.plot(f, 1e3 * r["y"], style, label=f"{name}, h = {1e3 * r['h']:.2g} mm")
            ax.set_xlabel(label + (" (normalised)" if key != "vx" else ""))
            ax.grid(alpha=0.3)
        axes[0].set_ylabel("distance from mid-height [mm]")
        axes[0].set_ylim(-6, 6)
        axes[-1].legend(fontsize=7)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0].lstrip("# "))
    parser.add_argument("--cells", type=int, nargs="+", default=[10, 20, 40], help="cells across H")
    parser.add_argument("--radius", type=float, default=4e-3, help="non-local radius r [m]")
    parser.add_argument("--weight", default="cubic", choices=list(dm.averaging.WEIGHTS))
    parser.add_argument("--law", default="max", choices=list(dm.averaging.LAWS), help="the non-local law")
    parser.add_argument("--output", type=Path, default=Path("results/shear_band"))
    args = parser.parse_args()
    args.output.mkdir(parents=True, exist_ok=True)
    results = study(args.cells, args.radius, args.weight, law=args.law)
    text = table(results)
    print(text)
    (args.output / "widths.txt").write_text(text + "\n")
    plain = {k: [{n: (v.tolist() if isinstance(v, np.ndarray) else v) for n, v in r.items()} for r in rs]
             for k, rs in results.items()}  # fmt: skip
    (args.output / "shear_band.json").write_text(json.dumps(plain, indent=1))
    plot(results, args.output / "shear_band.png")
    print(f"wrote {args.output}/widths.txt, shear_band.json, shear_band.png")


if __name__ == "__main__":
    main()
