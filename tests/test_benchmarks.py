"""The benchmark scripts run small: their numbers are there and add up."""

import importlib.util
import json
import sys
from pathlib import Path

import pytest
from mpi4py import MPI

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="the benchmarks run on one rank")


def load(name: str):
    spec = importlib.util.spec_from_file_location(name, BENCHMARKS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_silo_step_measures_the_flowing_silo(tmp_path, monkeypatch):
    silo_step = load("silo_step")
    out = tmp_path / "silo_step.json"
    monkeypatch.setattr(sys, "argv", ["silo_step", "--h", "0.01", "--t-from", "0.004", "--runs", "2",
                                      "--steps", "3", "--stream-mb", "8", "--json", str(out)])  # fmt: skip
    silo_step.main()
    (r,) = json.loads(out.read_text())["silo"]
    stages = r["stages_ms_per_step"]
    assert {"neighbours", "averaging", "p2g", "g2p"} <= set(stages)
    assert 0.5 * r["ms_per_step"] < sum(stages.values()) <= 1.01 * r["ms_per_step"]  # stages add up
    assert r["iterations_per_step"] >= 1.0 and r["particles"] == 4800
    assert r["pairs_per_particle"]["within_r_plus_skin"] > r["pairs_per_particle"]["within_r"] > 0.0
    assert r["bandwidth_GB_per_s"]["dram"]["copy"] > 0.1 and r["copy_bytes_per_particle_iteration"] > 0.0
    assert r["bytes_per_particle"]["particles"] >= 8 * (3 + 2 + 9 + 1 + 1)  # x, v, sigma, mass, volume
    assert r["bytes_per_particle"]["pair_lists"] > 4 * r["pairs_per_particle"]["within_r_plus_skin"]


def test_silo_step_refuses_bad_arguments(monkeypatch, capsys):
    silo_step = load("silo_step")
    monkeypatch.setattr(sys, "argv", ["silo_step", "--steps", "0"])
    with pytest.raises(SystemExit) as exit_:
        silo_step.main()
    assert exit_.value.code == 2 and "--steps must be >= 1" in capsys.readouterr().err


def test_mpi_scaling_records_its_run(tmp_path, monkeypatch, capsys):
    mpi_scaling = load("mpi_scaling")
    out = tmp_path / "mpi_scaling.json"
    monkeypatch.setattr(sys, "argv", ["mpi_scaling", "--h", "0.02", "--warmup", "20", "--steps", "5",
                                      "--runs", "1", "--json", str(out)])  # fmt: skip
    mpi_scaling.main()
    r = json.loads(out.read_text())["1"]
    assert r["ms_per_step"] > 0.0 and r["particles"] == r["particles_per_rank_max"] > 0
    assert r["repartitions"] == 0 and r["rebalance_ms_per_step"] == 0.0  # one rank: nothing to deal
    assert {"p2g", "g2p", "neighbours", "averaging"} <= set(r["stages_ms"])
    assert sum(r["stages_ms"].values()) <= r["ms_per_step"] * 1.01
    assert "1 rank(s)" in capsys.readouterr().out
    mpi_scaling.main()  # a second start adds its run to the samples
    r = json.loads(out.read_text())["1"]
    assert len(r["samples"]) == 2
    assert r["ms_per_step"] == pytest.approx(sum(s["ms_per_step"] for s in r["samples"]) / 2)
    monkeypatch.setattr(sys, "argv", [*sys.argv, "--fresh"])
    mpi_scaling.main()
    assert len(json.loads(out.read_text())["1"]["samples"]) == 1
    assert mpi_scaling.speed_up([10.0, 30.0, 12.0], [5.0, 20.0, 4.0]) == 2.0  # pairwise: 1.5, 2, 3


def test_mpi_scaling_refuses_bad_arguments(monkeypatch, capsys):
    mpi_scaling = load("mpi_scaling")
    monkeypatch.setattr(sys, "argv", ["mpi_scaling", "--runs", "0"])
    with pytest.raises(SystemExit) as exit_:
        mpi_scaling.main()
    assert exit_.value.code == 2 and "--runs and --steps must be >= 1" in capsys.readouterr().err


def test_output_cost_measures_each_layout(tmp_path, monkeypatch, capsys):
    output_cost = load("output_cost")
    out = tmp_path / "output_cost.json"
    monkeypatch.setattr(sys, "argv", ["output_cost", "--h", "0.02", "--writes", "2", "--json", str(out)])
    output_cost.main()
    (r,) = json.loads(out.read_text()).values()
    assert r["ranks"] == 1 and r["particles"] > 0 and r["step_s"] > 0.0
    for layout in ("gather", "per-rank"):  # the collective one needs h5py with MPI
        m = r[layout]
        assert m["write_s"] > 0.0
        assert m["bytes_per_write"] > r["particles"] * 8 * (3 + 3 + 9)  # x, velocity, stress at least
        assert m["rank0_peak_bytes"] > r["particles"] * 8 * 9  # the stress copied for the file
    assert "per-rank" in capsys.readouterr().out


def test_step_stability_samples_a_collapse(tmp_path, monkeypatch, capsys):
    step_stability = load("step_stability")
    out = tmp_path / "step_stability.json"
    scenario = BENCHMARKS.parent / "demos" / "column_collapse.toml"
    keys = [
        "nonlocal.radius=0", "mesh.upper=[0.4,0.12]", "mesh.cells=[20,6]",
        "bodies.column.region.max=[0.1,0.1]", "bodies.column.stress.surface=0.1", "time.end=0.02",
    ]  # fmt: skip
    argv = ["step_stability", str(scenario), *[a for k in keys for a in ("--set", k)], "--every", "2"]
    monkeypatch.setattr(sys, "argv", [*argv, "--json", str(out)])
    step_stability.main()
    r = json.loads(out.read_text())
    q = r["e_max_quantiles"]
    assert r["samples"] > 10 and 0.0 < q["0.5"] <= q["1.0"] == r["worst"]["e_max"] < 1.0
    assert r["unstable_samples"] == 0 and r["worst"]["particle"] >= 0
    assert "above 1 in 0" in capsys.readouterr().out
    monkeypatch.setattr(sys, "argv", [*argv[:-1], "0"])
    with pytest.raises(SystemExit) as exit_:
        step_stability.main()
    assert exit_.value.code == 2 and "--every must be >= 1" in capsys.readouterr().err
