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
