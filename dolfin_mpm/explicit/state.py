"""What a run carries from one step to the next, in one object (Warp's ``State``).

The step reads and writes it; checkpoints serialise it (:meth:`State.tree`) and restore it
(:meth:`State.restore`); nothing else holds time-varying data between steps. What does not
change during a run (grid, materials, boundary conditions, options) is the solver's.
"""

from dataclasses import dataclass, field

import numpy as np

from dolfin_mpm.core.particles import Particles, Sink

__all__ = ["FIXED_POINT_STATISTICS", "State"]

#: Counters of the fixed-point loop: steps looped, iterations in all, most in one step, steps
#: that reached the iteration limit, and the Newton and GMRES iterations of the paper's law
#: (:mod:`dolfin_mpm.averaging.complementarity`).
FIXED_POINT_STATISTICS = ("steps", "iterations", "max_iterations", "unconverged", "newton", "krylov")


@dataclass
class State:
    """The time-varying data of a run.

    Attributes:
        particles: this rank's material points.
        sinks: sinks by name, with what they absorbed.
        dt: time step [s].
        time: simulated time [s].
        step: steps taken.
        average: the non-local average with its neighbour lists (``None``: local model).
        R_changes: changes of the owned internal forces ``R`` made by the last steps' stress
            updates, latest first, each ``shape=(owned nodes * gdim,)`` (the fixed-point loop
            extrapolates them).
        v_mean: each owned node's running mean velocity [m/s] that the damping acts against
            (``options.damping_mean_time``), ``shape=(owned nodes * gdim,)``, NaN where the
            node held no material in the last step; ``None``: not kept.
        fixed_point: the loop's counters, :data:`FIXED_POINT_STATISTICS`.
        dissipated: the (visco)plastic work [J] of the stress updates on this rank since the
            start (:func:`dolfin_mpm.explicit.energy.plastic_work`).
        migrated: particles moved between ranks since the start (a diagnostic, not stored).
        repartitions: the times the cells were dealt to the ranks anew since the start (a
            diagnostic, not stored).
        balanced: the particle imbalance the last repartition left (1 before any).
        wall_stops: particle moves cut short at a rigid wall since the start (a diagnostic,
            not stored).
        reactions: the force [N] of each rigid wall on the material in the last step, on this
            rank's owned nodes, by wall (a step's output, not stored).

    """

    particles: Particles
    sinks: dict[str, Sink]
    dt: float
    time: float = 0.0
    step: int = 0
    average: object | None = None
    R_changes: list[np.ndarray] = field(default_factory=list)
    v_mean: np.ndarray | None = None
    fixed_point: dict[str, int] = field(default_factory=lambda: dict.fromkeys(FIXED_POINT_STATISTICS, 0))
    dissipated: float = 0.0
    migrated: int = 0
    repartitions: int = 0
    balanced: float = 1.0
    wall_stops: int = 0
    reactions: dict = field(default_factory=dict)

    # -- serialisation -------------------------------------------------------------------------
    def scalars(self) -> dict:
        """Time, step, time step, loop counters, the last repartition's imbalance: alike on all ranks."""
        counters = np.array([self.fixed_point[k] for k in FIXED_POINT_STATISTICS], dtype=np.int64)
        return {"time": self.time, "step": self.step, "dt": self.dt, "fixed_point": counters,
                "balanced": self.balanced}  # fmt: skip

    def tree(self, owned: int) -> dict:
        """The arrays of this rank as nested dicts (``owned``: owned nodes * gdim)."""
        sinks = {
            name: {
                "mass": np.array(k.mass), "momentum": np.asarray(k.momentum), "count": np.array(k.count),
                "energy": np.array(k.energy), "history": np.array(k.history, dtype=np.float64).reshape(-1, 2),
            }
            for name, k in self.sinks.items()
        }  # fmt: skip
        return {
            "particles": dict(self.particles.arrays()),
            "sinks": sinks,
            "nonlocal": self.average.state() if self.average is not None else {},
            "R_changes": np.array(self.R_changes, dtype=np.float64).reshape(len(self.R_changes), owned),
            "v_mean": np.array([] if self.v_mean is None else [self.v_mean], np.float64).reshape(-1, owned),
            "dissipated": np.array(self.dissipated),
        }

    def fits(self, tree: dict) -> bool:
        """Whether ``tree`` (from :meth:`tree`) has this state's particle fields and sinks."""
        arrays = dict(tree["particles"])
        state = arrays.pop("state", {})
        P = self.particles
        return (
            set(arrays) == set(Particles._fields)
            and set(state) == set(P.state)
            and set(tree["sinks"]) == set(self.sinks)
        )

    def restore(self, scalars: dict, tree: dict) -> None:
        """Take the values of :meth:`scalars` and :meth:`tree` (it must :meth:`fit <fits>`)."""
        P, arrays = self.particles, dict(tree["particles"])
        state = arrays.pop("state", {})
        for name, a in arrays.items():
            setattr(P, name, np.ascontiguousarray(a))
        P.state = {name: np.ascontiguousarray(a) for name, a in state.items()}
        for name, rec in tree["sinks"].items():
            sink = self.sinks[name]
            sink.mass, sink.count = float(rec["mass"]), int(rec["count"])
            sink.energy = float(rec.get("energy", 0.0))  # not in the checkpoints of earlier versions
            sink.momentum = np.array(rec["momentum"], dtype=np.float64)
            sink.history = [(float(t), float(m)) for t, m in rec["history"]]
        if self.average is not None:
            self.average.restore(tree["nonlocal"])
        self.R_changes = list(np.array(tree["R_changes"], dtype=np.float64))
        v_mean = np.array(tree.get("v_mean", np.zeros((0, 0))), dtype=np.float64)  # not in earlier versions
        self.v_mean = v_mean[0].copy() if len(v_mean) else None
        self.dissipated = float(tree.get("dissipated", 0.0))
        self.time, self.step, self.dt = float(scalars["time"]), int(scalars["step"]), float(scalars["dt"])
        self.balanced = float(scalars.get("balanced", 1.0))  # not in the checkpoints of earlier versions
        self.fixed_point.update(zip(FIXED_POINT_STATISTICS, (int(v) for v in scalars["fixed_point"])))
