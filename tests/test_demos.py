"""The demos, run small: each checks the number its Verification section prints."""

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

DEMOS = Path(__file__).parents[1] / "demos"


def load(name):
    spec = importlib.util.spec_from_file_location(name, DEMOS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_elastic_bar_musl_period_and_energy(tmp_path):
    r = load("demo_elastic_bar").run(cells=30, periods=5.0, scheme="MUSL", output=tmp_path, progress=False)
    assert abs(r["period"] / r["period_exact"] - 1.0) < 0.01
    assert r["energy_drift"] < 0.02
    assert (tmp_path / "particles.xdmf").exists() and (tmp_path / "tip_displacement.png").exists()


@pytest.mark.parametrize("scheme", ["USL"])
def test_elastic_bar_usl_period(scheme):
    r = load("demo_elastic_bar").run(cells=20, periods=2.5, scheme=scheme, progress=False)
    assert abs(r["period"] / r["period_exact"] - 1.0) < 0.01


def test_shear_band_width_set_by_the_radius_not_the_mesh():
    demo = load("demo_shear_band")
    r = 4e-3
    local = [demo.run(cells, 0.0) for cells in (10, 20)]
    nonlocal_ = [demo.run(cells, r) for cells in (10, 20)]
    # Local model: the band is one or two cells wide in the weak layer.
    assert local[0]["width_eps_vp"] / local[1]["width_eps_vp"] > 1.6
    # Non-local: the widths of e_vp_bar and of the velocity jump follow r, not h.
    for key in ("width_e_vp_bar", "width_velocity"):
        w = [run[key] for run in nonlocal_]
        assert max(w) / min(w) < 1.2 and min(w) > r
    assert all(run["mean_iterations"] < 5 for run in nonlocal_)


def test_silo3d_quick_discharge(tmp_path):
    demo = load("demo_silo3d")
    m_p = 1500.0 * 0.025**3 / 24  # a particle's: 4 in each of a cube's 6 tetrahedra
    r = demo.run(h=0.025, radius=0.02, t_end=0.04, t_settle=0.005, output=tmp_path, progress=False)
    assert abs(r["mass_final"] - r["mass_initial"]) < 1e-12 * r["mass_initial"]
    assert r["kinetic_at_opening"] < 1e-6 * r["mass_initial"]  # at rest when the gate goes
    assert r["discharged"][-1] > 50 * m_p and np.all(np.diff(r["discharged"]) >= 0.0)  # it flows
    assert r["unconverged"] == 0
    P = r["solver"].particles
    inside = P.x[:, 2] > 0.0
    assert np.all((P.x[inside, :2] > 0.0) & (P.x[inside, :2] < 0.2))  # no particle through a wall
    below = ~inside  # what has passed the bottom did so through the outlet
    assert np.all((P.x[below, :2] > 0.05 - 1e-9) & (P.x[below, :2] < 0.15 + 1e-9))
    demo.plot_section(r["solver"], 0.025, tmp_path / "section.png")
    assert (tmp_path / "particles.xdmf").exists() and (tmp_path / "section.png").exists()


def test_silo_quick_discharge(tmp_path):
    demo = load("demo_silo")
    r = demo.run(h=0.025, radius=0.02, t_end=0.1, t_settle=0.01, output=tmp_path, progress=False)
    # Mass: in the silo and in flight + absorbed by the sink = initial, to round-off.
    assert abs(r["mass_final"] - r["mass_initial"]) < 1e-12 * r["mass_initial"]
    # The fill was at rest when the outlet opened; then it flows, and keeps flowing.
    assert r["kinetic_at_opening"] < 1e-6
    assert r["discharged"][-1] > 1.0 and np.all(np.diff(r["discharged"]) >= 0.0)
    # e_vp_bar peaks near an outlet edge (x = 5 or 15 cm on the bottom).
    x, e = r["x"], r["e_vp_bar"]
    inside = x[:, 1] > 0.0
    peak = x[inside][np.argmax(e[inside])]
    assert min(np.hypot(peak[0] - 0.05, peak[1]), np.hypot(peak[0] - 0.15, peak[1])) < 0.05
    assert r["unconverged"] == 0
    # The section at y = 1 cm: a peak of e_vp_bar near the outlet edge, narrower than the half silo.
    widths = demo.band_widths(r)
    assert 0.0 < widths["edge"] < 0.1 and 0.0 < widths["edge_x"] < 0.1
    assert (tmp_path / "particles.xdmf").exists()
    # The flux through the outlet plane passes the opening, not the plates.
    x, flux = r["profile_flux"]
    assert sum(r["outlet_shares"]) > 0.0 and np.all(np.abs(flux[x < 0.04]) < 0.1 * flux.max())
    # A share of the points passing the outlet at the apex, stress free (bins of half a cell: on
    # this coarse mesh no bin's centre falls 2-3 cm from an edge, that band has no value).
    free = r["outlet_stress_free"]
    assert len(free) == 4 and free[2] is None and all(0.0 <= f <= 1.0 for f in free if f is not None)


def test_silo_outlet_shares_split_the_flux_by_distance_from_the_edges():
    """A uniform flux F over the 10 cm outlet: 2 cm of it in each of the three 1 cm bands, 4 cm beyond."""
    demo = load("demo_silo")
    x = np.arange(0.0025, 0.2, 0.005)  # bin centres, bins of 5 mm over the silo's width
    F = 1500.0
    flux = np.where((x > 0.05) & (x < 0.15), F, 7.0)  # 7: over the plates, not counted
    assert np.allclose(demo.outlet_shares(x, flux, 0.05, 0.15), [0.02 * F, 0.02 * F, 0.02 * F, 0.04 * F])


def test_silo_outlet_stress_free_shares_by_distance_from_the_edges():
    """Points at p = 0 counted in the bands of the outlet; bins over the plates are not counted."""
    demo = load("demo_silo")
    x = np.arange(0.0025, 0.2, 0.005)
    d = np.minimum(x - 0.05, 0.15 - x)
    count = np.where(d < 0.0, 9.0, 4.0)
    free = np.select([d < 0.0, d < 0.01, d < 0.02], [9.0, 3.0, 1.0], 0.0)  # 0-1 cm: 3 of 4, 1-2 cm: 1 of 4
    assert demo.outlet_stress_free(x, count, free, 0.05, 0.15) == [0.75, 0.25, 0.0, 0.0]
    assert demo.outlet_stress_free(x, 0.0 * count, free, 0.05, 0.15) == [None] * 4  # no point passed


def test_silo_quick_paper_law_and_its_report(tmp_path):
    """The paper's law converges; the speed across the bands gives widths; the JSON has them."""
    demo = load("demo_silo")
    quick = dict(h=0.025, t_end=0.1, t_settle=0.01, progress=False)
    runs = [demo.run(radius=0.0, **quick), demo.run(radius=0.02, weight="wendland", law="paper", **quick)]
    assert runs[1]["unconverged"] == 0 and runs[1]["mean_iterations"] > 1.0
    for r in runs:
        for band in ("edge", "stagnant", "wall"):
            assert 0.0 < r[f"{band}_band_width"] < 0.1 and 0.0 < r[f"{band}_band_x"] < 0.1
    lines = demo.law_lines(runs)
    assert any(line.startswith("| paper | 20 | wendland | 25 |") for line in lines)
    other = {**runs[0], "volumetric": "cell"}  # a run of the numerics study: listed apart
    split = {**runs[0], "split": [2, 1]}  # a run on rectangles: listed apart too
    wider = 1.1 * runs[0]["edge_band_width"]  # (the quick run is too short for a flow rate: NaN)
    step = {**runs[0], "courant": 0.25, "edge_band_width": wider}  # a run of the time-step study
    demo.write_json([*runs, other, split, step], tmp_path / "silo.json")
    data = json.loads((tmp_path / "silo.json").read_text())
    assert data["default_law"] == "max" and [r["law"] for r in data["runs"]] == ["local", "paper"]
    assert all(r["volumetric"] == data["numerics"]["volumetric"] == "nodal" for r in data["runs"])
    assert [r["volumetric"] for r in data["numerics_runs"]] == ["cell"]
    assert [r["split"] for r in data["split_runs"]] == [[2, 1]]
    assert [r["courant"] for r in data["timestep_runs"]] == [0.25]
    assert all(r["courant"] == 0.5 for r in data["runs"])
    # The time-step study's table: a row per factor, and the change to the smallest.
    lines = demo.timestep_lines([step, runs[0]])
    assert [line.split(" | ")[2] for line in lines[2:4]] == ["0.5", "0.25"]
    change = [line for line in lines if line.startswith("- local, h = 25 mm, Courant 0.5 -> 0.25: flow rate")]
    assert len(change) == 1 and "flow rate -, edge band +10.0 %, stagnant band +0.0 %" in change[0]
    older = {k: v for k, v in step.items() if k not in ("stagnant_band_width", "dt")}  # stored before them
    lines = demo.timestep_lines([older, runs[0]])
    assert "stagnant band -, wall band +0.0 %" in lines[-1] and "| 0.25 | - |" in lines[3]
    assert lines[3].split(" | ")[6] == "-"  # no stagnant band in the table either
    unrecorded = {k: v for k, v in runs[0].items() if k != "courant"}  # stored before the factor was
    demo.write_json([unrecorded], tmp_path / "older.json")
    assert json.loads((tmp_path / "older.json").read_text())["runs"][0]["courant"] == 0.5
    assert data["runs"][1]["edge_band_width"] == runs[1]["edge_band_width"]
    assert {"h", "radius", "weight", "wall_friction", "flow_rate", "channel_width"} <= set(data["runs"][0])
    assert data["runs"][1]["stagnant_band_width"] == runs[1]["stagnant_band_width"]


def test_silo_quick_overnonlocal_mix_is_named_by_its_factor():
    """A mix of m = 1.01 converges where r spans two points; its runs and rows carry m."""
    demo = load("demo_silo")
    quick = dict(h=0.025, t_end=0.05, t_settle=0.01, progress=False, radius=0.02, weight="wendland")
    r = demo.run(law="overnonlocal", m=1.01, **quick)
    assert r["unconverged"] == 0 and r["mean_iterations"] > 1.0 and r["m"] == 1.01
    assert demo.law_label(r) == "overnonlocal m = 1.01" and demo.law_label({**r, "radius": 0.0}) == "local"
    key = demo.run_key(h=0.01, radius=5e-3, weight="wendland", law="overnonlocal", m=1.01)
    assert key == "h10mm_r5mm_wendland_wall20_overnonlocal_m1.01"
    with pytest.raises(ValueError, match="needs its factor m"):
        demo.build(h=0.025, radius=0.02, weight="wendland", law="overnonlocal")


def test_silo_time_step_follows_the_courant_factor(monkeypatch, capsys):
    """Half the factor, half the step; the runs are named by it; the CLI refuses one out of (0, 1]."""
    demo = load("demo_silo")
    steps = [demo.build(h=0.025, radius=0.0, courant=c)[0].dt for c in (0.5, 0.25)]
    assert steps[1] == pytest.approx(0.5 * steps[0], rel=1e-12)
    assert demo.run_key(h=0.01, radius=5e-3, courant=0.25) == "h10mm_r5mm_cubic_wall20_courant0.25"
    assert demo.run_key(h=0.01, radius=5e-3, courant=0.5) == demo.run_key(h=0.01, radius=5e-3)
    monkeypatch.setattr("sys.argv", ["demo_silo.py", "--courant", "1.5"])
    with pytest.raises(SystemExit) as stop:
        demo.main()
    assert stop.value.code == 2 and "--courant: courant must be in (0, 1], got 1.5" in capsys.readouterr().err
    assert demo._spread([0.04, 0.05]) == "25 %" and demo._spread([0.04, float("nan")]) == "-"


def test_silo_points_per_triangle_study(monkeypatch, capsys):
    """Runs are named by their points per triangle; the table sets 16 on h beside 4 on h / 2."""
    demo = load("demo_silo")
    r = demo.run(h=0.025, radius=0.0, ppc=9, t_end=0.01, t_settle=0.005, progress=False)
    fill = demo.run(h=0.025, radius=0.0, t_end=0.01, t_settle=0.005, progress=False)
    assert r["ppc"] == 9 and fill["ppc"] == 4 and r["mass_initial"] == pytest.approx(fill["mass_initial"])
    assert demo.run_key(h=0.01, radius=5e-3, ppc=16) == "h10mm_r5mm_cubic_wall20_ppc16"
    assert demo.run_key(h=0.01, radius=5e-3, ppc=4) == demo.run_key(h=0.01, radius=5e-3)
    run = lambda h, ppc, q: dict(  # noqa: E731
        h=h, radius=5e-3, ppc=ppc, flow_rate=q, edge_band_width=0.03, mean_iterations=2.0, seconds=1.0
    )
    lines = demo.points_lines([run(0.01, 4, 100.0), run(0.01, 16, 110.0)], [run(0.005, 4, 121.0)])
    assert lines[2] == "| r = 5 mm | 10 | 4 | 3.54 | 6 | 100.0 | 30.0 | - | - | 2.00 | 1 |"
    assert lines[3] == "| r = 5 mm | 10 | 16 | 1.77 | 25 | 110.0 | 30.0 | - | - | 2.00 | 1 |"
    assert "- r = 5 mm, h = 10 mm, 4 -> 16 per triangle: flow rate +10.0 %" in lines
    assert (
        "- r = 5 mm, the same points on a grid 2 times finer: 16 per triangle on h = 10 mm 110.0, "
        "4 on h = 5 mm 121.0 kg/s/m (+10.0 %)"
    ) in lines
    counts = [run(0.01, 4, 100.0), run(0.01, 9, 103.0), run(0.01, 16, 103.0)]
    assert demo.points_advice(counts, 9) == [
        "  this model and mesh with other points per triangle: flow rate [kg/s/m] "
        "4: 100.0, 9: 103.0 (+3.0 %), 16: 103.0 (+0.0 %)"
    ]
    alone = demo.points_advice([run(0.01, 4, 100.0)], 4)[0]
    assert alone.endswith("run again with --ppc 9 to see how far this one moves")
    assert "--ppc 36 " in demo.points_advice([], 16)[0] and "--ppc 81 " in demo.points_advice([], 64)[0]
    monkeypatch.setattr("sys.argv", ["demo_silo.py", "--ppc", "5"])
    with pytest.raises(SystemExit) as stop:
        demo.main()
    assert stop.value.code == 2 and "--ppc: ppc must be a square number" in capsys.readouterr().err


def test_silo_with_cells_refined_at_the_outlet_edges():
    demo = load("demo_silo")
    r = demo.run(h=0.025, radius=0.0, edge_cell=0.0125, t_end=0.05, t_settle=0.005, progress=False)
    assert abs(r["mass_final"] - r["mass_initial"]) < 1e-12 * r["mass_initial"]
    assert r["discharged"][-1] > 0.0
    solver, _ = demo.build(h=0.025, radius=0.0, edge_cell=0.0125)
    x = solver.grid.node_x
    fine = np.isclose(np.diff(np.unique(x[:, 0].round(12))), 0.0125)  # the lines near the edges
    assert fine.any() and not fine.all()


def test_silo_cells_split_across_or_up():
    """``split`` cuts every square into KX columns and KY rows; the walls stay where they are."""
    demo = load("demo_silo")
    square, _ = demo.build(h=0.025, radius=0.0)
    across, _ = demo.build(h=0.025, radius=0.0, split=(2, 1))
    up, _ = demo.build(h=0.025, radius=0.0, split=(1, 3))
    lines = lambda s, c: np.unique(s.grid.node_x[:, c].round(12))  # noqa: E731
    assert len(lines(across, 0)) - 1 == 2 * (len(lines(square, 0)) - 1)
    assert np.array_equal(lines(across, 1), lines(square, 1))
    assert len(lines(up, 1)) - 1 == 3 * (len(lines(square, 1)) - 1)
    assert np.array_equal(lines(up, 0), lines(square, 0))
    assert np.isclose(across.grid.h_min, 0.0125 * 0.025 / np.hypot(0.0125, 0.025))  # the time step's h
    assert [w.points.tolist() for w in across.bcs[:4]] == [w.points.tolist() for w in square.bcs[:4]]
    assert demo.run_key(h=0.01, radius=0.0, split=(2, 1)) == "h10mm_r0mm_cubic_wall20_split2x1"
    assert demo.run_key(h=0.01, radius=0.0, split=None) == demo.run_key(h=0.01, radius=0.0)
    runs = [
        dict(h=0.01, radius=0.0, split=[2, 1], outlet_shares=[1.0, 2.0, 3.0, 4.0], flow_rate=10.0),
        dict(h=0.01, radius=5e-3, split=None, flow_rate=9.0),
    ]
    table = demo.split_lines(runs)
    assert table[2] == "| local | 5 x 10 | 1.0 | 2.0 | 3.0 | 4.0 | 10.0 |"
    assert table[3] == "| r = 5 mm | 10 x 10 | - | - | - | - | 9.0 |"


def test_silo_radius_study_on_three_meshes(tmp_path):
    demo = load("demo_silo")
    assert sorted({p["h"] for p in demo.STUDIES["radius"]}) == [0.0025, 0.005, 0.01]
    runs = [dict(h=h, radius=r, flow_rate=150.0 - 1e3 * r) for h in (0.005, 0.0025) for r in (0.0, 0.005)]
    demo.plot_radius(runs, tmp_path / "radius.png")
    assert (tmp_path / "radius.png").stat().st_size > 0


@pytest.mark.parametrize(
    "sizes, match",
    [
        (dict(split=(0, 1)), "split must be two whole numbers >= 1"),
        (dict(split=(2.0, 1)), "split must be two whole numbers >= 1"),
        (dict(split=(2,)), "split must be two whole numbers >= 1"),
        (dict(split=(2, 1), edge_cell=0.005), "split must be \\(1, 1\\) with edge_cell"),
        (dict(edge_cell=0.02), "edge_cell must be in"),
        (dict(outlet=0.25), "outlet must be narrower"),
        (dict(h=-0.01), "h must be a positive length"),
        (dict(width=-0.2), "width must be a positive length"),
        (dict(h=0.05), "cannot resolve the outlet"),
        (dict(h=0.0075), "must divide"),
        (dict(wall_friction=95.0), "wall_friction must be in"),
    ],
)
def test_silo_bad_input(sizes, match):
    with pytest.raises(ValueError, match=match):
        load("demo_silo").build(**sizes)


def test_hopper_quick_discharge():
    """Inclined walls on an unstructured mesh: the hopper settles, opens and discharges."""
    demo = load("demo_hopper")
    r = demo.run(h=0.02, t_end=0.1, t_settle=0.01, progress=False)
    assert r["mass_error"] < 1e-12
    assert r["discharged"] > 1.0 and r["flow_rate"] > 0.0
    solver, _ = demo.build(h=0.02)
    x = solver.grid.mesh.geometry.x[:, :2]
    for wall in solver.bcs[:2]:  # the inclined walls: no mesh vertex lies on them
        near = wall.over(x) & (np.abs(wall.distance(x)) < 1e-3 * 0.02)
        assert not near.any()


@pytest.mark.parametrize(
    "sizes, match",
    [
        (dict(h=0.03), "cannot resolve the outlet"),
        (dict(beta=75.0), "beta must be in"),
        (dict(D=-0.1), "D must be a positive length"),
    ],
)
def test_hopper_bad_input(sizes, match):
    with pytest.raises(ValueError, match=match):
        load("demo_hopper").build(**sizes)


def test_silo_runs_record_the_code_that_made_them(tmp_path, capsys):
    demo = load("demo_silo")
    now = demo.code_version()
    assert len(now) == 12 and set(now) <= set("0123456789abcdef") and demo.code_version() == now
    # A stored run of other code is reused, and said so.
    params = dict(h=0.01, radius=0.0)
    key, runs = demo.run_key(**params), tmp_path / "runs"
    runs.mkdir()
    stored = {"stress": "cell", "quadrature": "cell", "code": "0123456789ab", "flow_rate": 1.0}
    (runs / f"{key}.json").write_text(json.dumps(stored))
    np.savez(runs / f"{key}.npz", t=np.zeros(2))
    assert demo.cached_run(tmp_path, **params)["flow_rate"] == 1.0
    said = capsys.readouterr().out
    assert (
        f"{key}: the stored run is reused (its code 0123456789ab, now {now}; --force runs it again)" in said
    )
    runs = [dict(h=0.01, radius=0.0, code=now), dict(h=0.005, radius=0.0), dict(h=0.01, radius=0.0, code=now)]
    assert (
        demo.code_line(runs)
        == f"Code of the stored runs: 1 by {now} (this code), 1 by not recorded; this code is {now}."
    )


def test_silo_single_run_is_shown_with_its_mesh_study(tmp_path):
    """A run's numbers come with the same model's stored runs on other meshes, or what to run for them."""
    demo = load("demo_silo")
    runs = tmp_path / "runs"
    runs.mkdir()
    stored = {0.01: (134.7, 0.0352, 0.0409), 0.005: (141.8, 0.0348, 0.0457), 0.00125: (150.5, 0.0331, None)}
    for h, (q, edge, stagnant) in stored.items():
        r = {"stress": "cell", "quadrature": "cell", "h": h, "flow_rate": q, "edge_band_width": edge}
        r["wall_band_width"] = 0.03
        if stagnant is not None:  # the finest was stored before the stagnant band was measured
            r["stagnant_band_width"] = stagnant
        key = demo.run_key(h=h, radius=5e-3)
        (runs / f"{key}.json").write_text(json.dumps(r))
        np.savez(runs / f"{key}.npz", t=np.zeros(2))
    other = demo.run_key(h=0.0025, radius=0.01)  # another model, on a mesh the first lacks
    (runs / f"{other}.json").write_text(json.dumps({**r, "h": 0.0025}))
    np.savez(runs / f"{other}.npz", t=np.zeros(2))
    found = demo.mesh_runs(tmp_path, dict(h=0.005, radius=5e-3))
    assert [r["h"] for r in found] == [0.01, 0.005, 0.00125]
    lines = demo.mesh_lines(found)
    assert lines[1] == "    10: 134.7, 35.2 / 40.9 / 30.0"
    assert lines[2] == "    5: 141.8, 34.8 / 45.7 / 30.0   (+5.3 %, -1.1 %, +11.7 %, +0.0 %)"
    assert lines[3] == "    1.25: 150.5, 33.1 / - / 30.0   (+6.1 %, -4.9 %, -, +0.0 %)"
    assert len(lines) == 4  # more than one mesh: no advice
    assert [r["h"] for r in demo.mesh_runs(tmp_path, dict(h=0.005, radius=0.01))] == [0.0025]
    assert "run again with --h 0.0025 and the same options" in demo.mesh_lines(found[1:2])[-1]


def test_column_collapse_quick_mesh_study(tmp_path, monkeypatch, capsys):
    """The collapse study on two coarse meshes, cut short: the front has left the gate on both
    and is behind where free fall from the column's top, ``sqrt(2 g H0) t``, could carry it, the
    deposit is lower than the column, and the study's table, JSON and figure are written."""
    demo = load("demo_column_collapse")
    argv = ["demo", "--aspect", "1", "--h", "0.02", "0.01", "--t-end", "0.15", "--output", str(tmp_path)]
    monkeypatch.setattr("sys.argv", argv)
    demo.main()
    out = capsys.readouterr().out
    assert "mesh study: runout" in out and "from h = 20 to 10 mm" in out
    results = json.loads((tmp_path / "a1" / "collapse.json").read_text())
    assert [r["h"] for r in results] == [0.02, 0.01] and (tmp_path / "a1" / "collapse.png").stat().st_size > 0
    reach = np.sqrt(2 * 9.81 * 0.1) * 0.15 / 0.1  # [L0]
    for r in results:
        assert r["t_end"] == pytest.approx(0.15, abs=1e-3)
        assert 0.05 < r["runout"] < reach and r["height"] < 1.0 and 0.0 <= r["apart"] <= 1.0
        assert max(r["profile_y"]) <= 0.1 and (Path(r["folder"]) / "particles.xdmf").exists()


@pytest.mark.parametrize("diagonal", ["right", "crossed"])
def test_column_collapse_mesh_locks_on_two_triangles_per_square(tmp_path, diagonal):
    """The scenario's squares of four triangles let the sand flow without changing its volume;
    squares of two lock it (a = 1, h = 20 mm, t = 0.15 s; measured: front at 0.11 / 0.40 L0,
    the total volume, free volume included, +3.3 / +1.1 % on right / crossed diagonals)."""
    from dolfin_mpm.app import scenario
    from dolfin_mpm.app.runner import Runner

    demo = load("demo_column_collapse")
    keys = [*demo.overrides(0.02, 1.0, 0.15), "output.xdmf=false", "output.figures=false"]
    cfg = scenario.load(demo.SCENARIO, [*keys, f'mesh.diagonal="{diagonal}"'])
    sim = scenario.build(cfg)
    V0 = sim.solver.particles.volume.sum()
    Runner(sim, tmp_path, progress=False).run()
    P = sim.solver.particles
    growth = (P.volume + P.state["free_volume"]).sum() / V0 - 1.0
    front = demo.runout(P.x)
    if diagonal == "crossed":
        assert growth < 0.015 and front > 0.3
    else:  # locked: what the crossed mesh is measured against
        assert growth > 0.025 and front < 0.2


def test_column_collapse_scatter_runs_each_mesh_with_the_step_off(tmp_path, monkeypatch, capsys):
    """``--scatter 2``: each mesh also with the Courant factor 2 % below and above the scenario's;
    the runout's mean and standard deviation printed are those of the runs in the JSON."""
    demo = load("demo_column_collapse")
    assert demo.courants(4, 0.5) == [0.49, 0.51, 0.48, 0.52] and demo.courants(0, 0.5) == []
    with pytest.raises(ValueError, match="scatter must be"):
        demo.courants(-1, 0.5)
    argv = ["demo", "--aspect", "1", "--h", "0.02", "--t-end", "0.1", "--scatter", "2"]
    monkeypatch.setattr("sys.argv", [*argv, "--output", str(tmp_path)])
    demo.main()
    out = capsys.readouterr().out
    results = json.loads((tmp_path / "a1" / "collapse.json").read_text())
    assert [r["courant"] for r in results] == [None, 0.49, 0.51]
    assert (tmp_path / "a1" / "h20mm_courant0.49" / "particles.xdmf").exists()
    runouts = np.array([r["runout"] for r in results])
    mean, std = runouts.mean(), runouts.std(ddof=1)
    assert f"h = 20 mm: runout {mean:.3f} ± {std:.3f}" in out
    assert demo.spread(results) == {0.02: (pytest.approx(mean), pytest.approx(std), 3)}


def test_a_deposits_measures_come_from_its_particles():
    demo = load("demo_column_collapse")
    x = np.array([[0.0, 0.05], [0.1, 0.1], [0.2, 0.0]] * 40)
    d = demo.deposit(x, np.array([0.0, 1e-6, 0.0] * 40), H0=0.1, bin_width=0.05)
    assert d["runout"] == pytest.approx(1.0) and d["height"] == pytest.approx(1.0)
    assert d["apart"] == pytest.approx(1 / 3) and d["profile_y"][:3] == [0.05, 0.0, 0.1]


@pytest.mark.parametrize(
    "h, aspect, match",
    [(0.03, 1.0, "cannot resolve the column"), (0.01, 5.0, "aspect must be in"), (-0.01, 1.0, "h must be")],
)
def test_column_collapse_bad_input(h, aspect, match):
    with pytest.raises(ValueError, match=match):
        load("demo_column_collapse").overrides(h, aspect)
