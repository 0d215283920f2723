"""# FE and MPM benchmarks: one table against the analytical solutions

Runs the cylinder, footing and oedometer demos, each with the reference FE solver and with the
explicit MPM loaded quasi-statically, and writes their figures and one table (benchmark |
analytic | FE | error | MPM | error) into a Markdown report.

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
    """Each benchmark's FE and MPM results, with their wall times [s]."""
    cylinder = (5, 10, 0.1) if quick else ()
    footing = {"n": 12, "steps": 10} if quick else {}
    cylinder_mpm = (5, 10) if quick else ()
    footing_mpm = {"h": 0.1, "ppc": 1} if quick else {}
    associated_speed = 1e-3 if quick else 3e-4
    runs = {
        "cylinder": lambda: demo_cylinder.run(*cylinder, progress=False),
        "cylinder_mpm": lambda: demo_cylinder.run_mpm(*cylinder_mpm, progress=False),
        "footing_cohesive": lambda: demo_footing.run("cohesive", **footing, progress=False),
        "footing_cohesive_mpm": lambda: demo_footing.run_mpm(
            "cohesive", **footing_mpm, **demo_footing.BENCHMARK_MPM["cohesive"], progress=False
        ),
        "footing_frictional": lambda: demo_footing.run("frictional", **footing, progress=False),
        "footing_frictional_mpm": lambda: demo_footing.run_mpm("frictional", **footing_mpm, progress=False),
        "footing_associated": lambda: demo_footing.run("frictional-associated", **footing, progress=False),
        # Collapse needs 0.1 m of settlement, the push goes on to 0.3 m: 10 cm cells, four
        # particles each (one each leaves cells empty as the soil moves); faster when quick.
        "footing_associated_mpm": lambda: demo_footing.run_mpm(
            "frictional-associated", h=0.1, ppc=1 if quick else 4, speed=associated_speed, progress=False
        ),
        "oedometer": lambda: demo_oedometer.run(progress=False),
        "oedometer_mpm": lambda: demo_oedometer.run_mpm(),
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
    footings = [res["footing_cohesive"], res["footing_frictional"], res["footing_associated"]]
    cyl, oed, (coh, fri, aso) = res["cylinder"], res["oedometer"], footings
    names = ("cylinder", "footing_cohesive", "footing_frictional", "footing_associated", "oedometer")
    cyl_m, coh_m, fri_m, aso_m, oed_m = (res[f"{k}_mpm"] for k in names)
    demo_cylinder.plot(cyl, images / "fe_cylinder.png", cyl_m)
    demo_footing.plot(footings, images / "fe_footing.png", [coh_m, fri_m, aso_m])
    demo_oedometer.plot(oed, images / "fe_oedometer.png", oed_m)
    mpa, pct = 1e-6, lambda x: f"{100 * x:+.2f} %"
    davis = demo_footing.davis_capacity(demo_footing.soil("frictional")[0])
    fri_fe, fri_err = f"{fri['q_u_over_c']:.2f}", pct(fri["error"])
    if fri["failed_at"] is not None:  # no plateau: the last value is no collapse load
        fri_fe = (
            f"Newton stopped at {1e3 * fri['failed_at']:.1f} mm settlement, q / c = {fri['q_u_over_c']:.2f}"
        )
        fri_err = "no collapse load"
    rows = [
        ("cylinder: limit pressure [MPa]", f"{cyl['p_limit'] * mpa:.2f}", f"{cyl['p_max'] * mpa:.2f}",
         pct(cyl["limit_error"]), f"{cyl_m['p_plateau'] * mpa:.2f} (plateau)", pct(cyl_m["limit_error"])),
        ("cylinder: outer displacement along the path", "Hill", "", f"max {100 * cyl['u_b_error']:.2f} %",
         "p against Hill's p(u_b)", f"max {100 * cyl_m['path_error']:.1f} % of p_lim"),
        ("cylinder: plastic radius along the path", "Hill", "", f"max {100 * cyl['c_error']:.1f} % of a",
         "", ""),
        ("footing, cohesive: q_u / c", f"{coh['N_c']:.3f}", f"{coh['q_u_over_c']:.3f}", pct(coh["error"]),
         f"{coh_m['q_u_over_c']:.3f} (rigid walls, undamped, 37.5-50 mm)", pct(coh_m["error"])),
        ("footing, phi = 30 deg, DP matched to MC in plane strain, associated: q_u / c", f"{aso['N_c']:.2f}",
         f"{aso['q_u_over_c']:.2f}", pct(aso["error"]),
         f"{aso_m['q_10_over_c']:.2f} (at s = 0.1 B; {aso_m['q_u_over_c']:.2f} at 0.3 m)",
         pct(aso_m["error_10"])),
        ("footing, phi = 30 deg, the paper's DP (m = 1.029, g = q): q_u / c",
         f"{fri['N_c']:.2f} (MC, associated); {davis:.1f} (Davis, psi = 0)", fri_fe, fri_err,
         f"{fri_m['q_u_over_c']:.2f} (plateau)", f"{pct(fri_m['q_u_over_c'] / davis - 1.0)} of Davis"),
        ("oedometer: K0", f"{oed['K0']:.6f}", f"{oed['K0_fe']:.6f}", f"{oed['K0_fe'] / oed['K0'] - 1:+.1e}",
         f"{oed_m['K0_mpm']:.6f}", f"{oed_m['K0_mpm'] / oed['K0'] - 1:+.1e}"),
        ("oedometer: stress path (K0, then the cone)", "exact", "", f"max {oed['error']:.1e} of sigma_v", "",
         f"max {oed_m['error']:.1e} of sigma_v"),
        ("oedometer: ratio at 3 % strain -> K_a", f"{oed['K_active']:.4f}", f"{oed['K_final_fe']:.4f}", "",
         f"{oed_m['K_final_mpm']:.4f}", ""),
    ]  # fmt: skip
    cost = [
        ("cylinder", cyl["newton_mean"], cyl["solve_seconds"], cyl["seconds"], cyl_m),
        ("footing, cohesive", coh["newton_mean"], coh["solve_seconds"], coh["seconds"], coh_m),
        ("footing, frictional (paper's DP)", fri["newton_mean"], fri["solve_seconds"], fri["seconds"], fri_m),
        ("footing, frictional (associated)", aso["newton_mean"], aso["solve_seconds"], aso["seconds"], aso_m),
        ("oedometer", oed["newton_mean"], oed["solve_seconds"], oed["seconds"], oed_m),
    ]
    lines = [
        "# FE and MPM benchmarks",
        "",
        "The reference FE solver (`dolfin_mpm.fe.QuasiStatic`: small strain, plane strain, P2 "
        "displacements, stresses at 3 points per triangle, Newton with the consistent tangent of "
        "the return mapping the MPM uses) and the explicit MPM (P1 triangles, particles as "
        "integration points, loaded slowly under displacement control with local damping) against "
        "analytical solutions. "
        + ("Quick variants (coarse meshes). " if quick else "")
        + "Regenerate with",
        "",
        f"    python demos/fe_benchmarks.py {'--quick ' if quick else ''}--report {path.as_posix()}",
        "",
        "| benchmark | analytic | FE | error | MPM | error |",
        "|---|---|---|---|---|---|",
        *[f"| {' | '.join(row)} |" for row in rows],
        "",
        "The MPM loads are displacements: the bore of the cylinder is pushed out radially (by "
        "symmetry the same as a uniform pressure), the footing and the oedometer's top are pushed "
        "down; pressures are the reactions of those nodes, averaged over intervals of many steps.",
        "",
        "How each MPM number moves with the mesh, the loading speed and the local damping is in "
        "`docs/numerics.md` (`demo_cylinder.py --study`, `demo_footing.py --study`). The cylinder's "
        "limit pressure is converged in the mesh and the speed. The footings' loads are not with "
        "the local damping the other runs use: it drags the soil that flows past the footing and "
        "raises the footings' loads by several per cent, more as the cells shrink. The cohesive "
        "footing is therefore pushed undamped, by rigid walls that make it B wide on any mesh, past "
        "the FE's plateau (50 mm, its load the mean over the last quarter); the frictional footings' "
        "rows are still the damped runs'.",
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
        "least that; by Radenkovic's theorem it is at most the associated value, 67. "
        "The explicit MPM has no Newton iteration to fail: pushed down slowly it settles on a "
        "plateau, a collapse load of the same non-unique problem, between the FE lower bound and "
        "Davis's estimate. The associated cone dilates: the small-strain FE reaches its plateau "
        "at about 0.1 m of settlement (0.1 B). Its MPM footing (the grid nodes inside it, joined "
        f"as its base sinks) runs on 10 cm cells with {'one particle' if quick else 'four particles'} "
        f"each, loaded at {'1e-3' if quick else '3e-4'} of the p-wave speed, to 0.3 m, with the "
        "nearly empty nodes beside the heave tied to their neighbours (`light_nodes = "
        '"aggregate"`). The MPM is '
        "a large-deformation method: as the footing sinks into the dilating soil and the heave "
        "rises round it, its load keeps growing past the small-strain plateau, so its failure load "
        "is taken by the 10 % criterion, q at a settlement of 0.1 B. With one particle per "
        "triangle the cells empty as the soil moves and the load falls away from the FE's from "
        "about 40 mm on (`python demos/demo_footing.py --soil frictional-associated --study`; "
        "`docs/numerics.md`).",
        "",
        "| run | FE: Newton iterations per step | FE: solve [s] | FE: total [s] | MPM: particles | "
        "MPM: steps | MPM: total [s] |",
        "|---|---|---|---|---|---|---|",
        *[f"| {a} | {b:.1f} | {c:.1f} | {d:.1f} | {m['particles']} | {m['steps']} | {m['seconds']:.1f} |"
          for a, b, c, d, m in cost],
        "",
        "![cylinder](images/fe_cylinder.png)",
        "",
        "![footing](images/fe_footing.png)",
        "",
        "![oedometer](images/fe_oedometer.png)",
        "",
    ]  # fmt: skip
    path.write_text("\n".join(lines))


def main():
    """The command line: every benchmark, then the report."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0].lstrip("# "))
    parser.add_argument("--quick", action="store_true", help="the quick variants (coarse meshes)")
    parser.add_argument("--report", type=Path, default=Path("results/benchmarks.md"))
    args = parser.parse_args()
    results = run_all(args.quick)
    report(results, args.report, args.quick)
    print(f"wrote {args.report}")


if __name__ == "__main__":
    main()
