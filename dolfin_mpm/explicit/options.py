"""The numerical options of the explicit step, each with its allowed values in one place."""

from dataclasses import dataclass

import numpy as np

from dolfin_mpm.params import check_fields, parameter

__all__ = ["INTEGERS", "LIGHT_NODES", "QUADRATURE", "SCHEMES", "STRESS", "VOLUMETRIC", "Options"]

#: Where the velocities that give the strain rate come from: re-mapped momentum (MUSL) or the
#: nodal solve (USL).
SCHEMES = ("MUSL", "USL")
#: Where the volumetric strain rate comes from: each particle's cell, or the nodes' patches.
VOLUMETRIC = ("cell", "nodal")
#: The stress a particle carries into the next step: its own, or its cell's mean.
STRESS = ("cell", "particle")
#: How ``R`` integrates each cell (:mod:`dolfin_mpm.core.quadrature`).
QUADRATURE = ("particle", "cell")
#: Nodes whose own stable step is below the step: solved as the others, or tied to their neighbours.
LIGHT_NODES = ("own", "aggregate")


#: The options that take whole numbers.
INTEGERS = ("fixed_point_max_iter", "anderson_depth", "extrapolation", "rebalance_interval")


@dataclass(frozen=True)
class Options:
    """Settings of the step; the scenario's ``[solver]`` table is built from these fields.

    Args:
        scheme: ``"MUSL"`` (velocities re-mapped before the strain rate) or ``"USL"``.
        volumetric: ``"cell"`` (each particle's own velocity gradient) or ``"nodal"`` (its
            volumetric part averaged over the nodes' patches, against volumetric locking, see
            :mod:`dolfin_mpm.core.volumetric`; for meshes of two triangles per square: it is
            too soft on crossed squares, see ``docs/numerics.md``).
        stress: ``"cell"`` (each particle takes the volume-weighted mean stress of its cell's
            points of its material at the start of each step, which leaves the nodal forces
            unchanged, see :mod:`dolfin_mpm.core.cell_stress`) or ``"particle"`` (its own).
        quadrature: ``"particle"`` (``R`` summed over the points, each with its volume) or
            ``"cell"`` (each cell the material fills integrated over its area, see
            :mod:`dolfin_mpm.core.quadrature`: the silo's choice; it under-integrates dilatant
            flow, ``docs/numerics.md``).
        light_nodes: ``"own"`` (every active node solved for its own velocity) or
            ``"aggregate"`` (a node whose own stable step is below the step, in a patch that
            holds little material, moves with its neighbours, see
            :mod:`dolfin_mpm.core.aggregation`).
        flip: FLIP fraction of the particle velocity update, in [0, 1] (1 = pure FLIP).
        damping: local non-viscous (Cundall) damping factor, in [0, 1).
        damping_mean_time: ``None``: the damping opposes each node's velocity (Cundall's local
            damping); a time [s], > 0: it opposes the velocity's departure from its running
            mean over that time at the node, so that a steady flow past the grid is left
            undamped while oscillations about it are damped. Take several times the time a
            p-wave takes to cross the model, and much less than the loading's (``docs/numerics.md``).
        courant: Courant factor of the automatic time step, in (0, 1].
        dt: time step [s], > 0; ``None``: ``courant * h_min / (max p-wave speed + max particle
            speed at the start)``.
        mass_tol: nodes lighter than ``mass_tol * max nodal mass`` are left at rest, in [0, 1).
        on_exit: ``"error"`` to stop when a particle leaves the grid, or the sink receiving it.
        fixed_point_tol: loop tolerance on the relative change of ``R``, > 0.
        fixed_point_max_iter: most iterates per step, >= 1.
        relaxation: under-relaxation of the ``R`` iterates, in (0, 1].
        anderson_depth: Anderson acceleration depth of the loop, >= 0 (0: plain iteration).
        extrapolation: order 0, 1 or 2 of the loop's first iterate (see :mod:`dolfin_mpm.explicit.step`).
        rebalance: under MPI, deal the cells to the ranks anew by their particles when the
            imbalance (the largest rank's particle count over the mean) exceeds this, >= 1
            (``inf``: never; see :mod:`dolfin_mpm.parallel.rebalance`).
        rebalance_interval: steps between the checks of the imbalance, >= 1.

    """

    scheme: str = "MUSL"
    volumetric: str = "cell"
    stress: str = "cell"
    quadrature: str = "particle"
    light_nodes: str = "own"
    flip: float = parameter(0.0, 1.0, closed=(True, True), default=1.0)
    damping: float = parameter(0.0, 1.0, closed=(True, False), default=0.0)
    damping_mean_time: float | None = parameter(0.0, np.inf, "s", default=None)
    courant: float = parameter(0.0, 1.0, closed=(False, True), default=0.5)
    dt: float | None = parameter(0.0, np.inf, "s", default=None)
    mass_tol: float = parameter(0.0, 1.0, closed=(True, False), default=1e-10)
    on_exit: str = "error"
    fixed_point_tol: float = parameter(0.0, np.inf, default=1e-3)
    fixed_point_max_iter: int = parameter(1, np.inf, closed=(True, False), default=50)
    relaxation: float = parameter(0.0, 1.0, closed=(False, True), default=1.0)
    anderson_depth: int = parameter(0, np.inf, closed=(True, False), default=5)
    extrapolation: int = parameter(0, 2, closed=(True, True), default=2)
    rebalance: float = parameter(1.0, np.inf, closed=(True, True), default=np.inf)
    rebalance_interval: int = parameter(1, np.inf, closed=(True, False), default=20)

    def __post_init__(self):
        if self.scheme not in SCHEMES:
            raise ValueError(f"scheme must be 'USL' or 'MUSL', got {self.scheme!r}")
        if self.volumetric not in VOLUMETRIC:
            raise ValueError(f"volumetric must be 'cell' or 'nodal', got {self.volumetric!r}")
        if self.stress not in STRESS:
            raise ValueError(f"stress must be 'cell' or 'particle', got {self.stress!r}")
        if self.quadrature not in QUADRATURE:
            raise ValueError(f"quadrature must be 'particle' or 'cell', got {self.quadrature!r}")
        if self.light_nodes not in LIGHT_NODES:
            raise ValueError(f"light_nodes must be 'own' or 'aggregate', got {self.light_nodes!r}")
        for name in INTEGERS:
            if not isinstance(getattr(self, name), (int, np.integer)):
                raise ValueError(f"{name} must be an integer, got {getattr(self, name)!r}")
        check_fields(self)
