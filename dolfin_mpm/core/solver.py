"""The explicit MPM time step: locate -> P2G -> nodal solve -> G2P -> stress update.

One step advances ``M a = F + F_c - R`` (the paper's eq. 4) with the lumped mass matrix,
in the USL or MUSL variant, with a PIC/FLIP blend for the particle velocities.
"""

import math
import time
from collections import defaultdict
from collections.abc import Sequence
from contextlib import contextmanager

import numpy as np
from mpi4py import MPI

from dolfin_mpm.app.progress import Progress
from dolfin_mpm.averaging.nonlocal_average import NonlocalAverage
from dolfin_mpm.core.anderson import Anderson
from dolfin_mpm.core.boundary import BoundaryCondition
from dolfin_mpm.core.grid import Grid
from dolfin_mpm.core.locate import Basis, basis_at, locate
from dolfin_mpm.core.particles import Particles, Sink
from dolfin_mpm.core.transfer import gradient, internal_force, interpolate, scatter, volume_ratio
from dolfin_mpm.materials import DruckerPragerViscoplastic, Material, check_range
from dolfin_mpm.parallel.halo import DistributedAverage
from dolfin_mpm.parallel.migration import migrate

__all__ = ["SimulationError", "Solver"]

STAGES = ("locate", "basis", "p2g", "nodal_solve", "g2p", "constitutive")


class SimulationError(RuntimeError):
    """A run that went bad (non-finite state, particle lost); names the step and the particle."""


class Solver:
    """Explicit material point solver on a DOLFINx background grid.

    Args:
        grid: background grid.
        particles: material points (their ``material`` indexes ``materials``).
        materials: constitutive models.
        bcs: nodal boundary conditions, applied in order.
        gravity: body force per unit mass [m/s^2], ``shape=(gdim,)``; default zero.
        dt: time step [s]; default ``courant * h_min / max p-wave speed``.
        courant: Courant factor for the automatic step, in (0, 1].
        scheme: ``"MUSL"`` (velocities re-mapped before the strain rate) or ``"USL"``.
        flip: FLIP fraction of the particle velocity update, in [0, 1] (1 = pure FLIP).
        damping: local non-viscous (Cundall) damping factor, in [0, 1).
        sinks: sinks absorbing particles in their regions each step.
        on_exit: ``"error"`` to stop when a particle leaves the grid, or the name of a sink
            in ``sinks`` that receives it.
        mass_tol: nodes with mass below ``mass_tol * max nodal mass`` are left at rest.
        averaging: non-local average of the viscoplastic strain increments; switches on the
            paper's fixed-point loop (see :meth:`_step_nonlocal`). ``None`` or radius 0: local.
        fixed_point_tol: loop tolerance on the relative change of ``R``, > 0.
        fixed_point_max_iter: most iterates per step (a step that reaches it is counted in
            ``fixed_point["unconverged"]``), >= 1.
        relaxation: under-relaxation of the ``R`` iterates, in (0, 1].
        anderson_depth: Anderson acceleration depth of the loop, >= 0 (0: plain iteration).
        extrapolation: order 0, 1 or 2 of the loop's first iterate: ``R`` of the stresses at
            the start of the step (0, the paper's), plus the change the last step's stress
            update made to ``R`` (1), or that change extrapolated over the last two steps (2).

    """

    def __init__(
        self,
        grid: Grid,
        particles: Particles,
        materials: Material | Sequence[Material],
        bcs: Sequence[BoundaryCondition] = (),
        gravity=None,
        dt: float | None = None,
        courant: float = 0.5,
        scheme: str = "MUSL",
        flip: float = 1.0,
        damping: float = 0.0,
        sinks: Sequence[Sink] = (),
        on_exit: str = "error",
        mass_tol: float = 1e-10,
        averaging: NonlocalAverage | None = None,
        fixed_point_tol: float = 1e-3,
        fixed_point_max_iter: int = 50,
        relaxation: float = 1.0,
        anderson_depth: int = 5,
        extrapolation: int = 2,
    ):
        self.grid, self.particles = grid, particles
        self.materials = [materials] if isinstance(materials, Material) else list(materials)
        self.bcs = list(bcs)
        g = np.zeros(grid.gdim) if gravity is None else np.asarray(gravity, dtype=np.float64)
        if g.shape != (grid.gdim,):
            raise ValueError(f"gravity must have {grid.gdim} components, got {gravity!r}")
        self.gravity = g
        check_range("courant", courant, 0.0, 1.0, closed=(False, True))
        check_range("flip", flip, 0.0, 1.0, closed=(True, True))
        check_range("damping", damping, 0.0, 1.0, closed=(True, False))
        check_range("mass_tol", mass_tol, 0.0, 1.0, closed=(True, False))
        if scheme not in ("USL", "MUSL"):
            raise ValueError(f"scheme must be 'USL' or 'MUSL', got {scheme!r}")
        self.scheme, self.flip, self.damping, self.mass_tol = scheme, flip, damping, mass_tol
        self.sinks = {s.name: s for s in sinks}
        if on_exit != "error" and on_exit not in self.sinks:
            raise ValueError(
                f"on_exit must be 'error' or one of the sinks {list(self.sinks)}, got {on_exit!r}"
            )
        self.on_exit = on_exit
        self.averaging = None if averaging is None or averaging.is_local else averaging
        if self.averaging is not None and self.comm.size > 1:
            self.averaging = DistributedAverage(self.averaging, self.comm)
        if self.averaging is not None and (
            len(self.materials) != 1 or not isinstance(self.materials[0], DruckerPragerViscoplastic)
        ):
            raise ValueError(
                "averaging needs exactly one material with a split update (DruckerPragerViscoplastic)"
            )
        check_range("fixed_point_tol", fixed_point_tol, 0.0, np.inf)
        if not (isinstance(fixed_point_max_iter, (int, np.integer)) and fixed_point_max_iter >= 1):
            raise ValueError(f"fixed_point_max_iter must be an integer >= 1, got {fixed_point_max_iter!r}")
        check_range("relaxation", relaxation, 0.0, 1.0, closed=(False, True))
        if not (isinstance(anderson_depth, (int, np.integer)) and anderson_depth >= 0):
            raise ValueError(f"anderson_depth must be an integer >= 0, got {anderson_depth!r}")
        self.anderson_depth = anderson_depth
        if not (isinstance(extrapolation, (int, np.integer)) and 0 <= extrapolation <= 2):
            raise ValueError(f"extrapolation must be 0, 1 or 2, got {extrapolation!r}")
        self.extrapolation = extrapolation
        #: The changes of the owned ``R`` over the last steps' fixed-point loops, latest first.
        self.R_changes: list[np.ndarray] = []
        self.fixed_point_tol, self.fixed_point_max_iter, self.relaxation = (
            fixed_point_tol,
            fixed_point_max_iter,
            relaxation,
        )
        #: Fixed-point loop statistics: steps, total and largest iteration count, unconverged steps.
        self.fixed_point = {"steps": 0, "iterations": 0, "max_iterations": 0, "unconverged": 0}
        if len(particles) and not (
            0 <= particles.material.min() and particles.material.max() < len(self.materials)
        ):
            raise ValueError(f"particles.material must index the {len(self.materials)} materials")
        for m in self.materials:
            for name, shape in m.state_fields().items():
                particles.state.setdefault(name, np.zeros((len(particles), *shape)))
        # Global particle numbers, unique across ranks.
        offset = self.comm.exscan(len(particles)) or 0
        particles.id = offset + np.arange(len(particles), dtype=np.int64)

        self.critical_dt = (
            courant * self.comm.allreduce(grid.h_min, MPI.MIN) / max(m.p_wave_speed() for m in self.materials)
        )
        if dt is not None:
            check_range("dt", dt, 0.0, np.inf)
        self.dt = self.critical_dt if dt is None else float(dt)
        self.time = 0.0
        self.step_count = 0
        self.migrated = 0  #: particles moved between ranks since construction (not checkpointed)
        self.timings: dict[str, float] = defaultdict(float)

    @property
    def comm(self):
        return self.grid.comm

    @contextmanager
    def _stage(self, name: str):
        t0 = time.perf_counter()
        yield
        self.timings[name] += time.perf_counter() - t0

    # -- the step ------------------------------------------------------------------------------
    def step(self) -> None:
        """Advance particles and grid by one time step ``dt``."""
        dt = self.dt
        with self._stage("locate"):
            cells, N = self._locate()
        with self._stage("basis"):
            basis = basis_at(self.grid, cells, N)
        with self._stage("p2g"):
            self._p2g(basis)
        if self.averaging is None:
            with self._stage("nodal_solve"):
                self._nodal_solve(dt)
            with self._stage("g2p"):
                v, v_grid, L = self._g2p(basis, dt)
            with self._stage("constitutive"):
                self._update_stress(L, dt)
            self._move(v, v_grid, dt)
        else:
            self._step_nonlocal(basis, dt)
        self.time += dt
        self.step_count += 1
        self._check_finite()

    def _locate(self) -> tuple[np.ndarray, np.ndarray]:
        """Absorb particles into sinks, then find every particle's cell and basis values."""
        P = self.particles
        for sink in self.sinks.values():
            if sink.region is not None:
                sink.absorb(P, np.asarray(sink.region(P.x.T), dtype=bool), self.time)
        cells, N = locate(self.grid, P.x, P.cell)
        if self.comm.size > 1:
            with self._stage("migrate"):
                sent = migrate(self.grid, P, cells)
                self.migrated += sent
                if sent:
                    cells, N = locate(self.grid, P.x, P.cell)
        lost = cells < 0
        if np.any(lost):
            if self.on_exit == "error":
                i = np.flatnonzero(lost)[0]
                raise SimulationError(
                    f"step {self.step_count}, t = {self.time:.6g} s: particle {P.id[i]} left the "
                    f"grid at x = {P.x[i]} ({lost.sum()} particles outside)"
                )
            self.sinks[self.on_exit].absorb(P, lost, self.time)
            cells, N = cells[~lost], N[:, ~lost]
        P.cell = cells
        return cells, N

    def _p2g(self, basis: Basis) -> None:
        """Lumped mass, momentum, external force ``F`` and internal force ``R`` at the nodes."""
        P, grid = self.particles, self.grid
        m = grid.assemble(grid.mass, scatter(basis, P.mass))
        grid.assemble(grid.momentum, scatter(basis, self._momenta(P.v)))
        grid.f_ext.x.array[:] = (m[:, None] * self.gravity).ravel()  # from the assembled mass
        grid.assemble(grid.f_int, internal_force(basis, P.sigma, P.volume))
        self._inv_m = self._inverse_mass()

    def _inverse_mass(self) -> np.ndarray:
        """``1 / m`` at nodes heavier than ``mass_tol * max m``, 0 elsewhere, ``shape=(num_nodes,)``."""
        m = self.grid.mass.x.array
        m_max = self.comm.allreduce(m.max() if m.size else 0.0, MPI.MAX)
        active = m > self.mass_tol * m_max
        inv_m = np.zeros_like(m)
        inv_m[active] = 1.0 / m[active]
        return inv_m

    def _apply_bcs(self, v: np.ndarray) -> None:
        for bc in self.bcs:
            bc.apply(v)

    def _nodal_solve(self, dt: float) -> None:
        """Nodal velocities at the end of the step from ``M a = F + F_c - R``.

        ``F_c`` is the force the boundary conditions need against ``F - R`` (the reaction).
        Damping then acts on the out-of-balance force ``F + F_c - R``, so that it neither
        enters the reaction nor resists the motion a boundary condition prescribes.
        """
        grid, gdim = self.grid, self.grid.gdim
        inv_m = self._inv_m[:, None]
        m = grid.mass.x.array[:, None]
        v = grid.momentum.x.array.reshape(-1, gdim) * inv_m
        f = (grid.f_ext.x.array - grid.f_int.x.array).reshape(-1, gdim)
        v_trial = v + dt * f * inv_m
        v_new = v_trial.copy()
        self._apply_bcs(v_new)
        f_contact = m * (v_new - v_trial) / dt
        if self.damping > 0.0:
            f_out = f + f_contact
            v_new = v + dt * (f_out - self.damping * np.abs(f_out) * np.sign(v)) * inv_m
            self._apply_bcs(v_new)
        grid.f_contact.x.array[:] = f_contact.ravel()
        grid.velocity.x.array[:] = v_new.ravel()
        grid.acceleration.x.array[:] = ((v_new - v) / dt).ravel()

    def _g2p(self, basis: Basis, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Particle velocities from the grid, without moving the particles.

        Returns:
            The new particle velocities (PIC/FLIP blend) and the grid velocity at the
            particles that moves them, both ``shape=(n, gdim)``, and the velocity gradient
            ``shape=(n, gdim, gdim)``.

        """
        P, grid, gdim = self.particles, self.grid, self.grid.gdim
        v_grid = grid.velocity.x.array.reshape(-1, gdim)
        a_grid = grid.acceleration.x.array.reshape(-1, gdim)
        v_interp = interpolate(basis, v_grid)
        if self.flip == 1.0:
            v = P.v + dt * interpolate(basis, a_grid)
        elif self.flip > 0.0:
            v = self.flip * (P.v + dt * interpolate(basis, a_grid)) + (1.0 - self.flip) * v_interp
        else:
            v = v_interp
        if self.scheme == "MUSL":
            # Re-mapped momentum goes into `velocity`: `momentum` keeps the step's start.
            p = grid.assemble(grid.velocity, scatter(basis, self._momenta(v)))
            v_grid = p * self._inv_m[:, None]
            self._apply_bcs(v_grid)
            grid.velocity.x.array[:] = v_grid.ravel()
        return v, v_interp, gradient(basis, v_grid)

    def _move(self, v: np.ndarray, v_grid: np.ndarray, dt: float) -> None:
        """Commit the particle velocities ``v`` and move the particles with ``v_grid``."""
        P = self.particles
        P.v = v
        for c in range(self.grid.gdim):  # by columns: numpy is slow over short rows
            P.x[:, c] += dt * v_grid[:, c]

    def _momenta(self, v: np.ndarray) -> np.ndarray:
        """The particles' momenta ``m_p v_p`` for velocities ``v``, ``shape=(n, gdim)``."""
        m, out = self.particles.mass, np.empty_like(v)
        for c in range(v.shape[1]):  # by columns: numpy is slow over short rows
            np.multiply(m, v[:, c], out=out[:, c])
        return out

    def _update_stress(self, L: np.ndarray, dt: float) -> None:
        """Stress and state from each material; volume from ``det(I + dt L)``."""
        P = self.particles
        if len(self.materials) == 1:
            P.sigma = self.materials[0].update(P.sigma, L, dt, P.state)
        else:
            for k, material in enumerate(self.materials):
                idx = np.flatnonzero(P.material == k)
                state = {name: P.state[name][idx] for name in material.state_fields()}
                P.sigma[idx] = material.update(P.sigma[idx], L[idx], dt, state)
                for name, a in state.items():
                    P.state[name][idx] = a
        P.volume *= volume_ratio(L, dt)

    def _step_nonlocal(self, basis: Basis, dt: float) -> None:
        """The paper's step (§3): a fixed-point loop on the internal forces ``R``.

        Each iterate solves ``M a = F + F_c - R`` with the latest ``R``, maps the velocities
        to the particles, runs the local return mapping (increments ``de``), averages them,
        ``de_bar = A de``, evaluates the stresses with the non-local increment -- direction of
        the trial deviator, ``q = max(q_trial - 2 G max(de, de_bar), 0)`` (see
        :mod:`dolfin_mpm.materials.drucker_prager`) -- and from them ``R`` again. The first
        iterate is ``R`` of the stresses at the start of the step (the plain explicit step, as
        in the paper) plus, with ``extrapolation``, the change of ``R`` that the stress update
        made in the last step (order 1) or extrapolated over the last two steps (order 2):
        the loop's fixed point is the same, it starts closer to it. The loop ends when ``R``
        (and with it ``F_c``; ``F`` is fixed) changes by less than ``fixed_point_tol`` relative
        to ``max(|R|, |F|)``. The iterates of ``R`` are mixed with ``relaxation`` and Anderson
        acceleration.
        """
        P, grid, mat, avg = self.particles, self.grid, self.materials[0], self.averaging
        owned = grid.num_owned_nodes * grid.gdim
        with self._stage("neighbours"):
            avg.update(P.x[:, : grid.gdim], P.volume, P.id)
        f_ext = grid.f_ext.x.array[:owned]
        scale_F = math.sqrt(self.comm.allreduce(float(f_ext @ f_ext), MPI.SUM))
        R_start = R_in = grid.f_int.x.array[:owned].copy()
        if self.R_changes and self.extrapolation:
            R_in = R_start + self._predicted_change()
            grid.f_int.x.array[:owned] = R_in
            grid.f_int.x.scatter_forward()
        mixer = Anderson(self.anderson_depth, self.comm)
        for k in range(1, self.fixed_point_max_iter + 1):
            with self._stage("nodal_solve"):
                self._nodal_solve(dt)
            with self._stage("g2p"):
                v, v_grid, L = self._g2p(basis, dt)
            with self._stage("constitutive"):
                with self._stage("return_mapping"):
                    trial = mat.trial(P.sigma, L, dt)
                    de = mat.increment(trial, dt)
                with self._stage("averaging"):
                    de_bar = avg(de)
                with self._stage("return_mapping"):
                    sigma = mat.stress(trial, de, de_bar)
                volume = P.volume * volume_ratio(L, dt)
            with self._stage("p2g"):
                R = grid.assemble(grid.f_int, internal_force(basis, sigma, volume))
                R = R.ravel()[:owned].copy()  # f_int takes the next iterate below
                norms = self.comm.allreduce(np.array([(R - R_in) @ (R - R_in), R @ R]), MPI.SUM)
                if math.sqrt(norms[0]) <= self.fixed_point_tol * max(math.sqrt(norms[1]), scale_F, 1e-300):
                    break
                R_next = R_in + self.relaxation * (R - R_in)
                R_in = mixer(R_in, R_next)  # depth 0: R_next itself
                grid.f_int.x.array[:owned] = R_in
                grid.f_int.x.scatter_forward()
        else:
            self.fixed_point["unconverged"] += 1
        stats = self.fixed_point
        stats["steps"] += 1
        stats["iterations"] += k
        stats["max_iterations"] = max(stats["max_iterations"], k)
        if self.extrapolation:
            self.R_changes = [R - R_start, *self.R_changes][: self.extrapolation]
        P.sigma, P.volume = sigma, volume
        mat.record(P.state, de, de_bar, dt)
        self._move(v, v_grid, dt)

    def _predicted_change(self) -> np.ndarray:
        """The change of the owned ``R`` in this step, extrapolated from the last steps' changes."""
        dR = self.R_changes[: self.extrapolation]
        return 2.0 * dR[0] - dR[1] if len(dR) == 2 else dR[0]

    def _check_finite(self) -> None:
        P = self.particles
        if np.isfinite(P.sigma.sum() + P.v.sum() + P.x.sum()) and np.all(P.volume > 0.0):
            return  # finite sums have finite terms (an overflowing sum only costs the full check)
        bad = ~(
            np.isfinite(P.sigma).all(axis=(1, 2))
            & np.isfinite(P.v).all(axis=1)
            & np.isfinite(P.x).all(axis=1)
        )
        bad |= ~(P.volume > 0.0)
        if np.any(bad):
            i = np.flatnonzero(bad)[0]
            raise SimulationError(
                f"step {self.step_count}, t = {self.time:.6g} s: particle {P.id[i]} at x = {P.x[i]} "
                f"has non-finite stress or velocity, or non-positive volume ({bad.sum()} particles)"
            )

    # -- driving a run -------------------------------------------------------------------------
    def run(self, t_end: float, output=None, output_interval: float | None = None, progress: bool = True):
        """Step until ``t_end`` [s], writing ``output`` every ``output_interval`` [s].

        ``output`` is anything with ``write(solver)`` (see :mod:`dolfin_mpm.io.xdmf`); it is also
        written at the start and the end. A :class:`SimulationError` stops the run; what was
        written before stays readable. ``progress`` (the same on every rank) shows time,
        steps/s, ETA and the particle count on rank 0.
        """
        check_range("t_end", t_end, self.time, np.inf, closed=(True, False))
        n_steps = math.ceil((t_end - self.time) / self.dt - 1e-9)
        every = max(1, round(output_interval / self.dt)) if output_interval else max(n_steps, 1)
        bar = Progress(self.time, t_end, self.dt, enabled=progress and self.comm.rank == 0)
        if output is not None:
            output.write(self)
        for k in range(1, n_steps + 1):
            self.step()
            if output is not None and (k % every == 0 or k == n_steps):
                output.write(self)
            if progress:
                due = bar.due()  # rank 0's clock: all ranks follow it, the count is collective
                if self.comm.size > 1:
                    due = self.comm.bcast(due, root=0)
                if due or k == n_steps:
                    bar.show(self.time, self.num_particles(), final=k == n_steps)

    # -- global diagnostics (summed over ranks) --------------------------------------------------
    def num_particles(self) -> int:
        return self.comm.allreduce(len(self.particles), MPI.SUM)

    def total_mass(self) -> float:
        return self.comm.allreduce(float(self.particles.mass.sum()), MPI.SUM)

    def reaction(self, nodes: np.ndarray) -> np.ndarray:
        """Contact force ``F_c`` [N] (per metre in 2D) of the last step on ``nodes``, all ranks.

        The force the boundary conditions there exert on the material, ``shape=(gdim,)``.
        """
        gdim = self.grid.gdim
        nodes = np.asarray(nodes)
        owned = nodes[nodes < self.grid.num_owned_nodes]
        f = self.grid.f_contact.x.array.reshape(-1, gdim)[owned].sum(axis=0)
        return self.comm.allreduce(f, MPI.SUM)

    def total_momentum(self) -> np.ndarray:
        P = self.particles
        return self.comm.allreduce((P.mass[:, None] * P.v).sum(axis=0), MPI.SUM)

    def energies(self) -> dict[str, float]:
        """Kinetic, strain and gravitational potential energy [J] (per metre in 2D), and total."""
        P, g = self.particles, self.grid.gdim
        kinetic = 0.5 * float(np.sum(P.mass[:, None] * P.v**2))
        strain = 0.0
        for k, material in enumerate(self.materials):
            idx = P.material == k
            strain += float(np.sum(P.volume[idx] * material.strain_energy_density(P.sigma[idx])))
        potential = -float(np.sum(P.mass * (P.x[:, :g] @ self.gravity)))
        e = {
            name: self.comm.allreduce(val, MPI.SUM)
            for name, val in (("kinetic", kinetic), ("strain", strain), ("potential", potential))
        }
        e["total"] = e["kinetic"] + e["strain"] + e["potential"]
        return e
