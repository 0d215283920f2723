"""Checkpoints: a run stopped by SIGINT, SIGTERM or SIGKILL and resumed ends bit for bit where
the uninterrupted run ends; a failed checkpoint write leaves the last one intact."""

import errno
import io
import os
import shutil
import signal
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import dolfin_mpm  # noqa: F401  (first: loads DOLFINx's libraries)

# isort: split
import h5py
import numpy as np
import pytest
from mpi4py import MPI

from dolfin_mpm import NonlocalAverage
from dolfin_mpm.app import scenario
from dolfin_mpm.app.cli import main
from dolfin_mpm.explicit.progress import Progress
from dolfin_mpm.io import checkpoint, disk, xdmf

# Sand falls through a plate that opens at t = 5 ms into a sink: non-local averaging with
# kept pairs, particles leaving, an event, damping against the nodes' running mean velocities
# (a nodal state the checkpoint keeps); about 330 steps.
SCENARIO = """
[mesh]
shape = "rectangle"
lower = [0.0, 0.0]
upper = [0.1, 0.12]
cells = [10, 12]

[materials.sand]
model = "drucker_prager"
E = 1e6
nu = 0.3
rho = 1500.0
phi = 30.0
gamma = 1e3

[nonlocal]
radius = 0.01

[bodies.block]
material = "sand"
region = { min = [0.02, 0.05], max = [0.08, 0.1] }
velocity = [0.0, "-1.0 - 10 * (x - 0.05)"]

[walls.sides]
type = "slip"
region = [{ min = [0.0, 0.0], max = [0.0, 0.12] }, { min = [0.1, 0.0], max = [0.1, 0.12] }]
normal = [1.0, 0.0]

[walls.plate]
type = "frictional"
region = { min = [0.0, 0.04], max = [0.1, 0.04] }
normal = [0.0, -1.0]
friction_angle = 20.0

[sinks.below]
region = { min = [-inf, -inf], max = [inf, 0.02] }

[solver]
gravity = [0.0, -9.81]
damping = 0.05
damping_mean_time = 0.005

[time]
end = 0.04

[[events]]
time = 0.005
remove_walls = ["plate"]

[output]
interval = 0.002
checkpoint_interval = 0.004
figures = false
"""


def state(folder: Path) -> dict:
    """Everything in a checkpoint but the history, flattened."""
    out = {}
    with h5py.File(folder / "checkpoint.h5", "r") as f:
        out.update({f"attrs/{k}": np.asarray(v) for k, v in f.attrs.items()})
        f["rank0"].visititems(
            lambda name, d: out.update({name: d[()]}) if isinstance(d, h5py.Dataset) else None
        )
    return out


def same(a: np.ndarray, b: np.ndarray) -> bool:
    """Bit for bit the same values, NaN where the other has NaN (a node without a mean velocity)."""
    return a.dtype == b.dtype and np.array_equal(a, b, equal_nan=a.dtype.kind == "f")


def assert_same(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    for k in a:
        assert same(a[k], b[k]), k


@pytest.fixture(scope="module")
def scenario_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("scenario") / "fall.toml"
    path.write_text(SCENARIO)
    return path


@pytest.fixture(scope="module")
def reference(scenario_file):
    """The uninterrupted run."""
    folder = scenario_file.parent / "reference"
    assert main(["run", str(scenario_file), "--output", str(folder), "--quiet"]) == 0
    s = state(folder)
    # The run exercises what carries state across a restart.
    assert s["sinks/below/count"] > 0 and s["nonlocal/rebuilds"] > 1
    return s


def series(folder: Path, name: str = "particles") -> list[tuple[float, dict]]:
    """The times of ``folder/<name>.xdmf`` with the data each refers to, by attribute name."""
    root = ET.parse(folder / f"{name}.xdmf").getroot()
    out = []
    with h5py.File(folder / f"{name}.h5", "r") as f:
        for grid in root.find("Domain/Grid"):
            items = {a.get("Name"): a.find("DataItem").text for a in grid.iter("Attribute")}
            items["x"] = grid.find("Geometry/DataItem").text
            data = {k: f[text.split(":/")[1]][()] for k, text in items.items()}
            out.append((float(grid.find("Time").get("Value")), data))
    return out


def assert_same_series(folder: Path, reference: Path, extra: tuple = ()) -> None:
    """One series in ``folder`` with the times and the data of the series in ``reference``,
    and the ``extra`` times (a finished run's last state) besides."""
    assert not list(folder.glob("resume-*"))
    for name in ("particles", "grid"):
        ours = [(t, d) for t, d in series(folder, name) if t not in extra]
        theirs = series(reference, name)
        assert [t for t, _ in ours] == [t for t, _ in theirs], name
        for (_, a), (_, b) in zip(ours, theirs):
            assert_same(a, b)
        assert len(ours) + len(extra) == len(series(folder, name))


def test_resume_after_a_finished_shorter_run_is_bit_identical(scenario_file, reference, tmp_path):
    folder = tmp_path / "run"
    assert (
        main(["run", str(scenario_file), "--output", str(folder), "--quiet", "--set", "time.end=0.023"]) == 0
    )
    end = float(np.loadtxt(folder / "history.csv", delimiter=",", skiprows=1)[-1, 0])
    assert main(["resume", str(folder), "--quiet", "--set", "time.end=0.04"]) == 0
    assert_same(state(folder), reference)
    assert_same_series(folder, scenario_file.parent / "reference", extra=(end,))  # and the first end


def test_outputs_are_at_exact_multiples_of_the_interval_from_t_0(scenario_file, reference, tmp_path):
    """The stable step is shortened to a whole fraction of the interval: t = 0, 0.002, ... 0.04 s
    exactly, in the series, the history and the checkpoint; a start off the interval's grid too."""
    folder = scenario_file.parent / "reference"
    want = [k * 0.002 for k in range(21)]
    assert [t for t, _ in series(folder)] == want and [t for t, _ in series(folder, "grid")] == want
    assert np.loadtxt(folder / "history.csv", delimiter=",", skiprows=1)[:, 0].tolist() == want
    assert [v for k, v in reference.items() if k.endswith("time")] == [0.04]
    sim = scenario.build(scenario.load(scenario_file))
    assert (0.002 / sim.solver.dt) == round(0.002 / sim.solver.dt) and sim.solver.dt <= sim.solver.critical_dt
    run = tmp_path / "run"
    overrides = ["time.start=-0.0031", "time.end=0.006"]
    args = ["run", str(scenario_file), "--output", str(run), "-q", *[f"--set={o}" for o in overrides]]
    assert main(args) == 0
    times = [t for t, _ in series(run)]
    assert times[0] <= -0.0031 and times[1:] == [-0.002, 0.0, 0.002, 0.004, 0.006], times


def test_a_checkpoint_of_other_nodes_is_refused(scenario_file, reference):
    """As many nodes, elsewhere (as a mesh cut differently among ranks would give): refused."""
    shifted = ["mesh.lower=[0.0, -0.01]", "mesh.upper=[0.1, 0.11]"]  # 1 cm down: a node row each cm
    sim = scenario.build(scenario.load(scenario_file, shifted))
    data = checkpoint.read(scenario_file.parent / "reference" / "checkpoint.h5", MPI.COMM_WORLD)
    with pytest.raises(checkpoint.CheckpointError, match="grid's nodes, or their partition, differ"):
        checkpoint.restore(sim, data)


def _start(*args):
    return subprocess.Popen(
        [sys.executable, "-m", "dolfin_mpm", *args, "--quiet"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _step_of(path: Path) -> int:
    try:
        with h5py.File(path, "r") as f:
            return int(f.attrs["step"])
    except (OSError, KeyError):
        return -1


def _stop_after_checkpoint(proc, folder: Path, after: int, signum: int) -> int:
    """Send ``signum`` once a checkpoint later than step ``after`` exists; the checkpoint's step."""
    deadline = time.monotonic() + 120
    while _step_of(folder / "checkpoint.h5") <= after:
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline
        time.sleep(0.01)
    step = _step_of(folder / "checkpoint.h5")
    proc.send_signal(signum)
    return step


def test_sigint_sigterm_sigkill_and_resume_end_where_the_uninterrupted_run_ends(
    scenario_file, reference, tmp_path
):
    folder = tmp_path / "run"
    # Ctrl-C: a final checkpoint, a clean exit with 128 + SIGINT.
    proc = _start("run", str(scenario_file), "--output", str(folder))
    _stop_after_checkpoint(proc, folder, 0, signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 128 + signal.SIGINT, err
    assert err.startswith("warning: stopped by SIGINT") and "dolfin-mpm resume" in err  # also with -q
    assert "Traceback" not in err
    interrupted = _step_of(folder / "checkpoint.h5")
    # SIGTERM likewise, after resuming.
    proc = _start("resume", str(folder))
    _stop_after_checkpoint(proc, folder, interrupted, signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 128 + signal.SIGTERM, err
    # SIGKILL: no chance to write anything; the last periodic checkpoint stays.
    proc = _start("resume", str(folder))
    killed_at = _stop_after_checkpoint(proc, folder, _step_of(folder / "checkpoint.h5"), signal.SIGKILL)
    proc.communicate(timeout=60)
    assert proc.returncode == -signal.SIGKILL
    assert _step_of(folder / "checkpoint.h5") >= killed_at < reference["attrs/step"]
    assert not (folder / "checkpoint.h5.tmp").exists() or _step_of(folder / "checkpoint.h5") > 0
    assert main(["resume", str(folder), "--quiet"]) == 0
    assert_same(state(folder), reference)
    # The outputs the killed run wrote after its last checkpoint were dropped and written again.
    assert_same_series(folder, scenario_file.parent / "reference")


def _launcher() -> list[str] | None:
    """The launcher of this MPI (``mpiexec`` beside the interpreter, else ``mpirun``), or ``None``
    when there is none or it is another MPI's."""
    beside = Path(sys.executable).parent / "mpiexec"
    found = str(beside) if beside.exists() else shutil.which("mpirun")
    if found is None:
        return None
    try:
        version = subprocess.run([found, "--version"], capture_output=True, text=True, timeout=30).stdout
    except (OSError, subprocess.SubprocessError):
        return None
    ours = "Open MPI" if "Open MPI" in MPI.Get_library_version() else "HYDRA"
    return [found, "-n", "2"] if ours.lower() in version.lower() else None


def _ranks_of(folder: Path) -> list[int]:
    """Processes whose command line names ``folder``: the run's ranks (and its launcher)."""
    pids = []
    for entry in Path("/proc").iterdir():
        try:
            if entry.name.isdigit() and str(folder) in (entry / "cmdline").read_text():
                pids.append(int(entry.name))
        except OSError:
            pass
    return pids


@pytest.mark.skipif(not sys.platform.startswith("linux") or _launcher() is None, reason="Linux, a launcher")
def test_under_a_launcher_a_signal_checkpoints_and_a_killed_launcher_takes_its_ranks(scenario_file, tmp_path):
    """Ctrl-C to the launcher: a checkpoint and the documented status. SIGKILL to its process
    group (Open MPI's ranks have groups of their own): no rank lives on to write."""
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_", "PMI_", "HYDRA_"))}
    env.update(
        OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1", OMPI_MCA_rmaps_base_oversubscribe="1"
    )
    open_mpi = "Open MPI" in MPI.Get_library_version()

    def start(folder):
        command = [*_launcher(), sys.executable, "-m", "dolfin_mpm", "run", str(scenario_file), "--output",
                   str(folder), "--quiet", "--set", "time.end=10"]  # fmt: skip
        return subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
                                start_new_session=True)  # fmt: skip

    folder = tmp_path / "interrupted"
    proc = start(folder)
    try:
        step = _stop_after_checkpoint(proc, folder, 0, signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        _kill_group(proc)
    assert proc.returncode == (1 if open_mpi else 128 + signal.SIGINT), err
    said = (
        "stopped by SIGTERM (Open MPI's mpirun sends SIGTERM for Ctrl-C too)"
        if open_mpi
        else "stopped by SIGINT"
    )
    assert f"warning: {said}" in err and "checkpoint written" in err and "Traceback" not in err
    assert _step_of(folder / "checkpoint.h5") >= step

    folder = tmp_path / "killed"
    proc = start(folder)
    try:
        deadline = time.monotonic() + 120
        while _step_of(folder / "checkpoint.h5") <= 0:
            assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
            time.sleep(0.01)
        assert len(_ranks_of(folder)) >= 3  # the launcher and two ranks
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate(timeout=60)
        deadline = time.monotonic() + 0.3  # the kernel's kill is at once; Open MPI's own took 0.5-1 s
        while _ranks_of(folder) and time.monotonic() < deadline:
            time.sleep(0.01)
        assert _ranks_of(folder) == []
    finally:
        for pid in _ranks_of(folder):  # nothing left running whatever failed
            os.kill(pid, signal.SIGKILL)


def _kill_group(proc) -> None:
    """The launcher's process group killed, if it is still there."""
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass


def test_a_failed_checkpoint_write_keeps_the_last_one(scenario_file, tmp_path, monkeypatch, capsys):
    folder = tmp_path / "run"
    write_tree = checkpoint._write_tree

    def disk_full_after_the_first(group, tree):
        if group.name == "/history" and (folder / "checkpoint.h5").exists():
            raise OSError(errno.ENOSPC, "No space left on device")
        write_tree(group, tree)

    monkeypatch.setattr(checkpoint, "_write_tree", disk_full_after_the_first)
    assert (
        main(["run", str(scenario_file), "--output", str(folder), "--quiet", "--set", "output.xdmf=false"])
        == 1
    )
    err = capsys.readouterr().err
    assert "No space left on device" in err and "the previous checkpoint is intact" in err
    assert _step_of(folder / "checkpoint.h5") > 0 and not (folder / "checkpoint.h5.tmp").exists()


def test_nonlocal_state_restores_the_kept_pairs_after_removals_and_arrivals():
    """Pairs kept since a rebuild, minus absorbed particles, plus arrived ones: restored exactly."""
    rng = np.random.default_rng(1)
    x, volume, ids = rng.random((440, 2)), rng.random(440), np.arange(440)
    avg = NonlocalAverage(0.1)
    avg.update(x[:400], volume[:400], ids[:400])
    present = np.r_[rng.random(400) > 0.1, np.ones(40, dtype=bool)]  # a sink takes some, 40 arrive
    x = x[present] + 1e-4 * rng.standard_normal((present.sum(), 2))  # within the skin: pairs kept
    avg.update(x, volume[present], ids[present])
    restored = NonlocalAverage(0.1)
    restored.restore(avg.state())
    state = avg.state()
    assert len(state["ids_added"]) == 40 and np.isin(state["ids_built"], state["ids"]).sum() < 400
    x = x + 1e-4 * rng.standard_normal(x.shape)
    e = rng.random(len(x))
    for a in (avg, restored):
        a.update(x, volume[present], ids[present])
    assert np.array_equal(avg(e), restored(e)) and avg.rebuilds == restored.rebuilds == 1


def test_progress_bar_on_a_terminal_and_log_lines_elsewhere():
    class Terminal(io.StringIO):
        def isatty(self):
            return True

    for stream, tty in ((Terminal(), True), (io.StringIO(), False)):
        p = Progress(0.0, 1.0, 0.01, stream=stream, mass_unit="kg/m")
        p.due()
        p.show(0.5, 1234, 2.5)
        text = stream.getvalue()
        assert "t = 5.0000e-01 s" in text and "particles 1234" in text and "discharged 2.5 kg/m" in text
        assert ("[##########----------]  50.0%" in text) == tty and text.startswith("\r") == tty


def _copy_run(reference_folder: Path, tmp_path: Path) -> Path:
    folder = tmp_path / "run"
    folder.mkdir()
    for name in ("checkpoint.h5", "run.json", "scenario.toml"):
        (folder / name).write_bytes((reference_folder / name).read_bytes())
    return folder


def test_a_corrupted_checkpoint_is_refused(scenario_file, reference, tmp_path, capsys):
    """A flipped byte in any array, or an edited attribute, is found by the checksum; values no run
    writes are refused even when the checksum was recomputed after the edit."""
    folder = _copy_run(scenario_file.parent / "reference", tmp_path)
    path = folder / "checkpoint.h5"
    pristine = path.read_bytes()
    with h5py.File(path, "r") as f:
        offsets = [f[name].id.get_offset() for name in ("rank0/particles/sigma", "history/kinetic")]
    for offset in offsets:
        damaged = bytearray(pristine)
        damaged[offset + 3] ^= 0x10
        path.write_bytes(bytes(damaged))
        with pytest.raises(checkpoint.CheckpointError, match="corrupted: its checksum does not match"):
            checkpoint.read(path, MPI.COMM_WORLD)
        assert main(["resume", str(folder), "--quiet"]) == 2
        assert "corrupted" in capsys.readouterr().err
    for edit in ({"time": np.nan}, {"dt": -1.0}):
        path.write_bytes(pristine)
        with h5py.File(path, "r+") as f:
            f.attrs.update(edit)
        with pytest.raises(checkpoint.CheckpointError, match="corrupted: its checksum"):
            checkpoint.read(path, MPI.COMM_WORLD)
        with h5py.File(path, "r+") as f:  # and with a checksum made to match
            f.attrs["sha256"] = checkpoint._seal(dict(f.attrs), {name: f[name].attrs["sha256"] for name in f})
        with pytest.raises(checkpoint.CheckpointError, match="corrupted: time"):
            checkpoint.read(path, MPI.COMM_WORLD)


def test_resume_of_an_edited_scenario_is_refused_naming_the_change(
    scenario_file, reference, tmp_path, capsys
):
    folder = _copy_run(scenario_file.parent / "reference", tmp_path)
    text = (folder / "scenario.toml").read_text()
    (folder / "scenario.toml").write_text(
        text.replace("E = 1e6", "E = 5e6").replace("interval = 0.002", "interval = 0.004")
    )
    assert main(["resume", str(folder), "--quiet", "--set", "time.end=0.05"]) == 2
    err = capsys.readouterr().err
    assert "materials.sand.E (1000000.0 -> 5000000.0)" in err and "output" not in err.split(";")[0]
    (folder / "scenario.toml").write_text(text.replace("interval = 0.002", "interval = 0.004"))
    assert main(["resume", str(folder), "--quiet", "--set", "time.end=0.041"]) == 0  # output may change


def test_a_live_run_folder_is_not_clobbered_and_a_stale_lock_is_taken_over(scenario_file, tmp_path, capsys):
    import json
    import os
    import socket

    folder = tmp_path / "run"
    folder.mkdir()
    (folder / "particles.h5").write_bytes(b"a live run's output")
    (folder / "scenario.toml").write_text(scenario_file.read_text())
    (folder / "run.json").write_text(json.dumps({"set": [], "base": str(scenario_file.parent), "ranks": 1}))
    lock = folder / ".lock"
    lock.write_text(json.dumps({"host": socket.gethostname(), "pid": os.getpid()}))  # alive: us
    for command in (["run", str(scenario_file), "--output", str(folder), "--force"], ["resume", str(folder)]):
        assert main([*command, "--quiet"]) == 2
        assert "is in use by a run" in capsys.readouterr().err
    assert (folder / "particles.h5").read_bytes() == b"a live run's output" and lock.exists()
    gone = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True
    )
    lock.write_text(json.dumps({"host": socket.gethostname(), "pid": int(gone.stdout)}))  # stale
    end = "time.end=0.006"
    assert main(["run", str(scenario_file), "--output", str(folder), "--force", "--quiet", "--set", end]) == 0
    assert not lock.exists() and (folder / "checkpoint.h5").exists()


def test_a_failed_write_leaves_no_temporary_and_a_killed_runs_ones_are_cleared(scenario_file, tmp_path):
    from dolfin_mpm.app.runner import WRITTEN_ATOMICALLY, replace_atomically

    path = tmp_path / "history.csv"
    path.write_text("as it was")

    def fails(tmp):
        tmp.write_text("half")
        raise OSError(errno.ENOSPC, "No space left on device")

    with pytest.raises(OSError, match="No space"):
        replace_atomically(path, fails)
    assert path.read_text() == "as it was" and sorted(p.name for p in tmp_path.iterdir()) == ["history.csv"]
    # A run killed while writing leaves its temporaries: the next run in the folder removes them.
    folder = tmp_path / "run"
    folder.mkdir()
    for name in WRITTEN_ATOMICALLY:
        (folder / f"{name}.tmp").write_text("left by a killed run")
    (folder / "notes.tmp").write_text("not ours")
    end = "time.end=0.006"
    assert main(["run", str(scenario_file), "--output", str(folder), "--quiet", "--set", end]) == 0
    assert [p.name for p in folder.glob("*.tmp")] == ["notes.tmp"]


def test_history_counts_are_whole_numbers_and_a_resume_cannot_go_back_in_time(
    scenario_file, reference, capsys
):
    folder = scenario_file.parent / "reference"
    rows = (folder / "history.csv").read_text().splitlines()
    columns = rows[0].split(",")
    for row in rows[1:]:
        values = dict(zip(columns, row.split(",")))
        assert values["step"].isdigit() and values["particles"].isdigit(), row
    assert main(["resume", str(folder), "--quiet", "--set", "time.end=0.01"]) == 2
    assert "before the checkpoint's t = 0.04" in capsys.readouterr().err


def test_a_disk_that_fills_ends_the_run_cleanly_with_what_was_written_readable(
    scenario_file, tmp_path, monkeypatch, capsys
):
    """HDF5 meeting a full disk halfway leaves its file open and crashes the interpreter at exit:
    a write that would not fit is refused before it starts (room checked by ``io.disk``)."""
    folder, calls = tmp_path / "run", []
    usage = shutil.disk_usage(tmp_path)

    def filling(path):  # room for the first three writes, then none
        calls.append(path)
        return usage._replace(free=usage.free if len(calls) <= 3 else disk.SPARE)

    monkeypatch.setattr(disk.shutil, "disk_usage", filling)
    assert main(["run", str(scenario_file), "--output", str(folder), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert "No space left on device" in err and "bytes free in" in err and "Traceback" not in err
    assert not list(folder.glob("*.tmp"))
    for name in ("particles", "grid"):  # the series written so far open and agree
        times = xdmf.times(folder / f"{name}.xdmf")
        with h5py.File(folder / f"{name}.h5", "r") as f:
            assert len(times) >= 1 and (name == "grid" or len(f) == len(times))


def test_verbosity_quiet_plain_and_verbose(scenario_file, tmp_path, capsys):
    """-q: nothing but warnings and errors; plain: the summary and the end; -v: also each
    checkpoint and, at the end, the stage times and the fixed-point loop's counts."""
    outputs = {}
    for flag in ("-q", None, "-v"):
        folder = tmp_path / str(flag)
        args = ["run", str(scenario_file), "--output", str(folder), "--set", "time.end=0.01"]
        assert main(args + ([flag] if flag else [])) == 0
        outputs[flag] = capsys.readouterr()
    assert outputs["-q"].out == "" and outputs["-q"].err == ""
    plain, verbose = outputs[None].out, outputs["-v"].out
    assert "done: t = " in plain and "checkpoint at step" not in plain and "stages [ms per step" not in plain
    assert verbose.count("checkpoint at step") == 3  # at 4 and 8 ms and at the end
    steps = int(np.loadtxt(tmp_path / "-v" / "history.csv", delimiter=",", skiprows=1)[-1, 1])
    assert f"stages [ms per step, over the {steps} steps of this run]: " in verbose
    assert "fixed-point loop, over the whole run: " in verbose and "pair lists rebuilt" in verbose
    with pytest.raises(SystemExit):
        main(["check", str(scenario_file), "-v"])  # check has nothing more to say


def test_particle_figures_are_named_by_step_and_time_with_units(scenario_file, tmp_path):
    from dolfin_mpm.post.figures import field_unit

    folder = tmp_path / "run"
    overrides = ["time.end=0.008", "output.figures=true", "output.figure_interval=0.004"]
    assert (
        main(
            [
                "run",
                str(scenario_file),
                "--output",
                str(folder),
                "-q",
                *[a for o in overrides for a in ("--set", o)],
            ]
        )
        == 0
    )
    names = sorted(p.name for p in (folder / "figures").glob("particles_*.png"))
    # every 4 ms from t = 0, the end one of them: the step fits the output interval
    assert [n.split("_t")[1] for n in names] == ["0s.png", "0.004s.png", "0.008s.png"], names
    assert all(n.startswith("particles_000000") for n in names)
    assert field_unit("eps_vp_rate_nonlocal", 2) == "1/s" and field_unit("volume", 2) == "m²"
    assert (
        field_unit("volume", 3) == "m³" and field_unit("speed", 3) == "m/s" and field_unit("other", 2) == ""
    )


def test_the_ranks_parts_merged_for_another_number_of_ranks():
    """Sinks' totals summed and their histories combined into the cumulative mass of all ranks."""
    from dolfin_mpm.io.checkpoint import _emptied, _merged

    def part(n, history, first_node):
        particles = {"x": np.full((n, 3), float(first_node)), "state": {"eps": np.arange(n, dtype=float)}}
        sink = {
            "mass": np.array(history[-1][1] if history else 0.0),
            "momentum": np.array([1.0, -2.0]),
            "count": np.array(len(history)),
            "energy": np.array(0.5),
            "history": np.array(history).reshape(-1, 2),
        }
        nodes = np.array([[first_node, 0.0, 0.0], [first_node + 1.0, 0.0, 0.0]])
        R = np.arange(2 * 4, dtype=float).reshape(2, 4) + first_node
        return {"particles": particles, "sinks": {"out": sink}, "nonlocal": {"x_built": np.zeros((1, 2))},
                "R_changes": R, "dissipated": np.array(0.25), "nodes": nodes}  # fmt: skip

    ranks = [part(3, [(0.1, 1.0), (0.3, 3.0)], 0), part(2, [(0.2, 5.0)], 2), part(0, [], 4)]
    whole = _merged(ranks)
    assert whole["resharded"] and whole["nonlocal"] == {}
    assert whole["particles"]["x"].shape == (5, 3) and whole["particles"]["state"]["eps"].tolist() == [
        0,
        1,
        2,
        0,
        1,
    ]
    sink = whole["sinks"]["out"]
    assert sink["mass"] == 8.0 and sink["count"] == 3 and sink["energy"] == 1.5
    assert sink["momentum"].tolist() == [3.0, -6.0]
    assert sink["history"].tolist() == [[0.1, 1.0], [0.2, 6.0], [0.3, 8.0]]
    assert (
        whole["R_changes"].shape == (2, 12) and whole["nodes"].shape == (6, 3) and whole["dissipated"] == 0.75
    )
    empty = _emptied(whole)
    assert empty["particles"]["x"].shape == (0, 3) and empty["particles"]["state"]["eps"].shape == (0,)
    assert empty["sinks"]["out"]["mass"] == 0.0 and empty["sinks"]["out"]["history"].shape == (0, 2)
    assert empty["dissipated"] == 0.0 and empty["R_changes"] is whole["R_changes"]
