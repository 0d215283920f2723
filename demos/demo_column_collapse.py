"""# Granular column collapse: the runout and its mesh study

A column of the paper's sand, ``L0 = 10 cm`` wide and ``H0 = a L0`` tall, stands behind a gate
(damped settling from t = -0.01 s), is released at t = 0 and spreads over a rough floor (25°)
until it comes to rest. The left side is a symmetry plane. This demo runs the scenario
``demos/column_collapse.toml`` (a = 2; other aspect ratios on a grid scaled with a) on a
sequence of meshes and measures the deposit at rest:

- runout ``(L - L0) / L0``, with ``L`` the 99th-percentile particle x;
- residual height ``H / H0``, with ``H`` the 99th-percentile particle y;
- the share of the points apart (free volume > 0: pulled below the critical density, stress free).

The change of each from the second finest to the finest mesh is the number to quote with it.
A collapse's front is sensitive to small perturbations, so a single run's runout carries a
scatter of its own: ``--scatter K`` runs each mesh K more times with the time step 2, 4, ... %
off and reports the runout's mean and standard deviation, and the mesh change with its
uncertainty:

    python demos/demo_column_collapse.py                          # a = 2, h = 10 and 5 mm (~6 min)
    python demos/demo_column_collapse.py --aspect 1 --h 0.01 0.005 0.0025           # (~55 min)
    python demos/demo_column_collapse.py --aspect 1 --h 0.005 0.0025 --scatter 2    # (~2.6 h)

Measured (``docs/numerics.md``), on the scenario's squares of four triangles: a = 1 runs out
1.59 / 1.70 / 1.66 on h = 10 / 5 / 2.5 mm; over time steps 2 % apart 1.709 ± 0.019 on h = 5 mm
(five runs) and 1.665 ± 0.014 on 2.5 mm (three): −2.6 ± 1.3 % from 5 to 2.5 mm. a = 2 runs
out 3.51 / 3.54 on h = 10 / 5 mm.
On squares of two triangles the column locks (a = 1: 0.99 / 1.35 / 1.50 / 1.52 on h = 10 / 5 /
2.5 / 1.25 mm, with two thirds of its points apart). Two-dimensional experiments give
``ΔL / L0 ≈ 1.2 a`` for a up to 2–3 (Lube et al., Phys. Rev. E 72, 2005). Each mesh's run is
a scenario run in its own folder (XDMF for ParaView, ``history.csv``, figures); the study
writes ``collapse.json`` and ``collapse.png``.
"""

import argparse
import json
import math
from pathlib import Path

import dolfin_mpm as dm  # noqa: F401  (import first: it loads DOLFINx's libraries)

# isort: split
import numpy as np
from mpi4py import MPI

from dolfin_mpm.app import scenario
from dolfin_mpm.app.runner import Runner
from dolfin_mpm.io import xdmf
from dolfin_mpm.post.plotting import figure

SCENARIO = Path(__file__).with_name("column_collapse.toml")
L0 = 0.1  # m: the column's width (half the column: the left side is a symmetry plane)


def overrides(h: float, aspect: float, t_end: float | None = None) -> list[str]:
    """The scenario's keys for a column of aspect ratio ``aspect`` on a mesh of ``h`` [m].

    The grid is ``4 a L0`` long and ``1.2 a L0`` tall (0.8 × 0.24 m for a = 2, the scenario's);
    the run ends at ``t_end`` [s], by default ``0.4 + 0.2 a`` (at rest: the a = 2 front stops
    by 0.65 s, the a = 1 front by 0.4 s).
    """
    if not (math.isfinite(h) and h > 0.0):
        raise ValueError(f"h must be a positive length [m], got {h!r}")
    if not 0.5 <= aspect <= 4.0:
        raise ValueError(f"aspect must be in [0.5, 4], got {aspect!r}")
    H0 = aspect * L0
    if H0 < 4 * h - 1e-12:
        raise ValueError(
            f"h = {h} m cannot resolve the column: need at least 4 cells up it (h <= {H0 / 4} m)"
        )
    upper = (4 * H0, 1.2 * H0)
    cells = [max(1, round(u / h)) for u in upper]
    end = 0.4 + 0.2 * aspect if t_end is None else t_end
    return [
        f"mesh.upper=[{upper[0]!r}, {upper[1]!r}]",
        f"mesh.cells=[{cells[0]}, {cells[1]}]",
        f"bodies.column.region.max=[{L0!r}, {H0!r}]",
        f"bodies.column.stress.surface={H0!r}",
        f"time.end={end!r}",
        f"output.interval={end / 16!r}",
        f"output.checkpoint_interval={end!r}",
        f"output.figure_interval={end!r}",
    ]


def runout(x: np.ndarray) -> float:
    """``(L - L0) / L0`` of the particles at ``x`` [m] (``shape=(n, 2 or 3)``), L their 99th-percentile x."""
    return float((np.percentile(x[:, 0], 99) - L0) / L0)


def deposit(x: np.ndarray, free_volume: np.ndarray, H0: float, bin_width: float) -> dict:
    """Runout, residual height, share apart and surface profile of a deposit.

    Args:
        x: particle positions [m], ``shape=(n, 2)``.
        free_volume: the particles' free volume [m^2], ``shape=(n,)``.
        H0: the column's height [m].
        bin_width: width of the profile's columns [m].

    """
    edges = np.arange(0.0, x[:, 0].max() + bin_width, bin_width)
    column = np.digitize(x[:, 0], edges) - 1
    top = np.zeros(len(edges))
    np.maximum.at(top, column, x[:, 1])
    return {
        "runout": runout(x),
        "height": float(np.percentile(x[:, 1], 99) / H0),
        "apart": float(np.mean(free_volume > 0.0)),
        "profile_x": (edges + 0.5 * bin_width).tolist(),
        "profile_y": top.tolist(),
    }


def run(
    h=0.01, aspect=2.0, t_end=None, output=Path("results/column_collapse"), progress=True, courant=None
) -> dict:
    """The collapse on a mesh of ``h`` [m], run to ``t_end`` [s] in ``output/h<mm>``: its deposit.

    ``courant``: the solver's Courant factor, ``None`` for the scenario's; another one runs in
    ``output/h<mm>_courant<c>``.
    """
    extra = [] if courant is None else [f"solver.courant={courant!r}"]
    cfg = scenario.load(SCENARIO, overrides(h, aspect, t_end) + extra)
    sim = scenario.build(cfg)
    folder = Path(output) / (f"h{1e3 * h:g}mm" + ("" if courant is None else f"_courant{courant:g}"))
    folder.mkdir(parents=True, exist_ok=True)
    Runner(sim, folder, progress=progress).run()
    return {**measure(folder, h, aspect), "courant": courant}


def courants(count: int, base: float) -> list[float]:
    """``count`` Courant factors next to ``base``, 2 % apart: ``base (1 - 0.02)``, ``base (1 + 0.02)``,
    ``base (1 - 0.04)``, ... A step this much shorter or longer should not change a converged
    answer, so what the runs give about the base run is the scatter of a single run.
    """
    if not (isinstance(count, int) and 0 <= count <= 10):
        raise ValueError(f"scatter must be a whole number of runs in [0, 10], got {count!r}")
    steps = [sign * k for k in range(1, count // 2 + 2) for sign in (-1, 1)][:count]
    return [round(base * (1 + 0.02 * k), 6) for k in steps]


def spread(results: list[dict]) -> dict:
    """The runout's mean and standard deviation over the runs on each mesh: ``{h: (mean, std, runs)}``."""
    out = {}
    for h in sorted({r["h"] for r in results}, reverse=True):
        values = np.array([r["runout"] for r in results if r["h"] == h])
        out[h] = (float(values.mean()), float(values.std(ddof=1)) if len(values) > 1 else 0.0, len(values))
    return out


def measure(folder: Path, h: float, aspect: float) -> dict:
    """The deposit of the run in ``folder`` (mesh ``h`` [m], aspect ratio ``aspect``) at its last output."""
    # ## The deposit, from the particle series as ParaView shows it
    # The front's runout at every output shows whether the deposit is at rest: what it moved
    # over the last quarter of the run is ``moving``.
    series = folder / "particles.xdmf"
    times, fronts = xdmf.times(series), []
    for k in range(len(times)):
        t, x, _, fields = xdmf.read(series, k)
        fronts.append(runout(x))
    late = np.searchsorted(times, 0.75 * t)
    return {
        "h": h,
        "aspect": aspect,
        "t_end": t,
        "particles": len(x),
        **deposit(x[:, :2], fields["free_volume"].ravel(), aspect * L0, max(h, 2.5e-3)),
        "moving": fronts[-1] - fronts[late],
        "front_t": times,
        "front_runout": fronts,
        "folder": str(folder),
    }


def plot(results: list[dict], path: Path, runouts: dict | None = None) -> None:
    """The deposits' surface profiles on every mesh, and the runout against h.

    ``runouts``: :func:`spread` of all the runs, drawn as the mean and its standard deviation.
    """
    a = results[0]["aspect"]
    with figure(path, ncols=2, figsize=(11, 3.8), gridspec_kw={"width_ratios": [2.2, 1]}) as (ax1, ax2):
        for r in results:
            ax1.plot(
                100 * np.array(r["profile_x"]),
                100 * np.array(r["profile_y"]),
                label=f"h = {1e3 * r['h']:g} mm, t = {r['t_end']:.2f} s",
            )
        ax1.plot([0, 100 * L0, 100 * L0], [100 * a * L0] * 2 + [0], "k:", label="column at t = 0")
        ax1.set(xlabel="x [cm]", ylabel="surface height [cm]", title=f"Deposit, a = {a:g}")
        ax1.legend(fontsize=8)
        h = [1e3 * r["h"] for r in results]
        if runouts is None:
            ax2.plot(h, [r["runout"] for r in results], "o-")
        else:
            mean, std = (np.array([runouts[r["h"]][k] for r in results]) for k in (0, 1))
            ax2.errorbar(h, mean, yerr=std, fmt="o-", capsize=3)
        label = "runout (L - L0) / L0" + ("" if runouts is None else ": mean ± s.d.")
        ax2.set(xscale="log", xlabel="h [mm]", ylabel=label, title="Mesh study")
        ax2.set_xticks(h, [f"{v:g}" for v in h])
        ax2.minorticks_off()
        ax2.invert_xaxis()
        ax2.grid(alpha=0.3)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0].lstrip("# "))
    parser.add_argument("--h", type=float, nargs="+", default=[0.01, 0.005], help="mesh spacings [m]")
    parser.add_argument("--aspect", type=float, default=2.0, help="aspect ratio a = H0 / L0, in [0.5, 4]")
    parser.add_argument("--t-end", type=float, help="end of the run [s] (default 0.4 + 0.2 a: at rest)")
    parser.add_argument("--output", type=Path, default=Path("results/column_collapse"))
    parser.add_argument(
        "--scatter",
        type=int,
        default=0,
        help="runs more on each mesh, their time steps 2, 4, ... %% off the scenario's (their spread)",
    )
    args = parser.parse_args()
    for h in args.h:  # bad input before any run
        cfg = scenario.load(SCENARIO, overrides(h, args.aspect, args.t_end))
    factors = [None, *courants(args.scatter, cfg["solver"]["courant"])]  # the scenario's on every mesh
    output = args.output / f"a{args.aspect:g}"
    results = [
        run(h, args.aspect, args.t_end, output, courant=c)
        for h in sorted(args.h, reverse=True)
        for c in factors
    ]
    if MPI.COMM_WORLD.rank > 0:
        return
    for r in results:
        step = "" if r["courant"] is None else f" (Courant {r['courant']:g})"
        print(
            f"h = {1e3 * r['h']:g} mm{step}: runout {r['runout']:.3f}, H/H0 {r['height']:.3f}, "
            f"apart {100 * r['apart']:.0f} %, front moved {r['moving']:+.3f} L0 over the last quarter, "
            f"{r['particles']} particles"
        )
    # ## Verification
    # The deposit must be at rest (its front no longer moves; the particles' kinetic energy
    # does not say it, as FLIP keeps a noise of a few cm/s in the deposit) and its runout must
    # not change with the mesh: the change between the two finest meshes is its mesh error. A
    # collapse's front is sensitive to small perturbations: with ``--scatter`` each mesh's
    # runout is the mean over runs whose time steps differ by a few per cent, and its standard
    # deviation says how far a single run may be off.
    runouts = spread(results)
    if args.scatter:
        for h, (mean, std, n) in runouts.items():
            print(
                f"h = {1e3 * h:g} mm: runout {mean:.3f} ± {std:.3f} (mean ± standard deviation of {n} runs)"
            )
    if len(runouts) > 1:
        (ha, (a, sa, _)), (hb, (b, sb, _)) = list(runouts.items())[-2:]
        scatter = f" ± {math.hypot(sb, b / a * sa) / a:.3f}" if args.scatter else ""  # of b / a
        print(
            f"mesh study: runout {b:.3f}, change {b / a - 1:+.3f}{scatter} "
            f"from h = {1e3 * ha:g} to {1e3 * hb:g} mm (experiments: about {1.2 * args.aspect:.1f})"
        )
    (output / "collapse.json").write_text(json.dumps(results, indent=1))
    plot(
        [r for r in results if r["courant"] is None],
        output / "collapse.png",
        runouts if args.scatter else None,
    )
    print(f"wrote {output / 'collapse.json'} and {output / 'collapse.png'}")


if __name__ == "__main__":
    main()
