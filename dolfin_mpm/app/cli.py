"""The command line: ``dolfin-mpm run | check | resume | schema`` (also ``python -m dolfin_mpm``).

    dolfin-mpm check demos/silo.toml                    # validate and build, then stop
    dolfin-mpm run demos/silo.toml --output results/silo --set nonlocal.radius=0
    dolfin-mpm resume results/silo                      # after Ctrl-C, a kill or a crash
    dolfin-mpm check --explain materials.sand.phi       # what a key means and takes
    dolfin-mpm schema -o scenario.schema.json           # the JSON Schema (--reference: the page)

Exit status: 0 done, 1 the run failed (simulation or output), 2 bad input, 128 + signal
number when stopped by SIGINT or SIGTERM (after writing a checkpoint). Under ``mpirun``
every rank runs the same command; rank 0 prints (:mod:`dolfin_mpm.app.log`: ``-q`` only
warnings and errors, ``-v`` the details too). The launcher sets its own status: MPICH's
``mpiexec`` exits with the ranks' 130 or 143; Open MPI's ``mpirun`` sends SIGTERM to the ranks
for Ctrl-C as well, kills them 1 s later, and exits with 1 (:mod:`dolfin_mpm.parallel.launcher`).
Ranks die with their launcher.
"""

import argparse
import json
import warnings
from pathlib import Path

from mpi4py import MPI

from dolfin_mpm.app import scenario, schema
from dolfin_mpm.app.log import LOGGER, configure
from dolfin_mpm.app.runner import CHECKPOINT, FolderLock, Interrupted, RunError, Runner, write_run_info
from dolfin_mpm.explicit.solver import SimulationError
from dolfin_mpm.io import checkpoint
from dolfin_mpm.parallel.launcher import die_with_launcher, launcher_note

__all__ = ["main"]


def _fail(message: str, code: int) -> int:
    LOGGER.error(message)
    return code


def _scenario_errors(source, e: scenario.ScenarioError) -> int:
    if len(e.errors) == 1:
        return _fail(e.errors[0], 2)
    lines = "\n".join(f"  {line}" for line in e.errors)
    return _fail(f"{source}: {len(e.errors)} problems\n{lines}", 2)


def _summary(sim) -> str:
    s, cfg = sim.solver, sim.config
    span = cfg["time"]["end"] - s.time
    parts = [
        f"{s.num_particles()} particles", f"{s.grid.comm.allreduce(s.grid.num_owned_nodes)} nodes",
        f"{len(sim.walls)} walls", f"{len(s.sinks)} sinks", f"dt = {s.dt:.4g} s",
        f"about {max(0, round(span / s.dt))} steps from t = {s.time:.4g} s to {cfg['time']['end']:g} s",
    ]  # fmt: skip
    if s.averaging is not None:
        parts.append(f"non-local r = {s.averaging.radius:g} m ({s.averaging.weight})")
    title = f"{cfg['title']}: " if cfg["title"] else ""
    return title + ", ".join(parts)


def _check(args, comm) -> int:
    if args.explain is not None:
        try:
            LOGGER.info(schema.explain(args.explain))
        except schema.UnknownKey as e:
            return _fail(str(e), 2)
        return 0
    try:
        sim = scenario.build(scenario.load(args.scenario, args.set), comm)
    except scenario.ScenarioError as e:
        return _scenario_errors(args.scenario, e)
    LOGGER.info(f"{args.scenario}: OK. {_summary(sim)}")
    return 0


def _schema(args, comm) -> int:
    text = schema.reference() if args.reference else json.dumps(schema.schema(), indent=2) + "\n"
    if args.output is None:
        LOGGER.info(text.rstrip("\n"))
        return 0
    error = None
    if comm.rank == 0:
        try:
            Path(args.output).write_text(text)
        except OSError as e:
            error = f"cannot write {args.output} ({e.strerror or e})"
    error = comm.bcast(error, root=0)
    return _fail(error, 2) if error else 0


def _run(args, comm) -> int:
    path = Path(args.scenario)
    try:
        cfg = scenario.load(path, args.set)
    except scenario.ScenarioError as e:
        return _scenario_errors(path, e)
    folder = Path(args.output) if args.output else Path("results") / path.stem
    if (folder / CHECKPOINT).exists() and not args.force:
        return _fail(f"{folder} holds a run: continue it with `dolfin-mpm resume {folder}`, "
                     "or start over with --force", 2)  # fmt: skip
    error = None
    if comm.rank == 0:
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            error = f"cannot write to the output folder {folder} ({e.strerror or e})"
    error = comm.bcast(error, root=0)
    if error:
        return _fail(error, 2)

    def start() -> int:  # with the folder locked: --force cannot clobber a live run
        error = None
        if comm.rank == 0:
            try:
                (folder / CHECKPOINT).unlink(missing_ok=True)
                info = {"scenario": str(path.resolve()), "base": str(path.parent.resolve()),
                        "set": list(args.set), "ranks": comm.size}  # fmt: skip
                write_run_info(folder, path.read_text(), info)
            except OSError as e:
                error = f"cannot write to the output folder {folder} ({e.strerror or e})"
        error = comm.bcast(error, root=0)
        if error:
            return _fail(error, 2)
        try:
            sim = scenario.build(cfg, comm)
        except scenario.ScenarioError as e:
            return _scenario_errors(path, e)
        LOGGER.info(f"{_summary(sim)}\nwriting to {folder}")
        return _drive(Runner(sim, folder, progress=not args.quiet), comm, folder)

    return _locked(folder, comm, start)


def _locked(folder: Path, comm, work) -> int:
    """``work()`` with the run folder locked; exit 2 when another run holds it."""
    lock = FolderLock(folder, comm)
    error = lock.acquire()
    if error:
        return _fail(error, 2)
    try:
        return work()
    finally:
        lock.release()


def _resume(args, comm) -> int:
    folder = Path(args.folder)
    try:
        info = json.loads((folder / "run.json").read_text())
    except (OSError, ValueError) as e:
        return _fail(f"{folder} is not a run folder: cannot read run.json ({e})", 2)
    bad = [item for item in args.set if not item.split("=")[0].strip().startswith(checkpoint.RESUMABLE)]
    if bad:
        return _fail(f"--set {bad[0]}: a resumed run may change only time.end and output.*", 2)
    return _locked(folder, comm, lambda: _continue(args, comm, folder, info))


def _continue(args, comm, folder: Path, info: dict) -> int:
    overrides = [*info["set"], *args.set]
    try:
        cfg = scenario.load(folder / "scenario.toml", overrides, base=Path(info["base"]))
        sim = scenario.build(cfg, comm)
    except scenario.ScenarioError as e:
        return _scenario_errors(folder / "scenario.toml", e)
    try:
        data = checkpoint.read(folder / CHECKPOINT, comm)
        checkpoint.restore(sim, data)
    except checkpoint.CheckpointError as e:
        return _fail(str(e), 2)
    if args.set and comm.rank == 0:
        write_run_info(folder, (folder / "scenario.toml").read_text(), {**info, "set": overrides})
    s = sim.solver
    if (cfg["time"]["end"] - s.time) / s.dt < -1e-9:
        return _fail(f"time.end = {cfg['time']['end']:g} s is before the checkpoint's t = {s.time:.6g} s", 2)
    LOGGER.info(f"resuming {folder} at step {s.step_count}, t = {s.time:.6g} s")
    written = int(data["attrs"]["ranks"])
    if written != comm.size:
        LOGGER.info(
            f"the checkpoint was written on {written} rank{'s' * (written > 1)}: on {comm.size}, each "
            "particle went to the owner of its cell and the pair lists were built anew; the run "
            "continues to round-off"
        )
    return _drive(Runner(sim, folder, history=data["history"], progress=not args.quiet), comm, folder)


def _drive(runner: Runner, comm, folder: Path) -> int:
    s = runner.sim.solver
    first = s.step_count
    try:
        runner.run()
    except Interrupted as e:
        runner.progress.end_line()
        LOGGER.warning(f"{e}{launcher_note(comm, e.signum)} at step {s.step_count}, t = {s.time:.6g} s; "
                       f"checkpoint written. Continue with: dolfin-mpm resume {folder}")  # fmt: skip
        return 128 + e.signum
    except (RunError, checkpoint.CheckpointError, SimulationError) as e:
        runner.progress.end_line()
        return _fail(str(e), 1)
    LOGGER.info(f"done: t = {s.time:.6g} s after {s.step_count} steps; results in {folder}")
    for line in _details(s, s.step_count - first):
        LOGGER.debug(line)
    return 0


def _details(s, count: int) -> list[str]:
    """What ``-v`` adds at the end of a run of ``count`` steps: where the time went, what the loop did."""
    times = ", ".join(f"{name} {1e3 * t / max(count, 1):.3g}" for name, t in s.timings.items() if t > 0.0)
    lines = [f"stages [ms per step, over the {count} steps of this run]: {times}"]
    if s.comm.size > 1:
        seconds, total = s.timings.get("rebalance", 0.0), sum(s.timings.values())
        share = 100 * seconds / max(total, 1e-300)
        lines.append(
            f"ranks: {s.repartitions} repartitions in {seconds:.3g} s ({share:.2g} % of the steps' time), "
            f"{s.migrated} particle moves between ranks, imbalance now {s.imbalance():.3f}"
        )
    fp = s.fixed_point
    if s.averaging is not None and fp["steps"] > 0:
        lines.append(
            f"fixed-point loop, over the whole run: {fp['iterations'] / fp['steps']:.2f} iterations per "
            f"step (at most {fp['max_iterations']}), {fp['unconverged']} steps unconverged; pair lists "
            f"rebuilt {s.averaging.rebuilds} times"
        )
    return lines


def parser() -> argparse.ArgumentParser:
    """The argument parser of ``dolfin-mpm``."""
    p = argparse.ArgumentParser(
        prog="dolfin-mpm", description="Material point simulations from scenario files."
    )
    sub = p.add_subparsers(dest="command", required=True)
    overrides = dict(action="append", default=[], metavar="KEY=VALUE",
                     help="override a scenario value, e.g. materials.sand.phi=35 (repeatable)")  # fmt: skip
    quiet = dict(action="store_true", help="no progress display, only warnings and errors")
    verbose = dict(action="store_true", help="also each checkpoint, and the stage times at the end")
    check = sub.add_parser("check", help="validate a scenario and build it, without running")
    check.add_argument("scenario", nargs="?")
    check.add_argument(
        "--explain", metavar="KEY", help="what a key means and takes (materials.sand.phi, walls)"
    )
    check.add_argument("--set", **overrides)
    check.add_argument("-q", "--quiet", **quiet)
    run = sub.add_parser("run", help="run a scenario")
    run.add_argument("scenario")
    run.add_argument("--output", help="run folder (default: results/<scenario name>)")
    run.add_argument("--set", **overrides)
    run.add_argument("--force", action="store_true", help="start over in a folder that holds a run")
    run.add_argument("-q", "--quiet", **quiet)
    run.add_argument("-v", "--verbose", **verbose)
    resume = sub.add_parser("resume", help="continue a run from its last checkpoint")
    resume.add_argument("folder")
    resume.add_argument("--set", **{**overrides, "help": "change time.end or output.* (repeatable)"})
    resume.add_argument("-q", "--quiet", **quiet)
    resume.add_argument("-v", "--verbose", **verbose)
    formats = sub.add_parser("schema", help="write the JSON Schema of scenario files")
    formats.add_argument("-o", "--output", metavar="FILE", help="write to FILE (default: stdout)")
    formats.add_argument("--reference", action="store_true", help="the reference page (Markdown) instead")
    return p


def main(argv=None) -> int:
    """Run the command line ``argv`` (default ``sys.argv[1:]``); returns the exit status."""
    p = parser()
    args = p.parse_args(argv)
    if args.command == "check" and (args.scenario is None) == (args.explain is None):
        p.error("check takes a scenario, or --explain KEY alone")
    comm = MPI.COMM_WORLD
    die_with_launcher(comm)  # no rank writes on after its launcher was killed
    configure(comm, getattr(args, "verbose", False) - getattr(args, "quiet", False))
    command = {"check": _check, "run": _run, "resume": _resume, "schema": _schema}[args.command]
    with warnings.catch_warnings():  # a warning is one line on rank 0, as it comes
        warnings.showwarning = lambda message, *_, **__: LOGGER.warning(str(message))
        return command(args, comm)
