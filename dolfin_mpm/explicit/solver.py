"""The explicit material point solver: a model, the run's state, the step and the run loop.

:class:`Solver` checks its input, builds the :class:`~dolfin_mpm.explicit.step.Model` (grid,
materials, walls, gravity, options) and the :class:`~dolfin_mpm.explicit.state.State` (particles,
sinks, time, the non-local average, the loop's history), and advances the state with
:func:`dolfin_mpm.explicit.step.advance`. :meth:`Solver.run_until` is the one run loop: the
scenario runner and :meth:`Solver.run` both drive it.
"""

import math
import warnings
from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np
from mpi4py import MPI

from dolfin_mpm.averaging import NonlocalAverage
from dolfin_mpm.core.boundary import BoundaryCondition
from dolfin_mpm.core.grid import Grid
from dolfin_mpm.core.particles import Particles, Sink
from dolfin_mpm.core.walls import RigidWall
from dolfin_mpm.explicit.energy import mechanical
from dolfin_mpm.explicit.options import Options
from dolfin_mpm.explicit.progress import Progress
from dolfin_mpm.explicit.state import State
from dolfin_mpm.explicit.step import CORRECTION, Model, SimulationError, advance
from dolfin_mpm.explicit.timer import Timer
from dolfin_mpm.materials import Material
from dolfin_mpm.parallel import ids
from dolfin_mpm.parallel.halo import over_ranks
from dolfin_mpm.parallel.rebalance import deal, move_to, renumber, repartition
from dolfin_mpm.params import check_range

__all__ = ["SimulationError", "Solver"]


class Solver:
    """Explicit material point solver on a DOLFINx background grid.

    Args:
        grid: background grid.
        particles: material points (their ``material`` indexes ``materials``; those with
            ``id < 0`` are numbered, see :func:`dolfin_mpm.parallel.ids.number`).
        materials: constitutive models.
        bcs: nodal boundary conditions and rigid walls (:class:`~dolfin_mpm.core.walls.RigidWall`),
            applied in order.
        gravity: body force per unit mass [m/s^2], ``shape=(gdim,)``; default zero.
        sinks: sinks absorbing particles in their regions each step.
        averaging: non-local average of the plastic strain increments; switches on the
            paper's fixed-point loop (see :mod:`dolfin_mpm.explicit.step`). ``None`` or radius 0:
            local.
        **options: the step's numerical options, :class:`~dolfin_mpm.explicit.options.Options`
            (``dt``, ``courant``, ``scheme``, ``flip``, ``damping``, ``on_exit``, ...).

    """

    def __init__(
        self,
        grid: Grid,
        particles: Particles,
        materials: Material | Sequence[Material],
        bcs: Sequence[BoundaryCondition] = (),
        gravity=None,
        sinks: Sequence[Sink] = (),
        averaging: NonlocalAverage | None = None,
        **options,
    ):
        materials = [materials] if isinstance(materials, Material) else list(materials)
        g = np.zeros(grid.gdim) if gravity is None else np.asarray(gravity, dtype=np.float64)
        if g.shape != (grid.gdim,):
            raise ValueError(f"gravity must have {grid.gdim} components, got {gravity!r}")
        opts = Options(**options)
        sinks = {s.name: s for s in sinks}
        if opts.on_exit != "error" and opts.on_exit not in sinks:
            raise ValueError(
                f"on_exit must be 'error' or one of the sinks {list(sinks)}, got {opts.on_exit!r}"
            )
        if averaging is not None and averaging.is_local:
            averaging = None
        if averaging is not None and not any(m.plastic for m in materials):
            raise ValueError("averaging needs a plastic material: elastic increments are zero")
        if len(particles) and not (
            0 <= particles.material.min() and particles.material.max() < len(materials)
        ):
            raise ValueError(f"particles.material must index the {len(materials)} materials")
        particles.ensure_state({k: v for m in materials for k, v in m.state_fields().items()})
        if averaging is not None and averaging.law.iterative:
            needs, what = (
                ("increment_of_rate", "the increment of a given rate (a viscous law)")
                if averaging.law.rates
                else ("perzyna", "a Perzyna law of finite viscosity")
            )
            lacking = [type(m).__name__ for m in materials if m.plastic and not hasattr(m, needs)]
            if needs == "perzyna":  # the rate-independent limit has no overstress to average
                lacking += [f"{type(m).__name__} with gamma = inf" for m in materials
                            if hasattr(m, needs) and not math.isfinite(m.perzyna(1.0)[0])]  # fmt: skip
            if lacking:
                raise ValueError(f"the {averaging.law.name} law needs {what}, which {lacking} do not give")
            particles.ensure_state({CORRECTION: ()})
        ids.number(grid.comm, particles)
        # The waves travel at the p-wave speed through material that itself moves: a step may
        # carry neither a wave nor a particle across more than ``courant`` of a cell.
        top = float(np.max(np.abs(particles.v), initial=0.0))  # scaled: 1e308 m/s does not overflow
        speed = top * float(np.sqrt(np.max(np.sum((particles.v / top) ** 2, axis=1)))) if top > 0 else 0.0
        #: The particles' largest speed at the start [m/s], over the ranks.
        self.start_speed = grid.comm.allreduce(speed, MPI.MAX)
        h_min = grid.comm.allreduce(grid.h_min, MPI.MIN)
        #: The largest stable time step [s]: ``courant * h_min / (max p-wave speed + start_speed)``.
        self.critical_dt = (
            opts.courant * h_min / (max(m.p_wave_speed() for m in materials) + self.start_speed)
        )
        _check_walls(grid, particles, bcs)
        self.model = Model(grid, materials, list(bcs), g, opts)
        average = None if averaging is None else over_ranks(averaging, grid.comm)
        dt = self.critical_dt if opts.dt is None else float(opts.dt)
        if dt > self.critical_dt:
            warnings.warn(
                f"dt = {dt:.4g} s is {dt / self.critical_dt:.3g} times the stable step "
                f"{self.critical_dt:.4g} s (courant {opts.courant:g} x the smallest cell height / the "
                "largest p-wave speed and particle speed): "
                "the explicit step may blow up or give wrong results; leave dt unset to take the stable step",
                RuntimeWarning,
                stacklevel=2,
            )
        self.state = State(particles, sinks, dt, average=average)
        self.timer = Timer()
        #: The axes a :meth:`rebalance` cuts across, in turn (``None``: each part's longest
        #: extent). Cuts the flow does not cross in bulk keep the migration and the halo
        #: rebuilds down (a silo: vertical cuts, ``(0,)``).
        self.partition_axes: tuple[int, ...] | None = None

    # -- the model and the state, by name ---------------------------------------------------------
    grid = property(lambda self: self.model.grid)
    materials = property(lambda self: self.model.materials)
    gravity = property(lambda self: self.model.gravity)
    comm = property(lambda self: self.model.grid.comm)
    particles = property(lambda self: self.state.particles)
    sinks = property(lambda self: self.state.sinks)
    averaging = property(lambda self: self.state.average)
    dt = property(lambda self: self.state.dt)
    step_count = property(lambda self: self.state.step)
    fixed_point = property(lambda self: self.state.fixed_point)
    migrated = property(lambda self: self.state.migrated)
    repartitions = property(lambda self: self.state.repartitions)
    timings = property(lambda self: self.timer.seconds)

    @property
    def time(self) -> float:
        """Simulated time [s]."""
        return self.state.time

    @time.setter
    def time(self, t: float) -> None:
        self.state.time = float(t)

    @property
    def bcs(self) -> list[BoundaryCondition]:
        """The boundary conditions, applied in order (a run may replace the list)."""
        return self.model.bcs

    @bcs.setter
    def bcs(self, bcs: Sequence[BoundaryCondition]) -> None:
        _check_walls(self.grid, self.particles, bcs, self.time)
        self.model.bcs = list(bcs)

    @property
    def damping(self) -> float:
        """Local non-viscous damping factor, in [0, 1) (a run may change it)."""
        return self.model.options.damping

    @damping.setter
    def damping(self, value: float) -> None:
        self.model.options = replace(self.model.options, damping=value)

    def fit_step(self, interval: float) -> None:
        """Shorten the time step to ``interval / k`` [s], the longest that takes whole steps to ``interval``.

        For outputs at exact multiples of ``interval`` [s]; before the first step only. A step that
        fits already (to 1e-9 of a step) stays as it is.
        """
        check_range("interval", interval, 0.0, np.inf, closed=(False, False))
        if self.step_count:
            raise RuntimeError(
                f"fit_step: the run is at step {self.step_count}; fit the step before the first"
            )
        k = math.ceil(interval / self.dt - 1e-9)
        if abs(interval / self.dt - k) > 1e-9:
            self.state.dt = interval / k

    # -- stepping ----------------------------------------------------------------------------------
    def step(self) -> None:
        """Advance particles and grid by one time step ``dt``."""
        advance(self.model, self.state, self.timer)

    def rebalance(self) -> bool:
        """Deal the mesh's cells to the ranks anew by the particles they hold (collective).

        The particles, the nodal boundary conditions, the loop's history of ``R`` and the
        damping's mean velocities follow the new partition (:mod:`dolfin_mpm.parallel.rebalance`);
        the results are those of the old partition to round-off. Returns whether the grid
        changed (never on one rank).
        """
        if self.comm.size == 1:
            return False
        self.timer.start()
        grid, owner = repartition(self.grid, self.particles, self.partition_axes)
        if grid is not None:
            state = self.state
            state.R_changes, state.v_mean = move_to(
                self.grid, grid, owner, self.particles, state.R_changes, state.v_mean
            )
            self._use(grid)
            state.repartitions += 1
        self.timer.lap("rebalance")
        self.state.balanced = self.imbalance()
        return grid is not None

    def deal(self, cells: np.ndarray, ranks: np.ndarray) -> None:
        """Deal the cells as in :attr:`Grid.partition <dolfin_mpm.core.grid.Grid.partition>` (collective).

        For a checkpoint's partition, before its state is restored: the nodal boundary
        conditions follow, the particles not (the checkpoint brings their own).
        """
        self._use(deal(self.grid, cells, ranks))

    def _use(self, grid: Grid) -> None:
        """Run on ``grid``, the same mesh dealt anew: the nodal boundary conditions take its nodes."""
        renumber(self.grid, grid, self.bcs)
        self.model.grid = grid

    def run_until(
        self,
        t_end: float,
        actions: Sequence[tuple[int, Callable[[], None]]] = (),
        origin: int = 0,
        steps: int | None = None,
    ):
        """Step until ``t_end`` [s]; the run loop of every driver.

        Under MPI, every ``rebalance_interval`` steps the cells are dealt to the ranks anew
        (:meth:`rebalance`) where the :meth:`imbalance` exceeds the option ``rebalance`` and
        what the last repartition left (where cells cannot be dealt finer, a repartition that
        did no better is not made again), before the actions of that step.

        Args:
            t_end: the time to reach [s]; whole steps are taken while more than 1e-9 of a
                step remains.
            actions: ``(every, action)`` pairs: ``action()`` runs after each step whose number
                counted from ``origin`` is a multiple of ``every`` (in the order given).
            origin: the step number the counts start from.
            steps: take exactly this many steps instead (the count fixed before the run).

        """
        state, options = self.state, self.model.options
        balance = self.comm.size > 1 and math.isfinite(options.rebalance)
        last = None if steps is None else state.step + steps
        while (t_end - state.time) / state.dt > 1e-9 if last is None else state.step < last:
            self.step()
            if (
                balance
                and state.step % options.rebalance_interval == 0
                and self.imbalance() > max(options.rebalance, state.balanced)
            ):
                self.rebalance()
            for every, action in actions:
                if (state.step - origin) % every == 0:
                    action()

    def run(self, t_end: float, output=None, output_interval: float | None = None, progress: bool = True):
        """Step until ``t_end`` [s], writing ``output`` every ``output_interval`` [s].

        ``output`` is anything with ``write(solver)`` (see :mod:`dolfin_mpm.io.xdmf`); it is
        also written at the start and the end. A :class:`SimulationError` stops the run; what
        was written before stays readable. ``progress`` (the same on every rank) shows time,
        steps/s, ETA and the particle count on rank 0.
        """
        check_range("t_end", t_end, self.time, np.inf, closed=(True, False))
        n_steps = math.ceil((t_end - self.time) / self.dt - 1e-9)
        every = max(1, round(output_interval / self.dt)) if output_interval else max(n_steps, 1)
        bar = Progress(self.time, t_end, self.dt, enabled=progress and self.comm.rank == 0)

        origin = self.step_count

        def show():
            due = bar.due()  # rank 0's clock: all ranks follow it, the count is collective
            if self.comm.size > 1:
                due = self.comm.bcast(due, root=0)
            final = self.step_count - origin == n_steps
            if due or final:
                bar.show(self.time, self.num_particles(), final=final)

        actions = [(every, lambda: output.write(self))] if output is not None else []
        if progress:
            actions.append((1, show))
        if output is not None:
            output.write(self)
        self.run_until(t_end, actions, origin, steps=n_steps)
        if output is not None:
            output.write(self)  # once per time: a no-op when the last step wrote

    # -- global diagnostics (summed over ranks) --------------------------------------------------
    def num_particles(self) -> int:
        return self.comm.allreduce(len(self.particles), MPI.SUM)

    def imbalance(self) -> float:
        """The largest rank's particle count over the mean count (1 on one rank, or with none)."""
        counts = self.comm.allgather(len(self.particles))
        mean = sum(counts) / len(counts)
        return max(counts) / mean if mean > 0 else 1.0

    def total_mass(self) -> float:
        return self.comm.allreduce(float(self.particles.mass.sum()), MPI.SUM)

    def reaction(self, nodes) -> np.ndarray:
        """Contact force ``F_c`` [N] (per metre in 2D) of the last step on ``nodes``, all ranks.

        The force the boundary conditions there exert on the material, ``shape=(gdim,)``;
        ``nodes`` may be a :class:`~dolfin_mpm.core.walls.RigidWall` (its force alone).
        """
        gdim = self.grid.gdim
        if isinstance(nodes, RigidWall):
            return self.comm.allreduce(self.state.reactions.get(nodes, np.zeros(gdim)), MPI.SUM)
        nodes = np.asarray(nodes)
        owned = nodes[nodes < self.grid.num_owned_nodes]
        f = self.grid.f_contact.x.array.reshape(-1, gdim)[owned].sum(axis=0)
        return self.comm.allreduce(f, MPI.SUM)

    def total_momentum(self) -> np.ndarray:
        P = self.particles
        return self.comm.allreduce((P.mass[:, None] * P.v).sum(axis=0), MPI.SUM)

    def energies(self) -> dict[str, float]:
        """The energy balance [J] (per metre in 2D), over the ranks.

        ``kinetic``, ``strain`` and ``potential`` (gravity's, from y = 0 or z = 0) of the
        particles, and ``total`` their sum; since the start, ``dissipated`` (the plastic work of
        the stress updates) and ``sunk`` (the energy of what the sinks absorbed). What the total
        lost beyond these two went to the walls, the damping and the transfers.
        """
        e = mechanical(self.particles, self.materials, self.gravity)
        e["dissipated"] = self.state.dissipated
        e["sunk"] = sum(sink.energy for sink in self.sinks.values())
        e = dict(zip(e, self.comm.allreduce(np.array(list(e.values())), MPI.SUM).tolist()))
        e["total"] = e["kinetic"] + e["strain"] + e["potential"]
        return e


def _check_walls(grid: Grid, particles: Particles, bcs: Sequence, time: float = 0.0) -> None:
    """Raise ``ValueError`` naming a rigid wall outside the mesh or with particles behind it."""
    for bc in bcs:
        if isinstance(bc, RigidWall):
            bc.check(grid, particles, time)
