"""The demos, run small: each checks the number its Verification section prints."""

import importlib.util
from pathlib import Path

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
    # Local model: the band is the weak row, one cell wide.
    assert local[0]["width_eps_vp"] / local[1]["width_eps_vp"] > 1.6
    # Non-local: the widths of e_vp_bar and of the velocity jump follow r, not h.
    for key in ("width_e_vp_bar", "width_velocity"):
        w = [run[key] for run in nonlocal_]
        assert max(w) / min(w) < 1.2 and min(w) > r
    assert all(run["mean_iterations"] < 5 for run in nonlocal_)
