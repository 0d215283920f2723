"""The benchmarks against analytical solutions, run small: the reference FE solver and the MPM."""

import json

import numpy as np
import pytest
from dolfinx import mesh
from mpi4py import MPI
from test_demos import load

import dolfin_mpm as dm
from dolfin_mpm.fe import ConvergenceError, QuasiStatic
from dolfin_mpm.materials import MohrCoulombDruckerPrager, VonMises


def test_cylinder_limit_pressure_and_elastoplastic_path():
    r = load("demo_cylinder").run(n_radial=5, n_theta=10, step=0.1, progress=False)
    assert r["collapsed"], "Newton must fail just beyond the limit pressure"
    assert abs(r["limit_error"]) < 0.01  # the 1 %
    assert r["u_b_error"] < 0.02  # Hill's curve (approximate for nu = 0.3)
    assert r["c_error"] < 0.1  # plastic radius within a tenth of a (cells are a/5 wide)


def test_cylinder_study_quick(tmp_path, monkeypatch, capsys):
    """The cylinder's mesh and loading-speed study on its coarsest variant: FE and MPM limit
    pressures in a table row and in JSON."""
    monkeypatch.setattr("sys.argv", ["demo", "--study", "--quick", "--output", str(tmp_path)])
    load("demo_cylinder").main()
    (row,) = json.loads((tmp_path / "cylinder_study.json").read_text())
    (mpm,) = row["mpm"]
    assert (row["n_radial"], row["n_theta"], mpm["speed"]) == (5, 10, 3e-5)
    assert (
        abs(row["fe_limit_error"]) < 0.01 and abs(mpm["limit_error"]) < 0.05 and mpm["plateau_spread"] < 0.05
    )
    out = capsys.readouterr().out.splitlines()
    assert (
        out[0].startswith("| cells (across x along) |") and out[2].startswith("| 5 x 10 | ") and len(out) == 3
    )


def test_cylinder_mpm_reaches_the_limit_pressure():
    r = load("demo_cylinder").run_mpm(n_radial=5, n_theta=10, progress=False)
    assert abs(r["limit_error"]) < 0.05  # the 5 % for the MPM
    assert r["plateau_spread"] < 0.05  # a plateau, not an oscillation
    assert r["path_error"] < 0.1  # Hill's p(u_b) before the limit, start-up waves included


def test_footing_on_cohesive_soil_reaches_prandtl():
    r = load("demo_footing").run("cohesive", n=12, steps=10, progress=False)
    assert r["failed_at"] is None
    assert abs(r["error"]) < 0.05  # the 5 %
    assert abs(r["plateau"]) < 0.01  # the curve has levelled off: a collapse load


@pytest.mark.parametrize("footing", ["nodes", "walls"])
def test_footing_mpm_on_cohesive_soil_reaches_prandtl(footing):
    r = load("demo_footing").run_mpm("cohesive", h=0.1, ppc=1, progress=False, footing=footing)
    assert abs(r["error"]) < 0.10  # the 10 % for the MPM
    assert r["plateau_spread"] < 0.05


def test_footing_mpm_study_quick(tmp_path, monkeypatch, capsys):
    """The associated footing's MPM study on its coarsest variant: a table row and a JSON row for
    each stress option, each with a collapse load on a levelled-off curve."""
    demo = load("demo_footing")
    argv = ["demo", "--soil", "frictional-associated", "--study", "--quick", "--output", str(tmp_path)]
    monkeypatch.setattr("sys.argv", argv)
    demo.main()
    rows = json.loads((tmp_path / "footing_frictional-associated_study.json").read_text())
    assert [(r["h"], r["ppc"], r["stress"]) for r in rows] == [(0.1, 1, "cell"), (0.1, 1, "particle")]
    n_c = demo.prandtl_nc(30.0)
    for r in rows:
        assert "failed" not in r and 0.5 < r["q_u_over_c"] / n_c < 1.5 and r["plateau_spread"] < 0.3
        assert (
            r["error_10"] == pytest.approx(r["q_10_over_c"] / n_c - 1) and 0.5 < r["q_10_over_c"] / n_c < 1.5
        )
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("| h [mm] |") and out[2].startswith("| 100 | 1 | `cell` | 0.001 | 0.25 |")
    assert out[3].startswith("| 100 | 1 | `particle` |") and len(out) == 4


def test_footing_mpm_time_step_study_quick(tmp_path, monkeypatch, capsys):
    """The cohesive footing's time-step study on its coarsest variant: the soil's Courant number
    and half of it, each a row with its collapse load."""
    demo = load("demo_footing")
    argv = ["demo", "--soil", "cohesive", "--study", "time", "--quick", "--output", str(tmp_path)]
    monkeypatch.setattr("sys.argv", argv)
    demo.main()
    rows = json.loads((tmp_path / "footing_cohesive_study_time.json").read_text())
    assert [(r["h"], r["ppc"], r["speed"], r["courant"]) for r in rows] == [
        (0.1, 1, 1e-3, 0.5),
        (0.1, 1, 1e-3, 0.25),
    ]
    assert rows[1]["steps"] > 1.9 * rows[0]["steps"]  # half the step
    for r in rows:
        assert "failed" not in r and abs(r["error"]) < 0.15 and r["q_10_over_c"] is None
    out = capsys.readouterr().out.splitlines()
    assert out[3].startswith("| 100 | 1 | `cell` | 0.001 | 0.25 |") and len(out) == 4


def test_footing_command_line_quick(tmp_path, monkeypatch, capsys):
    """The demo's command line: the FE and the MPM runs of one soil, their JSON, plot and summary."""
    monkeypatch.setattr("sys.argv", ["demo", "--soil", "cohesive", "--quick", "--output", str(tmp_path)])
    load("demo_footing").main()
    saved = json.loads((tmp_path / "footing_cohesive.json").read_text())
    assert saved["mpm"]["soil"] == "cohesive" and saved["fe"]["failed_at"] is None
    assert saved["mpm"]["q_10_over_c"] is None  # a push of 5 cm does not reach 0.1 B
    row = {"h": 0.1, "ppc": 1, "stress": "cell", **{k: saved["mpm"][k] for k in ("q_10_over_c", "error_10")}}
    row.update(speed=3e-4, courant=0.5, q_u_over_c=5.4, error=0.05, plateau_spread=0.041)
    line = "| 100 | 1 | `cell` | 0.0003 | 0.5 | — | — | 5.40 | +5.0 % | 4.1 % |"
    assert load("demo_footing").study_line(row) == line
    assert (tmp_path / "footing_cohesive.png").stat().st_size > 0
    out = capsys.readouterr().out
    assert "\ncohesive: q_u / c = " in out and out.splitlines()[-1].startswith("MPM: q_u / c = ")


def test_fe_benchmarks_quick_report(tmp_path, monkeypatch):
    """Every benchmark's quick variant runs and the report has a row for each, with its figures."""
    report = tmp_path / "benchmarks.md"
    monkeypatch.setattr("sys.argv", ["fe_benchmarks", "--quick", "--report", str(report)])
    load("fe_benchmarks").main()
    text = report.read_text()
    heads = ("| benchmark |", "| run |")
    rows = [line for line in text.splitlines() if line.startswith("| ") and not line.startswith(heads)]
    assert len(rows) == 9 + 5  # the benchmarks, then what each run cost
    (associated,) = [row for row in rows if row.startswith("| footing, phi = 30 deg, DP matched")]
    mpm, error = associated.split(" | ")[-2:]
    assert "(at s = 0.1 B;" in mpm and error.endswith("% |") and "--quick --report" in text
    for name in ("fe_cylinder", "fe_footing", "fe_oedometer"):
        assert (tmp_path / "images" / f"{name}.png").stat().st_size > 0


def test_footing_mpm_study_reports_a_run_that_went_bad(monkeypatch):
    """A run that stops is a row of the study with its message, and the study goes on."""
    demo = load("demo_footing")
    calls = []

    def run_mpm(kind, h, ppc, speed, progress, stress, courant):
        calls.append(stress)
        if stress == "cell":
            raise dm.SimulationError("step 7, t = 0.1 s: particle 3 at x = [0 0 0] has a non-positive volume")
        q = {"q_u_over_c": 30.0, "error": -0.005, "q_10_over_c": 29.0, "error_10": -0.038}
        return {**q, "plateau_spread": 0.01, "steps": 9}

    monkeypatch.setattr(demo, "run_mpm", run_mpm)
    rows = demo.study_mpm(study={"h": (0.1,), "ppc": (1,), "stress": ("cell", "particle")}, progress=False)
    assert calls == ["cell", "particle"] and "non-positive volume" in rows[0]["failed"]
    head = "| 100 | 1 | `{}` | 0.0003 | 0.25 |"
    assert demo.study_line(rows[0]) == head.format("cell") + " stopped: step 7, t = 0.1 s | | | | |"
    assert demo.study_line(rows[1]) == head.format("particle") + " 29.00 | -3.8 % | 30.00 | -0.5 % | 1.0 % |"


def test_footing_on_frictional_soil_with_the_plane_strain_matched_associated_cone_reaches_prandtl():
    r = load("demo_footing").run("frictional-associated", n=16, steps=10, progress=False)
    assert r["failed_at"] is None
    assert abs(r["error"]) < 0.05  # the 5 % against Mohr-Coulomb's N_c = 30.14
    assert abs(r["plateau"]) < 0.01
    assert r["newton_max"] <= 12


def test_oedometer_follows_k0_then_the_cone(tmp_path):
    demo = load("demo_oedometer")
    r, mpm = demo.run(progress=False), demo.run_mpm()
    assert r["K0_fe"] == pytest.approx(r["K0"], rel=1e-10)
    assert r["error"] < 1e-10  # the whole stress path, elastic and plastic
    assert r["sigma_z_equals_sigma_h"] < 1e-10
    assert r["K0"] < r["K_final_fe"] < r["K_active"]
    # The MPM, loaded slowly enough to be quasi-static, follows the same path.
    assert mpm["K0_mpm"] == pytest.approx(r["K0"], rel=1e-5)
    assert mpm["error"] < 1e-6
    assert r["K0"] < mpm["K_final_mpm"] < r["K_active"]
    demo.save(tmp_path, r, mpm)
    assert (tmp_path / "oedometer.png").exists() and (tmp_path / "oedometer.json").exists()


def unit_square(n=2):
    return mesh.create_rectangle(MPI.COMM_WORLD, [np.zeros(2), np.ones(2)], [n, n], mesh.CellType.triangle)


@pytest.mark.parametrize("psi", [0.0, 10.0])
def test_jacobian_of_a_non_symmetric_tangent_is_the_derivative_of_the_internal_force(psi):
    """Non-associated flow makes the material tangent non-symmetric: the assembled Jacobian must
    apply it as d sigma / d eps (not its transpose)."""
    import dolfinx.fem.petsc

    mat = MohrCoulombDruckerPrager(E=1e7, nu=0.3, rho=1.0, phi=30.0, c=1e3, psi=psi)
    fe = QuasiStatic(unit_square(3), mat)
    rng = np.random.default_rng(3)
    x = fe.V.tabulate_dof_coordinates()[:, :2]
    u0 = np.column_stack([-2e-3 * x[:, 0] + 3e-3 * x[:, 1], -1e-3 * x[:, 1]]).ravel()
    u0 += rng.normal(0.0, 2e-4, u0.shape)  # points in different states
    v = rng.normal(0.0, 1e-3, u0.shape)

    def force(u):
        fe.u.x.array[:] = u
        fe._update_stress()
        return fe.internal_force()

    h = 1e-7
    fd = (force(u0 + h * v) - force(u0 - h * v)) / (2 * h)
    force(u0)
    A = dolfinx.fem.petsc.assemble_matrix(fe._jacobian)
    A.assemble()
    vec, Av = A.createVecRight(), A.createVecLeft()
    vec.setArray(v)
    A.mult(vec, Av)
    D = fe._tangent_q.x.array.reshape(-1, 4, 4)
    assert np.abs(D - D.transpose(0, 2, 1)).max() > 0.05 * mat.E  # the test needs non-symmetric tangents
    np.testing.assert_allclose(Av.getArray(), fd, atol=1e-6 * np.abs(fd).max())


def test_convergence_error_names_the_load_reached():
    msh = unit_square()
    fe = QuasiStatic(msh, VonMises(E=1e9, nu=0.3, rho=1.0, sigma_y=1e6))
    bottom = mesh.locate_entities_boundary(msh, 1, lambda x: np.isclose(x[1], 0.0))
    fe.fix(bottom, 0)
    fe.fix(bottom, 1)
    fe.pressure(mesh.locate_entities_boundary(msh, 1, lambda x: np.isclose(x[0], 0.0)), 1e6)
    with pytest.raises(ConvergenceError, match="did not converge from load") as err:
        fe.advance([0.2, 5.0], min_step=0.05)  # a side pressure of 5 sigma_y: no equilibrium
    assert 0.2 <= err.value.load < 5.0 and err.value.load == fe.load


@pytest.mark.parametrize(
    "kwargs, match",
    [({"degree": 3}, "degree must be 1 or 2"), ({"tol": 0.0}, r"tol must be in \(0, 1\)"),
     ({"max_backtracks": -1}, "max_backtracks must be an integer >= 0")],
)  # fmt: skip
def test_bad_solver_input(kwargs, match):
    with pytest.raises(ValueError, match=match):
        QuasiStatic(unit_square(), VonMises(E=1e9, nu=0.3, rho=1.0, sigma_y=1e6), **kwargs)
