"""Driving a scenario: the time loop with its events, output, checkpoints, figures and progress.

A run folder holds the scenario it ran (``scenario.toml``, ``run.json``), the XDMF series,
``history.csv`` (time, energies, discharged mass, particle count at each output time),
``checkpoint.h5`` and ``figures/``. Every decision in the loop depends on the step counter
and the simulated time only, never on the wall clock, so a run resumed from a checkpoint
takes exactly the steps the uninterrupted run would have taken.
"""

import csv
import json
import logging
import math
import os
import signal
import socket
from collections.abc import Callable
from contextlib import contextmanager
from pathlib import Path

import numpy as np
from mpi4py import MPI

from dolfin_mpm.app.log import LOGGER
from dolfin_mpm.app.scenario import Simulation
from dolfin_mpm.core.walls import RigidWall
from dolfin_mpm.explicit.progress import Progress
from dolfin_mpm.io import checkpoint
from dolfin_mpm.io.xdmf import Output
from dolfin_mpm.post.figures import field_unit, field_values, plot_curves, plot_particles

__all__ = ["HISTORY", "FolderLock", "Interrupted", "RunError", "Runner"]

#: The columns of ``history.csv``; ``imbalance`` is the largest rank's particle count over the mean.
HISTORY = (
    "t", "step", "kinetic", "strain", "potential", "total", "dissipated", "sunk", "discharged", "particles",
    "imbalance",
)  # fmt: skip
CHECKPOINT = "checkpoint.h5"


class RunError(RuntimeError):
    """Output that cannot be written (folder gone, disk full); names the file and the last checkpoint."""


class Interrupted(Exception):
    """The run stopped on a signal after writing its checkpoint; ``signum`` names the signal."""

    def __init__(self, signum: int):
        self.signum = signum
        super().__init__(f"stopped by {signal.Signals(signum).name}")


@contextmanager
def _catch_signals(flag: dict):
    """SIGINT and SIGTERM set ``flag["signum"]`` instead of stopping the process."""

    def handler(signum, frame):
        flag["signum"] = signum

    previous = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, h in previous.items():
            signal.signal(s, h)


class Runner:
    """Runs a built scenario in ``folder``, fresh or from a checkpoint.

    Args:
        sim: the built scenario (restored from a checkpoint when ``history`` is given).
        folder: the run folder (exists and is writable).
        history: columns recorded before a checkpoint; ``None`` for a fresh run.
        progress: show progress on rank 0.
        stream: where progress goes (default ``sys.stdout``).

    """

    def __init__(self, sim: Simulation, folder, history: dict | None = None, progress=True, stream=None):
        self.sim, self.folder = sim, Path(folder)
        self.comm = sim.solver.comm
        self.root = self.comm.rank == 0
        self.fresh = history is None
        self.history = {k: [] for k in HISTORY}
        for k in HISTORY if history else ():  # a column the run's version did not record: nan
            self.history[k] = list(history[k]) if k in history else [math.nan] * len(history["t"])
        gdim = sim.solver.grid.gdim
        self.mass_unit, self.energy_unit = ("kg/m", "J/m") if gdim == 2 else ("kg", "J")
        s, cfg = sim.solver, sim.config
        self.progress = Progress(
            cfg["time"]["start"], cfg["time"]["end"], s.dt, stream, progress and self.root, self.mass_unit
        )
        self.figures = self.folder / "figures"
        g = s.grid.node_x
        lo, hi = np.empty(3), np.empty(3)
        self.comm.Allreduce(g.min(axis=0, initial=np.inf), lo, MPI.MIN)
        self.comm.Allreduce(g.max(axis=0, initial=-np.inf), hi, MPI.MAX)
        self.bounds = (lo, hi)

    # -- what happens at output times ----------------------------------------------------------
    def _guard(self, what: str, action) -> None:
        """Run ``action`` on rank 0; an OSError there becomes a RunError on every rank."""
        error = None
        if self.root:
            try:
                action()
            except OSError as e:
                error = f"writing {what} failed ({e}); {self._last_checkpoint()}"
        error = self.comm.bcast(error, root=0)
        if error:
            raise RunError(error)

    def _last_checkpoint(self) -> str:
        path = self.folder / CHECKPOINT
        return f"the last checkpoint {path} is intact" if path.exists() else "no checkpoint was written yet"

    def _record(self) -> None:
        s = self.sim.solver
        if self.history["t"] and self.history["t"][-1] == s.time:
            return
        e = s.energies()
        row = (
            s.time,
            s.step_count,
            *(e[k] for k in ("kinetic", "strain", "potential", "total", "dissipated", "sunk")),
        )
        row += (self.sim.discharged_mass(), s.num_particles(), s.imbalance())
        for k, v in zip(HISTORY, row):
            self.history[k].append(v)
        self._guard(self.folder / "history.csv", self._write_history)

    def _write_history(self) -> None:
        def write(tmp: Path) -> None:
            with open(tmp, "w", newline="") as f:
                w = csv.writer(f)
                w.writerow(HISTORY)
                counts = [k in ("step", "particles") for k in HISTORY]  # whole numbers, also after a resume
                rows = zip(*(self.history[k] for k in HISTORY))
                w.writerows([int(v) if count else v for v, count in zip(row, counts)] for row in rows)

        replace_atomically(self.folder / "history.csv", write)

    def _snapshot(self) -> None:
        s, field = self.sim.solver, self.sim.config["output"]["figure_field"]
        if not self.sim.config["output"]["figures"]:
            return
        x = self.comm.gather(s.particles.x, root=0)
        values = self.comm.gather(field_values(s.particles, field), root=0)
        path = self.figures / f"particles_{s.step_count:08d}_t{s.time:.4g}s.png"  # in order, and when
        walls = [w.points + w.velocity * s.time for w in s.bcs if isinstance(w, RigidWall) and w.gdim == 2]
        unit = field_unit(field, s.grid.gdim)

        def plot():
            self.figures.mkdir(exist_ok=True)
            plot_particles(
                path, np.concatenate(x), np.concatenate(values), field, s.time, self.bounds, unit, walls
            )

        self._guard(path, plot)

    def _curves(self) -> None:
        if self.sim.config["output"]["figures"] and len(self.history["t"]) > 1:
            history = {k: np.array(v) for k, v in self.history.items()}

            def plot():
                self.figures.mkdir(exist_ok=True)
                plot_curves(self.figures, history, self.mass_unit, self.energy_unit)

            self._guard(self.figures / "energy.png", plot)

    def _checkpoint(self) -> None:
        history = {k: np.array(v, dtype=np.float64) for k, v in self.history.items()}
        checkpoint.write(self.folder / CHECKPOINT, self.sim, history)
        self._curves()
        s = self.sim.solver
        if LOGGER.isEnabledFor(logging.DEBUG):
            self.progress.end_line()
            LOGGER.debug(f"checkpoint at step {s.step_count}, t = {s.time:.6g} s")

    # -- the loop --------------------------------------------------------------------------------
    def run(self) -> None:
        """Step to the scenario's end time; checkpoint on SIGINT/SIGTERM and raise :class:`Interrupted`.

        Raises:
            Interrupted: after the checkpoint a signal asked for.
            RunError: output or checkpoint could not be written.
            SimulationError: the simulation went bad (what was written stays readable).

        """
        s, cfg = self.sim.solver, self.sim.config
        steps = {
            k: max(1, round(cfg["output"][k] / s.dt))
            for k in ("interval", "checkpoint_interval", "figure_interval")
        }
        output = None
        if cfg["output"]["xdmf"]:
            try:
                # a resumed run extends the series from its checkpoint's time
                layout = None if cfg["output"]["layout"] == "auto" else cfg["output"]["layout"]
                output = Output(self.folder, self.comm, None if self.fresh else s.time, layout)
            except OSError as e:
                raise RunError(f"cannot write the XDMF series in {self.folder} ({e})") from None
        flag = {"signum": 0}
        try:
            with _catch_signals(flag):
                if self.fresh:
                    self._output(output)
                    self._snapshot()
                schedule = [(e["time"], k) for k, e in enumerate(cfg["events"]) if k not in self.sim.applied]
                actions = [
                    (steps["interval"], lambda: self._output(output)),
                    (steps["figure_interval"], self._snapshot),
                    (steps["checkpoint_interval"], self._checkpoint),
                    (1, lambda: self._poll(flag)),
                ]
                origin = s.step_count - round(s.time / s.dt)  # the step at t = 0: counts go from there
                for t_target, event in [*schedule, (cfg["time"]["end"], None)]:
                    s.run_until(t_target, actions, origin)
                    if event is not None:
                        self.sim.apply_event(event)
                self._output(output)
                self._snapshot()
                self._checkpoint()
                self.progress.show(
                    s.time, s.num_particles(), self.sim.discharged_mass(), self._imbalance(), final=True
                )
        finally:
            if output is not None:
                output.close()

    def _output(self, output) -> None:
        self._land()
        self._record()
        if output is not None:
            try:
                output.write(self.sim.solver)  # collective
            except OSError as e:
                message = f"writing the XDMF series in {self.folder} failed ({e}); {self._last_checkpoint()}"
                if self.comm.size > 1:  # the other ranks are past the write: stop them all
                    LOGGER.error(message)
                    self.comm.Abort(1)
                raise RunError(message) from None

    def _land(self) -> None:
        """Put the clock on the multiple of the output interval it is at to round-off (1e-9 of a step).

        ``k dt`` and ``k' interval`` differ in their last bits: the files say 0.025, not 0.025000000000000001.
        """
        s, interval = self.sim.solver, self.sim.config["output"]["interval"]
        k = round(s.time / interval)
        if abs(s.time - k * interval) <= 1e-9 * s.dt:
            s.time = k * interval

    def _imbalance(self) -> float | None:
        """The particle imbalance over the ranks for the progress line; ``None`` on one rank."""
        return self.sim.solver.imbalance() if self.comm.size > 1 else None

    def _poll(self, flag: dict) -> None:
        """Refresh the progress when due; on a signal, checkpoint and raise :class:`Interrupted`.

        Both decisions are the same on every rank.
        """
        due = self.progress.due()
        signum = flag["signum"]
        if self.comm.size > 1:
            flags = np.empty(2, dtype=np.int64)
            self.comm.Allreduce(np.array([signum, int(due)], dtype=np.int64), flags, MPI.MAX)
            signum, due = int(flags[0]), bool(flags[1])
        s = self.sim.solver
        if due:
            self.progress.show(s.time, s.num_particles(), self.sim.discharged_mass(), self._imbalance())
        if signum:
            self._checkpoint()
            raise Interrupted(signum)


class FolderLock:
    """A run folder's lock: one run at a time writes into a folder (``.lock``, rank 0).

    The lock file is created atomically and holds the host and process id of its run. A lock
    whose process is gone on this host is stale and taken over; a live one, or one of another
    host, is refused. Collective: every rank learns the outcome.
    """

    NAME = ".lock"

    def __init__(self, folder: Path, comm):
        self.path, self.comm, self.held = Path(folder) / self.NAME, comm, False

    def acquire(self) -> str | None:
        """Take the lock; ``None`` when taken, else why not (the same on every rank)."""
        error = None
        if self.comm.rank == 0:
            error = self._take()
            self.held = error is None
        return self.comm.bcast(error, root=0)

    def _take(self) -> str | None:
        me = {"host": socket.gethostname(), "pid": os.getpid()}
        for _ in range(2):
            try:
                fd = os.open(self.path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
            except FileExistsError:
                try:
                    owner = json.loads(self.path.read_text())
                except (OSError, ValueError):
                    owner = {}
                if owner.get("host") == me["host"] and not _alive(owner.get("pid")):
                    self.path.unlink(missing_ok=True)  # stale: its run is gone
                    continue
                who = f"process {owner.get('pid', '?')} on {owner.get('host', '?')}"
                return (
                    f"{self.path.parent} is in use by a run ({who}); wait for it to end, or remove "
                    f"{self.path} if that run is gone"
                )
            except OSError as e:
                return f"cannot lock the run folder {self.path.parent} ({e.strerror or e})"
            with os.fdopen(fd, "w") as f:
                json.dump(me, f)
            for name in WRITTEN_ATOMICALLY:  # what a killed run was writing: never renamed, never read
                (self.path.parent / f"{name}.tmp").unlink(missing_ok=True)
            return None
        return f"cannot lock the run folder {self.path.parent}"

    def release(self) -> None:
        if self.held:
            self.path.unlink(missing_ok=True)
            self.held = False


def _alive(pid) -> bool:
    """Whether process ``pid`` runs on this host."""
    try:
        os.kill(int(pid), 0)
    except (TypeError, ValueError, ProcessLookupError):
        return False
    except PermissionError:
        return True
    return True


def write_run_info(folder: Path, scenario_text: str, info: dict) -> None:
    """Store the scenario text and how it was run (``run.json``) in ``folder``, atomically."""
    for name, text in (("scenario.toml", scenario_text), ("run.json", json.dumps(info, indent=1))):
        replace_atomically(folder / name, lambda tmp, text=text: tmp.write_text(text))


#: The files a run writes through a temporary beside them (``<name>.tmp``).
WRITTEN_ATOMICALLY = (CHECKPOINT, "history.csv", "scenario.toml", "run.json")


def replace_atomically(path: Path, write: Callable[[Path], None]) -> None:
    """``write`` the file ``path`` as ``<path>.tmp`` then rename it: ``path`` is whole or as it was.

    A failed write removes its temporary and raises its error.
    """
    tmp = path.with_name(path.name + ".tmp")
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
