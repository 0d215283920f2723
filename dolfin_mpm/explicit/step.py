"""One explicit MPM step, the paper's §3, as a fixed sequence of stages.

    sinks -> locate [-> migrate] -> basis [-> cell stress] [-> quadrature] -> P2G [-> neighbours]
      -> loop { nodal solve -> G2P -> return mapping [-> averaging] -> stress [-> R, test] }
      -> move

P2G gives the lumped mass, the momentum, the external force ``F`` and the internal force ``R``
of the stresses at the start of the step. Each iterate of the loop solves ``M a = F + F_c - R``
with the latest ``R`` (eq. 4), maps the velocities to the particles, runs each material's
return mapping (trial stress -> increment ``de``), averages the increments over the radius r
(``de_bar``, eqs. 2, 3, 5), evaluates the stresses with them and, from those, ``R`` again. The
loop ends when ``R`` (and with it ``F_c``; ``F`` is fixed) changes by less than
``fixed_point_tol`` relative to ``max(|R|, |F|)``; the iterates are mixed with ``relaxation``
and Anderson acceleration. The local model is the loop's single pass, with no average and no
test. The first iterate is ``R`` of the start-of-step stresses (the paper's, order 0) plus the
change of ``R`` the stress update made in the last step (order 1) or extrapolated over the last
two (order 2): the fixed point is the same, the loop starts closer to it.

Each stage is a function of what it reads, returning what it writes; :func:`advance` alone
changes the :class:`~dolfin_mpm.explicit.state.State`: its particles (sinks, migration, cells)
and neighbour lists before the loop, stresses, volumes, material state, velocities and
positions after it. The grid's Functions serve
as assembly buffers and hold the step's nodal fields for output at its end.
"""

import math
from dataclasses import dataclass

import numpy as np
from mpi4py import MPI

from dolfin_mpm.averaging.complementarity import solve_rates
from dolfin_mpm.averaging.overstress import solve_overstress
from dolfin_mpm.core.aggregation import Aggregation, gershgorin_stiffness
from dolfin_mpm.core.cell_stress import cell_mean_stress
from dolfin_mpm.core.grid import Grid
from dolfin_mpm.core.locate import Basis, basis_at, locate
from dolfin_mpm.core.particles import Particles, move
from dolfin_mpm.core.quadrature import cell_weights
from dolfin_mpm.core.transfer import (
    gradient,
    grid_to_particles,
    internal_force,
    particles_to_grid,
    volume_ratio,
)
from dolfin_mpm.core.volumetric import nodal_volume, nodal_volumetric
from dolfin_mpm.core.walls import Contact, contacts, stop_at_walls
from dolfin_mpm.explicit.anderson import Anderson
from dolfin_mpm.explicit.energy import mechanical, plastic_work
from dolfin_mpm.explicit.options import Options
from dolfin_mpm.explicit.state import State
from dolfin_mpm.explicit.timer import Timer
from dolfin_mpm.materials.base import Trial
from dolfin_mpm.materials.separation import separate
from dolfin_mpm.parallel.migration import migrate
from dolfin_mpm.parallel.reduce import max_over_ranks, sum_over_ranks

__all__ = ["CORRECTION", "STAGES", "Model", "Nodal", "SimulationError", "advance", "p2g"]

#: The stages of :func:`advance` in their order; each step's times add up to the step.
STAGES = (
    "sinks", "locate", "migrate", "basis", "cell_stress", "quadrature", "p2g", "neighbours", "nodal_solve",
    "g2p", "return_mapping", "averaging", "stress", "internal_force", "convergence", "move",
)  # fmt: skip

#: The particle state field an iterative non-local law starts each step from, the last step's
#: end: the rates ``u`` [-] of the paper's law (:mod:`dolfin_mpm.averaging.complementarity`),
#: the applied increments ``d`` [-] of the overstress law (:mod:`dolfin_mpm.averaging.overstress`).
CORRECTION = "nonlocal_correction"
#: The iterative laws are solved to this part of the loop's tolerance: what is left of it
#: reaches the loop as noise in ``R``. Solved to the full tolerance, 3 of the 4576 steps of the
#: silo with r = 10 mm on h = 5 mm stalled at the iteration limit (the paper's law); at 0.3, none.
LAW_TOL = 0.3


class SimulationError(RuntimeError):
    """A run that went bad (non-finite state, particle lost); names the step and the particle."""


@dataclass
class Model:
    """What does not change from step to step (walls and damping may change between steps).

    Attributes:
        grid: background grid.
        materials: constitutive models; ``particles.material`` indexes them.
        bcs: nodal boundary conditions and rigid walls
            (:class:`~dolfin_mpm.core.walls.RigidWall`), applied in order.
        gravity: body force per unit mass [m/s^2], ``shape=(gdim,)``.
        options: numerical options.

    """

    grid: Grid
    materials: list
    bcs: list
    gravity: np.ndarray
    options: Options


@dataclass
class Nodal:
    """What P2G gives the loop: nodal arrays of this rank's nodes (owned first, then ghosts).

    Attributes:
        mass: lumped mass [kg], ``shape=(num_nodes,)``.
        inv_mass: ``1 / mass`` at nodes heavier than ``mass_tol * max mass``, else 0.
        momentum: [kg m/s], ``shape=(num_nodes, gdim)``.
        f_ext: external force ``F`` [N], ``shape=(num_nodes * gdim,)``.
        f_int: internal force ``R`` of the start-of-step stresses [N], same shape.
        bcs: the step's boundary conditions: the nodal ones, and each line of rigid walls as
            the :class:`~dolfin_mpm.core.walls.Contact` of the particles over it.
        mass_dofs, inv_mass_dofs: ``mass`` and ``inv_mass`` for each component,
            ``shape=(num_nodes * gdim,)``: the nodal solve's arithmetic runs on flat arrays
            (numpy is slow over rows of 2 or 3).
        aggregation: the light nodes tied to their neighbours, or ``None``; ``mass``,
            ``momentum`` and ``f_ext`` are then the aggregated ones (0 at the light nodes).

    """

    mass: np.ndarray
    inv_mass: np.ndarray
    momentum: np.ndarray
    f_ext: np.ndarray
    f_int: np.ndarray
    bcs: list
    mass_dofs: np.ndarray
    inv_mass_dofs: np.ndarray
    aggregation: Aggregation | None = None

    def apply_bcs(self, v: np.ndarray) -> None:
        """Correct nodal velocities ``v`` (``shape=(num_nodes, gdim)``) in place."""
        for bc in self.bcs:
            bc.apply(v)

    def settle(self, v: np.ndarray) -> None:
        """The boundary conditions on nodal velocities ``v`` (``shape=(num_nodes, gdim)``), in place.

        Light nodes follow their masters as these are after the conditions, then take their
        own; the conditions leave velocities that meet them as they are, and each wall's
        corrections of the two passes add up.
        """
        self.apply_bcs(v)
        if self.aggregation is None:
            return
        self.aggregation.extend(v)
        walls = [c for c in self.bcs if isinstance(c, Contact)]
        first = [c.changes.copy() for c in walls]
        self.apply_bcs(v)
        for c, changes in zip(walls, first):
            c.changes += changes

    def velocity(self, momentum: np.ndarray) -> np.ndarray:
        """Nodal velocities of (aggregated) momenta, flat as ``mass_dofs``; light nodes from their masters."""
        v = momentum.ravel() * self.inv_mass_dofs
        if self.aggregation is not None:
            self.aggregation.extend(v.reshape(len(self.mass), -1))
        return v

    def gather(self, f: np.ndarray) -> np.ndarray:
        """Nodal forces or momenta ``f`` (flat, assembled) with the light nodes' moved to their masters."""
        if self.aggregation is None:
            return f
        return self.aggregation.gather(f.reshape(len(self.mass), -1)).ravel()


# -- stages ----------------------------------------------------------------------------------------
def p2g(
    model: Model,
    P: Particles,
    basis: Basis,
    time: float = 0.0,
    weights: np.ndarray | None = None,
    dt: float | None = None,
) -> Nodal:
    """Lumped mass, momentum, ``F = m g``, ``R`` and the walls' contacts at the nodes, over ranks.

    Moving walls are where they are at ``time`` [s]; ``weights``: factors of the volumes in
    ``R`` (:mod:`dolfin_mpm.core.quadrature`), ``None``: 1; ``dt`` [s]: the step, which the
    light nodes are found for (``options.light_nodes = "aggregate"``).
    """
    grid = model.grid
    volume = P.volume if weights is None else P.volume * weights
    m, momentum, f_int = particles_to_grid(basis, P.mass, P.v, P.sigma, volume)
    m = grid.assemble(grid.mass, m)
    momentum = grid.assemble(grid.momentum, momentum)
    f_int = grid.assemble(grid.f_int, f_int)
    m_max = max_over_ranks(grid.comm, m.max() if m.size else 0.0)
    active = m > model.options.mass_tol * m_max
    bcs = contacts(model.bcs, grid, P.x, P.mass, basis, m, time)
    aggregation = None
    if model.options.light_nodes == "aggregate":
        moduli = [mat.rho * mat.p_wave_speed() ** 2 for mat in model.materials]  # M = rho c_p^2 [Pa]
        modulus = moduli[0] if len(moduli) == 1 else np.array(moduli)[P.material]
        stiffness = gershgorin_stiffness(grid, basis, P.volume * modulus)
        held = np.concatenate([np.asarray(bc.nodes, dtype=np.int64) for bc in bcs] + [np.zeros(0, np.int64)])
        aggregation = Aggregation.of(grid, m, stiffness, active, dt, held)
    if aggregation is not None:  # the light nodes' mass and momentum on their masters
        m, momentum = aggregation.gather(m), aggregation.gather(momentum)
        active = m > model.options.mass_tol * m_max
    f_ext = grid.f_ext.x.array.reshape(-1, grid.gdim)
    for c in range(grid.gdim):  # from the assembled mass
        f_ext[:, c] = m * model.gravity[c]
    inv_m = np.zeros_like(m)
    inv_m[active] = 1.0 / m[active]
    f_int = f_int.ravel().copy()
    per_dof = _per_dof(m, grid.gdim), _per_dof(inv_m, grid.gdim)
    return Nodal(m, inv_m, momentum, grid.f_ext.x.array, f_int, bcs, *per_dof, aggregation)


def nodal_solve(
    model: Model, nodal: Nodal, R: np.ndarray, dt: float, v_mean: np.ndarray | None = None
) -> tuple[np.ndarray, ...]:
    """Nodal velocities at the end of the step from ``M a = F + F_c - R``.

    ``F_c`` is the force the boundary conditions need against ``F - R`` (the reaction).
    Damping then acts on the out-of-balance force ``F + F_c - R``, so that it neither enters
    the reaction nor resists the motion a boundary condition prescribes: ``-damping |f|``
    against the sign of the velocity (Cundall), or of its departure from ``v_mean``, the
    nodes' running mean velocities (flat as ``mass_dofs``; NaN: none yet, the node's velocity).

    Returns:
        The velocity, the acceleration and ``F_c``, each ``shape=(num_nodes, gdim)``, and each
        rigid wall's share of ``F_c`` on this rank's owned nodes [N], by wall.

    """
    gdim, damping = model.grid.gdim, model.options.damping
    inv_m, m = nodal.inv_mass_dofs, nodal.mass_dofs  # flat, as the nodal arrays below
    v = nodal.velocity(nodal.momentum)
    f = nodal.gather(nodal.f_ext - R)
    v_trial = v + dt * f * inv_m
    v_new = v_trial.copy()
    nodal.settle(v_new.reshape(-1, gdim))
    f_contact = m * (v_new - v_trial) / dt
    reactions = {w: f for c in nodal.bcs if isinstance(c, Contact) for w, f in c.forces(dt).items()}
    if damping > 0.0:
        f_out = f + f_contact
        swing = v if v_mean is None else v - np.where(np.isnan(v_mean), v, v_mean)
        v_new = v + dt * (f_out - damping * np.abs(f_out) * np.sign(swing)) * inv_m
        nodal.settle(v_new.reshape(-1, gdim))
    nodal_field = lambda a: a.reshape(-1, gdim)  # noqa: E731
    return nodal_field(v_new), nodal_field((v_new - v) / dt), nodal_field(f_contact), reactions


def g2p(
    model: Model,
    P: Particles,
    basis: Basis,
    nodal: Nodal,
    v_node: np.ndarray,
    a_node: np.ndarray,
    dt: float,
    lumped: np.ndarray | None = None,
) -> tuple[np.ndarray, ...]:
    """Particle velocities and velocity gradients from the grid, without moving the particles.

    With MUSL the new particle momenta are mapped back to the nodes (through the buffer
    ``grid.velocity``) and the strain rate comes from those velocities. ``lumped``: the step's
    :func:`~dolfin_mpm.core.volumetric.nodal_volume`, the weights of the nodal volumetric rate.

    Returns:
        The new particle velocities (PIC/FLIP blend) and the displacements ``dt v_grid`` that
        move them, both ``shape=(n, gdim)``; the velocity gradient ``shape=(n, gdim, gdim)``;
        and the nodal velocity it came from, ``shape=(num_nodes, gdim)``.

    """
    grid, musl = model.grid, model.options.scheme == "MUSL"
    v, dx, momenta = grid_to_particles(
        basis, v_node, a_node, P.v, dt, model.options.flip, P.mass if musl else None
    )
    if musl:
        v_node = nodal.velocity(nodal.gather(grid.assemble(grid.velocity, momenta).ravel())).reshape(
            -1, grid.gdim
        )
        nodal.settle(v_node)
    L = gradient(basis, v_node)
    if model.options.volumetric == "nodal":
        L = nodal_volumetric(grid, basis, L, P.volume, lumped)
    return v, dx, L, v_node


class Constitutive:
    """The stress update split as the materials are: trial -> increment -> [average] -> stress.

    Particles are grouped by material once per step; with one material there is one group
    and no copying.
    """

    def __init__(self, materials: list, P: Particles):
        self.materials = materials
        if len(materials) == 1:
            self.groups = [(materials[0], slice(None), P.state)]
        else:
            self.groups = []
            for k, material in enumerate(materials):
                idx = np.flatnonzero(P.material == k)
                state = {name: P.state[name][idx] for name in material.state_fields()}
                self.groups.append((material, idx, state))
        #: ``m / rho_c`` of each particle [m^3] (inf where never apart); None: no material separates.
        self.critical_volume = self.apart = None
        if any(m.rho_c is not None for m in materials):
            rho_c = np.array([np.inf if m.rho_c is None else m.rho_c for m in materials])
            self.critical_volume = P.mass / rho_c[P.material]
            #: Points apart at the start of the step: stress free through the step (the contact
            #: state lags a step, as an explicit scheme may, and stays fixed in the loop's iterates).
            self.apart = P.state["free_volume"] > 0.0

    def trials(self, P: Particles, L: np.ndarray, dt: float) -> list:
        """Each group's elastic predictor."""
        return [material.trial(P.sigma[idx], L[idx], dt) for material, idx, _ in self.groups]

    def increments(self, P: Particles, trials: list, dt: float, dq: np.ndarray | None = None) -> np.ndarray:
        """Every particle's increment ``de`` from the trial states, ``shape=(n,)``.

        ``dq`` [Pa] ``shape=(n,)``: a non-local law's correction of the trial ``q`` that each
        return takes (:mod:`dolfin_mpm.averaging.law`); ``None``: the local returns.
        """
        parts = []
        for (material, idx, state), trial in zip(self.groups, trials):
            if dq is not None:
                trial = Trial(trial.p, trial.s, np.maximum(trial.q + dq[idx], 0.0))
            parts.append(material.increment(trial, state, dt))
        return self.gather(P, parts)

    def increments_of_rates(self, P: Particles, trials: list, u: np.ndarray, dt: float) -> tuple:
        """Each particle's increment whose end state has the rate ``u``, and minus its slope.

        See ``increment_of_rate`` of the materials (:mod:`dolfin_mpm.averaging.complementarity`);
        all ``shape=(n,)``.
        """
        parts = [m.increment_of_rate(t, u[idx], dt) for (m, idx, _), t in zip(self.groups, trials)]
        return self.gather(P, [d for d, _ in parts]), self.gather(P, [s for _, s in parts])

    def overstress_fields(self, P: Particles, trials: list, dt: float) -> tuple[np.ndarray, ...]:
        """What the overstress law reads of the trial states, each ``shape=(n,)``.

        Trial ``q`` [Pa], the yield value ``y`` of ``q`` [Pa] (``<= 0`` at an apex) and the
        Perzyna law's ``c`` [-] and ``N`` of each particle's material.
        """
        groups = [(m, t) for (m, _, _), t in zip(self.groups, trials)]
        q = self.gather(P, [t.q for t in trials])
        y = self.gather(P, [m.yield_value(t) for m, t in groups])
        c, N = (self.gather(P, [np.full(len(t.q), m.perzyna(dt)[k]) for m, t in groups]) for k in (0, 1))
        return q, y, c, N

    def two_G(self, P: Particles) -> np.ndarray:
        """``2 G`` of each particle's material [Pa], ``shape=(n,)``."""
        if len(self.materials) == 1:
            return np.full(len(P), 2.0 * self.materials[0].G)
        return 2.0 * np.array([m.G for m in self.materials])[P.material]

    def gather(self, P: Particles, parts: list) -> np.ndarray:
        """One particle array from the groups' parts."""
        if len(parts) == 1:
            return parts[0]
        out = np.empty(len(P))
        for (_, idx, _), part in zip(self.groups, parts):
            out[idx] = part
        return out

    def stresses(self, P: Particles, trials: list, de: np.ndarray, de_bar: np.ndarray | None) -> np.ndarray:
        """The stresses with the local and (if any) non-local increments, ``shape=(n, 3, 3)``."""
        if len(self.groups) == 1:
            return self.materials[0].stress(trials[0], de, de_bar)
        sigma = np.empty_like(P.sigma)
        for (material, idx, _), trial in zip(self.groups, trials):
            sigma[idx] = material.stress(trial, de[idx], None if de_bar is None else de_bar[idx])
        return sigma

    def volumes(self, P: Particles, L: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray | None]:
        """Volume from ``det(I + dt L)`` and, where materials separate, the free volume."""
        J = volume_ratio(L, dt)
        if self.critical_volume is None:
            return P.volume * J, None
        return separate(P.volume, P.state["free_volume"], J, self.critical_volume)

    def record(
        self,
        P: Particles,
        de: np.ndarray,
        de_bar: np.ndarray | None,
        dt: float,
        applied: np.ndarray | None = None,
    ) -> None:
        """Each material's state after the step (into ``P.state``); ``applied``: see ``Material.record``."""
        part = lambda a, idx: None if a is None else a[idx]  # noqa: E731
        for material, idx, state in self.groups:
            material.record(state, de[idx], part(de_bar, idx), dt, applied=part(applied, idx))
            if len(self.groups) > 1:
                for name, a in state.items():
                    P.state[name][idx] = a


# -- the step ----------------------------------------------------------------------------------
def advance(model: Model, state: State, timer: Timer) -> None:
    """Advance ``state`` by one time step ``state.dt``; stage times go to ``timer``."""
    grid, options, P, dt = model.grid, model.options, state.particles, state.dt
    comm, average = grid.comm, state.average
    timer.start()
    for sink in state.sinks.values():
        if sink.region is not None:
            _absorb(model, sink, P, np.asarray(sink.region(P.x.T), dtype=bool), state.time)
    timer.lap("sinks")
    cells, N = locate(grid, P.x, P.cell)
    timer.lap("locate")
    if comm.size > 1:
        sent = migrate(grid, P, cells)
        state.migrated += sent
        if sent:
            cells, N = locate(grid, P.x, P.cell)
        timer.lap("migrate")
    cells, N = _leave_grid(model, state, cells, N)
    P.cell = cells
    basis = basis_at(grid, cells, N)
    timer.lap("basis")
    constitutive = Constitutive(model.materials, P)
    if options.stress == "cell":  # apart points stay stress free, out of the means
        P.sigma = cell_mean_stress(
            P.sigma, P.volume, cells, P.material, grid.num_cells, constitutive.apart, in_place=True
        )
        timer.lap("cell_stress")
    weights = lumped = None  # lumped: the particles' volume at the nodes, for both options
    if options.quadrature == "cell" or options.volumetric == "nodal":
        lumped = nodal_volume(grid, basis, P.volume)
    if options.quadrature == "cell":
        weights = cell_weights(grid, basis, cells, P.volume, lumped)
        timer.lap("quadrature")
    elif lumped is not None:
        timer.lap("g2p")  # the nodal volumetric rate's weights
    nodal = p2g(model, P, basis, state.time, weights, dt)
    timer.lap("p2g")
    if average is not None:
        average.update(P.x[:, : grid.gdim], P.volume, P.id)
        timer.lap("neighbours")

    R_node = nodal.f_int  # with ghosts: what the nodal solve reads
    law = None if average is None else average.law
    if average is not None:  # the loop's start: owned R, first iterate, scale of the test
        owned = grid.num_owned_nodes * grid.gdim
        R_start = R_in = nodal.f_int[:owned].copy()
        if state.R_changes and options.extrapolation:
            R_in = R_start + _predicted_change(state.R_changes, options.extrapolation)
            R_node = grid.refresh_ghosts(grid.f_int, R_in).copy()  # f_int takes the next R
        scale_F = math.sqrt(sum_over_ranks(comm, nodal.f_ext[:owned] @ nodal.f_ext[:owned]))
        mixer = Anderson(options.anderson_depth, comm)
        converged = False
        if law.iterative:  # from the last step's end: the paper's rates, the overstress increments
            guess = P.state[CORRECTION].copy()
    rates = law is not None and law.rates  # the paper's law or the over-non-local mix
    if rates:
        applied_of = law.applied(average)  # d = A u, or the mix m A u + (1 - m) u
        _check_mix(state, law, average, comm)
    overstress = law is not None and law.name == "overstress"
    applied = None
    if law is not None and law.iterative:
        two_G = constitutive.two_G(P)
    v_mean = None  # the damping's mean velocities at this rank's nodes, ghosts too
    if options.damping_mean_time is not None:
        v_mean = np.full(nodal.mass_dofs.shape, np.nan)
        if state.v_mean is not None:
            v_mean = grid.refresh_ghosts(grid.scratch_vector, state.v_mean).copy()
    for k in range(1, (1 if average is None else options.fixed_point_max_iter) + 1):
        v_node, a_node, f_contact, reactions = nodal_solve(model, nodal, R_node, dt, v_mean)
        v_solved = v_node
        timer.lap("nodal_solve")
        v, dx, L, v_node = g2p(model, P, basis, nodal, v_node, a_node, dt, lumped)
        timer.lap("g2p")
        trials = constitutive.trials(P, L, dt)
        if rates:  # the rates by semismooth Newton, from the last iterate's (or step's)
            u_trial = constitutive.gather(P, [t.q for t in trials]) / two_G  # q_trial / 2G
            timer.lap("return_mapping")
            size = math.sqrt(sum_over_ranks(comm, u_trial @ u_trial))
            tol_u = LAW_TOL * options.fixed_point_tol * size
            of_rate = lambda u: constitutive.increments_of_rates(P, trials, u, dt)  # noqa: E731
            applied, de, inner = solve_rates(applied_of, of_rate, guess, comm, tol_u)
            guess = de  # the next iterate starts from these rates
            de_bar = applied
            state.fixed_point["newton"] += inner["newton"]
            state.fixed_point["krylov"] += inner["krylov"]
            timer.lap("averaging")
            sigma = constitutive.stresses(P, trials, applied, None)
        elif overstress:  # the end states' overstress, a convex minimum, from the last increments
            q_trial, y, c, N = constitutive.overstress_fields(P, trials, dt)
            free = y > 0.0  # not at an apex, where a point is stress free whatever its neighbours
            b = two_G * c / np.where(free, y, 1.0) ** N
            timer.lap("return_mapping")
            size = math.sqrt(sum_over_ranks(comm, q_trial @ q_trial))
            tol_q = LAW_TOL * options.fixed_point_tol * size
            f_t = q_trial - y
            f, inner = solve_overstress(
                average, average.metric, f_t, b, N, y, f_t - two_G * guess, comm, tol_q
            )
            state.fixed_point["newton"] += inner["newton"]
            state.fixed_point["krylov"] += inner["krylov"]
            timer.lap("averaging")
            applied = de_bar = guess = np.where(free, (f_t - f) / two_G, q_trial / two_G)
            de = np.where(free, c * np.maximum(f / np.where(free, y, 1.0), 0.0) ** N, applied)  # own rates
            sigma = constitutive.stresses(P, trials, applied, None)
        else:
            de = constitutive.increments(P, trials, dt)
            timer.lap("return_mapping")
            de_bar = None
            if average is not None:
                de_bar = average(de)
                timer.lap("averaging")
            sigma = constitutive.stresses(P, trials, de, de_bar)
        volume, free_volume = constitutive.volumes(P, L, dt)
        if free_volume is not None:
            sigma[constitutive.apart] = 0.0  # stress free until the free volume has closed
        timer.lap("stress")
        if average is None:
            break
        weighted = volume if weights is None else volume * weights
        R = grid.assemble(grid.f_int, internal_force(basis, sigma, weighted)).ravel()[:owned].copy()
        timer.lap("internal_force")
        norms = np.sqrt(sum_over_ranks(comm, [(R - R_in) @ (R - R_in), R @ R]))
        converged = norms[0] <= options.fixed_point_tol * max(norms[1], scale_F, 1e-300)
        if law.iterative:  # and the law at every rank's points
            converged &= comm.allreduce(inner["converged"], MPI.LAND)
        if not converged:
            R_in = mixer(R_in, R_in + options.relaxation * (R - R_in))  # depth 0: the relaxed R
            R_node = grid.refresh_ghosts(grid.f_int, R_in).copy()  # f_int takes the next R
        timer.lap("convergence")
        if converged:
            break

    if average is not None:
        stats = state.fixed_point
        stats["steps"] += 1
        stats["iterations"] += k
        stats["max_iterations"] = max(stats["max_iterations"], k)
        stats["unconverged"] += not converged
        if options.extrapolation:
            state.R_changes = [R - R_start, *state.R_changes][: options.extrapolation]
        grid.refresh_ghosts(grid.f_int, R)  # the R of the stresses the step ends with
        if law.iterative:
            P.state[CORRECTION] = guess
    if v_mean is not None:
        owned = grid.num_owned_nodes * grid.gdim
        mean = _running_mean(v_mean, v_solved.ravel(), nodal.inv_mass_dofs, dt, options.damping_mean_time)
        state.v_mean = mean[:owned]
    state.reactions = reactions
    state.dissipated += plastic_work(constitutive.groups, trials, sigma, volume)
    P.sigma, P.volume = sigma, volume
    constitutive.record(P, de, de_bar, dt, applied)
    if free_volume is not None:
        P.state["free_volume"] = free_volume
    state.wall_stops += stop_at_walls(model.bcs, P.x, dx, v, state.time, dt)
    P.v = v
    sound = move(P, dx)
    for f, a in ((grid.velocity, v_node), (grid.acceleration, a_node), (grid.f_contact, f_contact)):
        f.x.array[:] = a.ravel()
    state.time = _after(state.time, dt)
    state.step += 1
    if not sound:
        _name_the_unsound(state)
    timer.lap("move")


def _per_dof(a: np.ndarray, gdim: int) -> np.ndarray:
    """Nodal values ``a`` (``shape=(num_nodes,)``) for each of ``gdim`` components, flat."""
    out = np.empty((len(a), gdim))
    for c in range(gdim):  # by columns: np.repeat is slow over a few components
        out[:, c] = a
    return out.ravel()


def _running_mean(v_mean: np.ndarray, v: np.ndarray, inv_mass: np.ndarray, dt: float, time: float):
    """The nodes' running mean velocities after a step of ``dt`` [s] that ended with velocities ``v``.

    Exponential over ``time`` [s] (the mean of a velocity held that long is ``1 - 1/e`` of the
    way to it); a node new to the material starts from its velocity, one without material has
    none (NaN). All flat as ``Nodal.mass_dofs``.
    """
    start = np.where(np.isnan(v_mean), v, v_mean)
    share = -math.expm1(-dt / time)
    return np.where(inv_mass > 0.0, start + share * (v - start), np.nan)


def _after(time: float, dt: float) -> float:
    """``time + dt`` [s], exactly ``k dt`` where it is that to round-off.

    A run started whole steps before t = 0 is at 0 there, not at the 1e-17 s that adding ``dt``
    k times leaves.
    """
    t = time + dt
    k = round(t / dt)
    return k * dt if abs(t - k * dt) <= 1e-9 * dt else t


def _leave_grid(model: Model, state: State, cells: np.ndarray, N: np.ndarray):
    """Particles outside the grid: an error, or absorbed by the ``on_exit`` sink."""
    lost = cells < 0
    if not np.any(lost):
        return cells, N
    P, options = state.particles, model.options
    if options.on_exit == "error":
        i = np.flatnonzero(lost)[0]
        raise SimulationError(
            f"step {state.step}, t = {state.time:.6g} s: particle {P.id[i]} left the "
            f"grid at x = {P.x[i]} ({lost.sum()} particles outside)"
        )
    _absorb(model, state.sinks[options.on_exit], P, lost, state.time)
    return cells[~lost], N[:, ~lost]


def _absorb(model: Model, sink, P: Particles, mask: np.ndarray, time: float) -> None:
    """``sink`` absorbs the particles where ``mask`` holds, with the energy they carry."""
    energy = sum(mechanical(P, model.materials, model.gravity, mask).values()) if mask.any() else 0.0
    sink.absorb(P, mask, time, energy)


def _predicted_change(R_changes: list[np.ndarray], order: int) -> np.ndarray:
    """The change of the owned ``R`` in this step, extrapolated from the last steps' changes."""
    dR = R_changes[:order]
    return 2.0 * dR[0] - dR[1] if len(dR) == 2 else dR[0]


def _check_mix(state: State, law, average, comm: MPI.Comm) -> None:
    """Stop where the over-non-local mix may have no solution: a point's own weight ``m A_ii + 1 - m <= 0``.

    Collective: every rank raises, the one holding the worst point naming it.
    """
    own = law.own_weights(average)
    if own is None:
        return
    worst = own.min(initial=np.inf)
    if max_over_ranks(comm, -worst) < 0.0:
        return
    P = state.particles
    if worst <= 0.0:
        i = int(np.argmin(own))
        A_ii = (own[i] - 1.0 + law.m) / law.m
        where = f"particle {P.id[i]} at x = {P.x[i]}: own weight m A_ii + 1 - m = {own[i]:.3g}"
        bound = f"m must be below 1 / (1 - A_ii) = {1.0 / (1.0 - A_ii):.4g} there"
    else:
        where, bound = "a particle of another rank", "see that rank's message"
    raise SimulationError(
        f"step {state.step}, t = {state.time:.6g} s: law 'overnonlocal' with m = {law.m:g} may have no "
        f"unique solution where a point's own rate lowers its own increment: {where}; {bound} "
        "(dolfin_mpm.averaging.law)"
    )


def _name_the_unsound(state: State) -> None:
    """Stop, naming the first particle that :func:`~dolfin_mpm.core.particles.move` found unsound."""
    P = state.particles
    fields = {
        "a non-finite stress": ~np.isfinite(P.sigma).all(axis=(1, 2)),
        "a non-finite velocity": ~np.isfinite(P.v).all(axis=1),
        "a non-finite position": ~np.isfinite(P.x).all(axis=1),
        "a non-positive volume": ~(P.volume > 0.0),
    }
    bad = np.logical_or.reduce(list(fields.values()))
    i = np.flatnonzero(bad)[0]
    what = " and ".join(name for name, mask in fields.items() if mask[i])
    raise SimulationError(
        f"step {state.step}, t = {state.time:.6g} s: particle {P.id[i]} at x = {P.x[i]} has {what} "
        f"({bad.sum()} particles with non-finite stress, velocity or position, or non-positive volume)"
    )
