"""# Finite-element benchmarks: one table against the analytical solutions

Runs the cylinder, footing and oedometer demos and writes their figures and one table
(benchmark | analytic | FE | error | MPM) into a Markdown report.

    python demos/fe_benchmarks.py [--quick] [--report docs/benchmarks.md]
"""

import argparse
import sys
import time
from pathlib import Path

import dolfin_mpm  # noqa: F401  (import first: it loads DOLFINx's libraries)

# isort: split
sys.path.insert(0, str(Path(__file__).parent))
import demo_cylinder
import demo_footing
import demo_oedometer


def run_all(quick=False):
    """Each benchmark's result and its wall time [s]."""
    cylinder = (5, 10, 0.1) if quick else ()
    footing = {"n": 12, "steps": 10} if quick else {}
    runs = {
        "cylinder": lambda: demo_cylinder.run(*cylinder, progress=False),
        "footing_cohesive": lambda: demo_footing.run("cohesive", **footing, progress=False),
        "footing_frictional": lambda: demo_footing.run("frictional", **footing, progress=False),
        "footing_associated": lambda: demo_footing.run("frictional-associated", **footing, progress=False),
        "oedometer": lambda: demo_oedometer.run(progress=False),
    }
    out = {}
    for name, fn in runs.items():
        start = time.perf_counter()
        out[name] = fn()
        out[name]["seconds"] = time.perf_counter() - start
        print(f"{name}: {out[name]['seconds']:.1f} s", flush=True)
    return out


def report(res, path: Path, quick: bool):
    """Write the table and the figures (into ``images/`` beside ``path``)."""
    images = path.parent / "images"
    images.mkdir(parents=True, exist_ok=True)
    demo_cylinder.plot(res["cylinder"], images / "fe_cylinder.png")
    footings = [res["footing_cohesive"], res["footing_frictional"], res["footing_associated"]]
    demo_footing.plot(footings, images / "fe_footing.png")
    demo_oedometer.plot(res["oedometer"], images / "fe_oedometer.png")
    cyl, oed, (coh, fri, aso) = res["cylinder"], res["oedometer"], footings
    mpa, pct = 1e-6, lambda x: f"{100 * x:+.2f} %"
    fri_fe, fri_err = f"{fri['q_u_over_c']:.2f}", pct(fri["error"])
    if fri["failed_at"] is not None:  # no plateau: the last value is no collapse load
        fri_fe = (
            f"Newton stopped at {1e3 * fri['failed_at']:.1f} mm settlement, q / c = {fri['q_u_over_c']:.2f}"
        )
        fri_err = "no collapse load"
    rows = [
        ("cylinder: limit pressure [MPa]", f"{cyl['p_limit'] * mpa:.2f}", f"{cyl['p_max'] * mpa:.2f}",
         pct(cyl["limit_error"])),
        ("cylinder: outer displacement along the path", "Hill", "", f"max {100 * cyl['u_b_error']:.2f} %"),
        ("cylinder: plastic radius along the path", "Hill", "", f"max {100 * cyl['c_error']:.1f} % of a"),
        ("footing, cohesive: q_u / c", f"{coh['N_c']:.3f}", f"{coh['q_u_over_c']:.3f}", pct(coh["error"])),
        ("footing, phi = 30 deg, DP matched to MC in plane strain, associated: q_u / c", f"{aso['N_c']:.2f}",
         f"{aso['q_u_over_c']:.2f}", pct(aso["error"])),
        ("footing, phi = 30 deg, the paper's DP (m = 1.029, g = q): q_u / c",
         f"{fri['N_c']:.2f} (MC, associated)", fri_fe, fri_err),
        ("oedometer: K0", f"{oed['K0']:.6f}", f"{oed['K0_fe']:.6f}", f"{oed['K0_fe'] / oed['K0'] - 1:+.1e}"),
        ("oedometer: stress path (K0, then the cone)", "exact", "", f"max {oed['error']:.1e} of sigma_v"),
        ("oedometer: ratio at 3 % strain -> K_a", f"{oed['K_active']:.4f}", f"{oed['K_final_fe']:.4f}", ""),
    ]  # fmt: skip
    cost = [
        ("cylinder", cyl["newton_mean"], cyl["solve_seconds"], cyl["seconds"]),
        ("footing, cohesive", coh["newton_mean"], coh["solve_seconds"], coh["seconds"]),
        ("footing, frictional (paper's DP)", fri["newton_mean"], fri["solve_seconds"], fri["seconds"]),
        ("footing, frictional (associated)", aso["newton_mean"], aso["solve_seconds"], aso["seconds"]),
        ("oedometer", oed["newton_mean"], oed["solve_seconds"], oed["seconds"]),
    ]
    lines = [
        "# Finite-element benchmarks",
        "",
        "The reference solver (`dolfin_mpm.fe.QuasiStatic`: small strain, plane strain, P2 "
        "displacements, stresses at 3 points per triangle, Newton with the consistent tangent of "
        "the return mapping the MPM uses) against analytical solutions. "
        + ("Quick variants (coarse meshes). " if quick else "")
        + "Regenerate with",
        "",
        f"    python demos/fe_benchmarks.py {'--quick ' if quick else ''}--report {path.as_posix()}",
        "",
        "| benchmark | analytic | FE | error | MPM |",
        "|---|---|---|---|---|",
        *[f"| {a} | {b} | {c} | {d} | not yet |" for a, b, c, d in rows],
        "",
        "Prandtl's N_c = 30.14 for phi = 30 deg holds for associated Mohr-Coulomb. A Drucker-Prager "
        "cone gives the same plane-strain collapse load when it is matched in plane strain with "
        "associated flow: q = M (p + c cot phi), M = 3 sqrt(3) tan phi / sqrt(9 + 12 tan^2 phi) = "
        "0.832 (`MohrCoulombDruckerPrager`; the match is derived in its module). The paper's cone "
        "has m = 18 sin phi / (9 - sin^2 phi) = 1.029, the mean of the triaxial compression and "
        "extension matches; with its isochoric flow (g = q) the plane-strain match would be "
        "M = sqrt(3) sin phi = 0.866, so the paper's cone is as strong as Mohr-Coulomb with "
        "phi = 36.4 deg and c = 128 kPa in plane strain (associated N_c c'/c = 67; Davis's "
        "reduced-strength estimate for psi = 0: 32.8). It has no collapse load here: with "
        "non-associated perfectly plastic flow the tangent of a flowing point loses ellipticity "
        "(acoustic tensor determinant -0.17 G^2) and its symmetric part is indefinite (second-order "
        "work -0.31 G), so the incremental problem is not unique; Newton's iterates flip points "
        "near the yield surface between elastic and plastic and cycle, and step cutting does not "
        "help. The loads reached are carried (equilibrium was found), so the collapse load is at "
        "least that; by Radenkovic's theorem it is at most the associated value, 67.",
        "",
        "| run | Newton iterations per step | solve [s] | total [s] |",
        "|---|---|---|---|",
        *[f"| {a} | {b:.1f} | {c:.1f} | {d:.1f} |" for a, b, c, d in cost],
        "",
        "![cylinder](images/fe_cylinder.png)",
        "",
        "![footing](images/fe_footing.png)",
        "",
        "![oedometer](images/fe_oedometer.png)",
        "",
    ]
    path.write_text("\n".join(lines))


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0].lstrip("# "))
    parser.add_argument("--quick", action="store_true", help="the quick variants (coarse meshes)")
    parser.add_argument("--report", type=Path, default=Path("results/benchmarks.md"))
    args = parser.parse_args()
    results = run_all(args.quick)
    report(results, args.report, args.quick)
    print(f"wrote {args.report}")
