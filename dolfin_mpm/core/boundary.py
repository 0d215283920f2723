"""Nodal boundary conditions of the explicit step: fixed, slip and frictional rigid walls.

Each condition corrects the trial nodal velocity ``v* = v + dt a`` on its nodes; the solver
turns the correction into the contact force ``F_c = m (v - v*) / dt`` of the paper's eq. (4).
"""

from dataclasses import dataclass

import numpy as np

from dolfin_mpm.params import check_range

__all__ = ["BoundaryCondition", "FixedBC", "FrictionalWall", "SlipBC", "VelocityBC", "coulomb"]


def coulomb(v: np.ndarray, normal: np.ndarray, mu: float) -> np.ndarray:
    """Velocities ``v`` (``(k, gdim)``) after unilateral Coulomb contact with a wall at rest.

    Velocities into the wall (along the unit ``normal``) lose their normal part, and their
    tangential speed drops by ``mu`` times the normal speed removed (to zero: stick); velocities
    away from the wall are kept, so material can separate from it.
    """
    vn = v @ normal
    hit = vn > 0.0
    out = v.copy()
    vt = v[hit] - vn[hit, None] * normal
    speed = np.linalg.norm(vt, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = np.where(speed > 0.0, np.maximum(0.0, 1.0 - mu * vn[hit] / speed), 0.0)
    out[hit] = scale[:, None] * vt
    return out


def _unit(normal, gdim: int) -> np.ndarray:
    """``normal`` scaled to length 1; refuses a zero, NaN or infinite component."""
    n = np.asarray(normal, dtype=np.float64).ravel()
    if n.shape != (gdim,) or not np.all(np.isfinite(n)) or not np.any(n):
        raise ValueError(f"normal must be a non-zero vector of {gdim} finite numbers, got {normal!r}")
    n = n / np.max(np.abs(n))  # first by the largest component: the norm neither overflows nor underflows
    return n / np.linalg.norm(n)


@dataclass
class BoundaryCondition:
    """Base: a set of grid nodes (local indices, ghosts included)."""

    nodes: np.ndarray

    def __post_init__(self):
        self.nodes = np.asarray(self.nodes, dtype=np.int64)

    def apply(self, v: np.ndarray) -> None:
        """Correct the nodal velocities ``v`` (``shape=(num_nodes, gdim)``) in place."""
        raise NotImplementedError

    def node_values(self) -> dict[str, np.ndarray]:
        """The condition's per-node arrays by name, each with a row per node of ``nodes``."""
        return {}

    def renumber(self, nodes: np.ndarray, values: dict[str, np.ndarray]) -> None:
        """Hold ``nodes`` of a repartitioned grid, with the rows ``values`` of :meth:`node_values`."""
        self.nodes = np.asarray(nodes, dtype=np.int64)


@dataclass
class FixedBC(BoundaryCondition):
    """No motion at the nodes (clamped)."""

    def apply(self, v):
        v[self.nodes] = 0.0


@dataclass
class VelocityBC(BoundaryCondition):
    """Prescribed velocity components at the nodes (a moving plate or a driven boundary).

    Args:
        velocity: [m/s], ``shape=(gdim,)`` for all nodes or ``(len(nodes), gdim)``; NaN
            components are left free.

    """

    velocity: np.ndarray = None

    def __post_init__(self):
        super().__post_init__()
        v = np.asarray(self.velocity, dtype=np.float64)
        if v.ndim not in (1, 2) or (v.ndim == 2 and v.shape[0] != len(self.nodes)):
            raise ValueError(f"velocity must have shape (gdim,) or ({len(self.nodes)}, gdim), got {v.shape}")
        if np.isinf(v).any():
            raise ValueError("velocity must be finite (NaN for a free component), got an infinite one")
        self.velocity = np.broadcast_to(v, (len(self.nodes), v.shape[-1]))
        self._set = ~np.isnan(self.velocity)

    def node_values(self):
        return {"velocity": np.asarray(self.velocity)}

    def renumber(self, nodes, values):
        super().renumber(nodes, values)
        self.velocity = values["velocity"]
        self._set = ~np.isnan(self.velocity)

    def apply(self, v):
        vi = v[self.nodes]
        vi[self._set] = self.velocity[self._set]
        v[self.nodes] = vi


@dataclass
class SlipBC(BoundaryCondition):
    """Roller: zero velocity normal to a wall of any orientation, free tangential motion.

    Args:
        normal: wall normal, ``shape=(gdim,)`` (sign irrelevant).

    """

    normal: tuple = (1.0, 0.0)

    def __post_init__(self):
        super().__post_init__()
        self.normal = _unit(self.normal, len(self.normal))

    def apply(self, v):
        vn = v[self.nodes] @ self.normal
        v[self.nodes] -= vn[:, None] * self.normal


@dataclass
class FrictionalWall(BoundaryCondition):
    """Rigid wall with Coulomb friction (unilateral contact).

    Nodes moving into the wall lose their normal velocity; the tangential speed is reduced
    by ``mu`` times the removed normal speed (stick when that exceeds it). Nodes moving away
    are left free, so material can separate from the wall (:func:`coulomb`). The wall is the
    nodes' patches: for a wall anywhere, on or off the nodes, see :mod:`dolfin_mpm.core.walls`.

    Args:
        normal: outward normal of the material, pointing into the wall, ``shape=(gdim,)``.
        mu: friction coefficient, >= 0 (``tan`` of the wall friction angle).

    """

    normal: tuple = (1.0, 0.0)
    mu: float = 0.0

    def __post_init__(self):
        super().__post_init__()
        self.normal = _unit(self.normal, len(self.normal))
        check_range("mu", self.mu, 0.0, np.inf, closed=(True, False))

    def apply(self, v):
        v[self.nodes] = coulomb(v[self.nodes], self.normal, self.mu)

    def sides(self, node_x: np.ndarray, x: np.ndarray, reach: float) -> tuple[int, int]:
        """Local counts of the points ``x`` within ``reach`` [m] of the wall's nodes, by side.

        First those on the side the normal points to (into the wall: there should be none), then
        those on the other. ``node_x``: the grid's node coordinates, ``shape=(num_nodes, k)``;
        ``x``: ``(n, k)``, ``k >= gdim`` (the first ``gdim`` are read).
        """
        if len(self.nodes) == 0 or len(x) == 0:
            return 0, 0
        from scipy.spatial import cKDTree

        gdim = len(self.normal)
        wall, x = node_x[self.nodes, :gdim], x[:, :gdim]
        distance, nearest = cKDTree(wall).query(x, distance_upper_bound=reach)
        near = np.isfinite(distance)
        d = (x[near] - wall[nearest[near]]) @ np.asarray(self.normal)
        return int(np.sum(d > 1e-9 * reach)), int(np.sum(d < -1e-9 * reach))
