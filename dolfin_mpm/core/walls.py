"""Rigid walls as geometry with Coulomb friction, wherever the nodes fall: segments, facets.

A 2D wall is a segment ``a -> b`` with the material on its left (walk the material's boundary
counter-clockwise); a 3D wall is a facet, a planar convex polygon whose corners go
counter-clockwise seen from the material. Its unit normal ``n`` points away from the material,
into the wall. A particle is *over* the wall when its foot point on the wall's line (plane)
lies on the segment (facet).

Contact is imposed in two places:

- **On the grid**, each step: a node on or behind the wall's line takes the unilateral Coulomb
  condition of :func:`~dolfin_mpm.core.boundary.coulomb` in the share of its lumped mass that
  lies over the wall, ``alpha_i = sum_p N_i(x_p) m_p [p over the wall] / m_i``: its velocity
  correction is ``alpha_i`` times the full one. This is the lumped projection of the contact
  impulse onto the P1 nodes, the projection P2G makes of the momentum. A node under a plate
  takes the full condition, the node at a plate's edge the share of its patch the plate
  carries, a node under an opening none: the opening is as wide as the geometry says, on or
  off the nodes. Walls on one line (plane) add their shares: a plate and the gate next to it.
- **At the particles**, in the move: a particle whose path would cross the wall stops on it
  and loses its velocity into the wall. Where the grid condition is partial (at an edge) the
  interpolated velocity may point into the wall; the stop keeps the wall impenetrable there.
"""

import ctypes
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from mpi4py import MPI

from dolfin_mpm import native
from dolfin_mpm.core.grid import Grid
from dolfin_mpm.core.locate import Basis
from dolfin_mpm.params import check_range

__all__ = ["Contact", "RigidWall", "contacts", "stop_at_walls"]

#: Nodes within this fraction of the smallest cell height in front of a wall's line count as on it.
ON_LINE = 1e-6
#: A particle stopped on a wall lands this fraction of the wall's length in front of it, and one
#: found as far behind it counts as on it (round-off).
ROUNDOFF = 1e-12
#: Corners of a facet may lie this fraction of its size off its plane, its turns bend back as
#: much, and no edge may be shorter.
_FLAT = 1e-9
#: Walls whose normals (and velocities) differ by this much at most lie on one line (plane).
_PARALLEL = 1e-12

_REAL = native.array(np.float64)
_NONE = np.zeros(1)  # what a kernel is given for an array it does not read
_kernels = native.kernels(
    Path(__file__).with_suffix(".c"),
    {
        "contact_apply": (
            ctypes.c_int64, ctypes.c_int32, native.array(np.int64), _REAL, ctypes.c_int32, _REAL, _REAL,
            _REAL, _REAL, _REAL,
        ),
        "stop_at_walls": (
            ctypes.c_int64, ctypes.c_int32, _REAL, _REAL, _REAL, ctypes.c_int32, *[_REAL] * 10,
            ctypes.c_double, native.array(np.int32), _REAL, _REAL, native.array(np.int64),
        ),
        "wall_shares": (
            ctypes.c_int64, ctypes.c_int32, _REAL, _REAL, native.array(np.int32), _REAL, ctypes.c_int64,
            ctypes.c_int32, _REAL, _REAL, ctypes.c_double, _REAL, _REAL, _REAL, native.array(np.int32), _REAL,
            _REAL, _REAL,
        ),
    },
)  # fmt: skip


@dataclass(eq=False)  # a wall is itself: compared and hashed by identity
class RigidWall:
    """A rigid wall with Coulomb friction, at rest or in uniform translation.

    Args:
        points: the wall at t = 0 [m]. In 2D a segment, its ends ``[[x0, y0], [x1, y1]]``,
            the material on the left going from the first to the second; in 3D a facet, the
            corners ``[[x, y, z], ...]`` of a convex polygon in one plane (three or more),
            counter-clockwise seen from the material.
        mu: friction coefficient, >= 0 (``tan`` of the wall friction angle; ``inf``: rough,
            no slip while in contact).
        name: what errors call it.
        velocity: the wall's velocity [m/s], ``shape=(gdim,)``, default 0: at time t its
            points are ``points + velocity * t``.

    """

    points: np.ndarray
    mu: float = 0.0
    name: str = "wall"
    velocity: tuple | None = None

    def __post_init__(self):
        s = np.asarray(self.points, dtype=np.float64)
        if s.ndim != 2 or s.shape[1] not in (2, 3) or not np.all(np.isfinite(s)):
            raise ValueError(
                f"{self.name}: points must be a segment [[x0, y0], [x1, y1]] (2D) or a facet "
                f"[[x, y, z], ...] (3D) of finite coordinates, got {self.points!r}"
            )
        self.gdim = gdim = s.shape[1]
        if gdim == 2 and len(s) != 2:
            raise ValueError(f"{self.name}: a wall in 2D is a segment of two points, got {len(s)}")
        if gdim == 3 and len(s) < 3:
            raise ValueError(f"{self.name}: a wall in 3D is a facet of three or more points, got {len(s)}")
        check_range(f"{self.name}: mu", self.mu, 0.0, np.inf, closed=(True, True))
        v = np.zeros(gdim) if self.velocity is None else np.asarray(self.velocity, dtype=np.float64)
        if v.shape != (gdim,) or not np.all(np.isfinite(v)):
            raise ValueError(
                f"{self.name}: velocity must be {gdim} finite numbers [m/s], got {self.velocity!r}"
            )
        self.points, self.velocity = s, v
        size = max(1.0, float(np.abs(s).max()))
        if gdim == 2:
            d = s[1] - s[0]
            self.length = float(np.hypot(*d))
            if not self.length > 1e-12 * size:
                raise ValueError(f"{self.name}: segment is degenerate (its ends coincide), got {s.tolist()}")
            self.tangent = d / self.length
            self.normal = np.array([self.tangent[1], -self.tangent[0]])  # right of a -> b: into the wall
        else:
            self._facet(s, size)

    def _facet(self, s: np.ndarray, size: float) -> None:
        """Normal, size and inward edge normals of a facet; refuses one that is not flat and convex."""
        up = np.cross(s, np.roll(s, -1, axis=0)).sum(axis=0)  # Newell: twice the area, towards the material
        area = 0.5 * float(np.linalg.norm(up))
        extent = float(np.linalg.norm(s.max(axis=0) - s.min(axis=0)))
        if not area > 1e-12 * extent * extent or not extent > 1e-12 * size:
            raise ValueError(
                f"{self.name}: facet is degenerate (no area: its points on a line, or not in order "
                f"round it), got {s.tolist()}"
            )
        up /= 2.0 * area
        off = np.abs((s - s.mean(axis=0)) @ up)
        if off.max() > _FLAT * extent:
            k = int(np.argmax(off))
            raise ValueError(
                f"{self.name}: facet is not flat: point {s[k].tolist()} lies {off[k]:.3g} m off the "
                f"plane that fits its points"
            )
        edges = np.roll(s, -1, axis=0) - s
        short = np.linalg.norm(edges, axis=1) <= _FLAT * extent
        if short.any():
            k = int(np.argmax(short))
            raise ValueError(
                f"{self.name}: facet is degenerate (its corners {k} and {(k + 1) % len(s)} coincide), "
                f"got {s.tolist()}"
            )
        inward = np.cross(up, edges)  # left of each edge, seen from the material: the inside
        inward /= np.linalg.norm(inward, axis=1)[:, None]
        # every corner against each edge: on its inner side, or on it
        bend = np.einsum("ikc,ic->ik", s[None, :, :] - s[:, None, :], inward)
        if bend.min() < -_FLAT * extent:
            raise ValueError(
                f"{self.name}: facet is not convex, or its points are not in order round it, got {s.tolist()}"
            )
        self.normal, self.length = -up, extent  # into the wall: away from the material
        self._inward, self._offset = inward, np.einsum("ic,ic->i", s, inward)

    def start(self, time: float = 0.0) -> np.ndarray:
        """The first point [m] at ``time`` [s], ``shape=(gdim,)``."""
        return self.points[0] + self.velocity * time

    def distance(self, x: np.ndarray, time: float = 0.0) -> np.ndarray:
        """Signed distance [m] of points ``x`` (``(n, >=gdim)``) from the line (plane) at ``time`` [s].

        Positive on the material's side.
        """
        a, n = self.start(time), self.normal
        d = (a[0] - x[:, 0]) * n[0] + (a[1] - x[:, 1]) * n[1]
        return d if self.gdim == 2 else d + (a[2] - x[:, 2]) * n[2]

    def over(self, x: np.ndarray, time: float = 0.0) -> np.ndarray:
        """Whether the foot point of each of ``x`` (``(n, >=gdim)``) lies on the wall at ``time`` [s]."""
        if self.gdim == 2:
            a, t = self.start(time), self.tangent
            s = (x[:, 0] - a[0]) * t[0] + (x[:, 1] - a[1]) * t[1]
            return (s >= 0.0) & (s <= self.length)
        return self._inside(x[:, :3] - self.velocity * time)

    def _inside(self, y: np.ndarray) -> np.ndarray:
        """Whether points ``y`` (``(n, 3)``, relative to the facet at t = 0) are over it."""
        return np.all(y @ self._inward.T >= self._offset, axis=1)

    def check(self, grid: Grid, particles, time: float = 0.0) -> None:
        """Raise ``ValueError`` for a wall not of the grid's dimension, outside it, or with material behind.

        ``particles`` (:class:`~dolfin_mpm.core.particles.Particles`): the material must lie on
        the wall's side at ``time`` [s]; collective over the grid's ranks.
        """
        g = self.gdim
        if grid.gdim != g:
            kind = "a segment in 2D" if g == 2 else "a facet in 3D"
            raise ValueError(f"{self.name}: the wall is {kind}, the grid is {grid.gdim}D")
        comm = grid.comm
        lo, hi = np.empty(g), np.empty(g)
        comm.Allreduce(grid.node_x[:, :g].min(axis=0), lo, op=MPI.MIN)
        comm.Allreduce(grid.node_x[:, :g].max(axis=0), hi, op=MPI.MAX)
        slack = 1e-9 * float(np.max(hi - lo))
        ends = self.points + self.velocity * time
        outside = ((ends < lo - slack) | (ends > hi + slack)).any(axis=1)
        if outside.any():
            bound = lambda v: f"{0.0 if abs(v) <= slack else v:g}"  # noqa: E731  (round-off of 0 shown as 0)
            box = " x ".join(f"[{bound(a)}, {bound(b)}]" for a, b in zip(lo, hi))
            kind = "segment" if g == 2 else "facet"
            raise ValueError(
                f"{self.name}: {kind} point {ends[np.argmax(outside)].tolist()} lies outside the mesh {box}"
            )
        x = particles.x
        behind = np.flatnonzero(self.over(x, time) & (self.distance(x, time) < -ON_LINE * grid.h_min))
        count = comm.allreduce(behind.size, op=MPI.SUM)
        if count:
            first = comm.allgather(x[behind[0], :g].tolist() if behind.size else None)
            side = (
                f"on the left of the segment {self.points.tolist()}, going from its first point to its second"
                if g == 2
                else f"on the side from which the facet's points {self.points.tolist()} go counter-clockwise"
            )
            raise ValueError(
                f"{self.name}: {count} particles start behind the wall (the first at "
                f"{next(p for p in first if p is not None)}); the material must lie {side}"
            )


class Contact:
    """The walls of one line in one step: nodes and each wall's share ``alpha`` of each node.

    ``apply`` corrects nodal velocities like a boundary condition, each wall in its share by
    the unilateral Coulomb condition of :func:`~dolfin_mpm.core.boundary.coulomb` (a compiled
    pass, ``walls.c``); the walls' corrections are computed from the same velocities and added.
    :meth:`forces` are those of the last call.
    """

    def __init__(self, nodes: np.ndarray, normal: np.ndarray, members: list, mass: np.ndarray, owned: int):
        self.nodes, self.normal, self.members = np.ascontiguousarray(nodes, dtype=np.int64), normal, members
        self.mass = np.where(nodes < owned, mass, 0.0)  # ghosts count on their owners
        self._alpha = np.ascontiguousarray([alpha for _, alpha in members], dtype=np.float64)
        self._mu = np.array([wall.mu for wall, _ in members], dtype=np.float64)
        self._velocity = np.ascontiguousarray([wall.velocity for wall, _ in members], dtype=np.float64)
        self.changes = np.zeros((len(members), len(nodes), len(normal)))

    def apply(self, v: np.ndarray) -> None:
        """Correct the nodal velocities ``v`` (``shape=(num_nodes, gdim)``, C-contiguous) in place."""
        k, m = len(self.nodes), len(self.members)
        _kernels().contact_apply(
            k, len(self.normal), self.nodes, self.normal, m, self._alpha, self._mu, self._velocity, v,
            self.changes,
        )  # fmt: skip

    def forces(self, dt: float) -> dict:
        """Each wall's force [N] on the material in the last :meth:`apply`, by wall.

        Of a step ``dt`` [s], on this rank's owned nodes.
        """
        return {wall: self.mass @ change / dt for (wall, _), change in zip(self.members, self.changes)}


def contacts(
    conditions: list, grid: Grid, x: np.ndarray, m: np.ndarray, basis: Basis, mass: np.ndarray, time: float
) -> list:
    """The step's boundary conditions: nodal ones as they are, rigid walls as :class:`Contact` s.

    Args:
        conditions: nodal boundary conditions and :class:`RigidWall` s, in the order to apply.
        x: particle positions [m], ``shape=(n, 3)``, at the start of the step.
        m: particle masses [kg], ``shape=(n,)``.
        basis: the P1 basis at ``x``.
        mass: the assembled lumped mass [kg], ``shape=(num_nodes,)``.
        time: the start of the step [s] (where moving walls are).

    """
    out, lines = [], {}  # a line's first wall's place in out -> (the line's key, its walls)
    tol = ON_LINE * grid.h_min
    for bc in conditions:
        if not isinstance(bc, RigidWall):
            out.append(bc)
            continue
        key = (*bc.normal.tolist(), *bc.velocity.tolist(), float(bc.normal @ bc.start(time)))  # as it moves
        k = next((k for k, (other, _) in lines.items() if _same_line(key, other, tol)), None)
        if k is None:
            lines[len(out)] = (key, [bc])
            out.append(None)
        else:
            lines[k][1].append(bc)
    if not lines:
        return out
    # each wall's mass at the nodes: of the particles within a cell of its line, over it (one
    # pass over the particles for all the walls)
    every_wall = [w for _, line in lines.values() for w in line]
    shares = iter(_wall_shares(x, m, basis, every_wall, grid.diameter, time))
    for k, (_, line) in lines.items():
        w0 = line[0]
        behind = np.flatnonzero((w0.distance(grid.node_x, time) <= tol) & (mass > 0.0))
        members = [(w, grid.assemble(grid.scratch, next(shares))[behind] / mass[behind]) for w in line]
        touched = np.logical_or.reduce([alpha > 0.0 for _, alpha in members])
        nodes = behind[touched]
        members = [(w, alpha[touched]) for w, alpha in members]
        out[k] = Contact(nodes, w0.normal, members, mass[nodes], grid.num_owned_nodes)
    return out


def _wall_shares(
    x: np.ndarray, m: np.ndarray, basis: Basis, walls: list, limit: float, time: float
) -> np.ndarray:
    """Local nodal sums ``sum_p N_a(x_p) m_p`` of each wall's particles, ``shape=(len(walls), num_nodes)``.

    A wall's particles: less than ``limit`` [m] in front of its line (plane) and over it, at
    ``time`` [s]; one pass over the particles for all of them.
    """
    g, n = walls[0].gdim, len(m)
    starts = np.ascontiguousarray([w.start(time) for w in walls], dtype=np.float64)
    normals = np.ascontiguousarray([w.normal for w in walls], dtype=np.float64)
    if g == 2:
        tangents = np.ascontiguousarray([w.tangent for w in walls], dtype=np.float64)
        lengths = np.array([w.length for w in walls], dtype=np.float64)
        shifts = inward = offsets = _NONE
        begin = np.zeros(len(walls) + 1, dtype=np.int32)
    else:
        tangents = lengths = _NONE
        shifts = np.ascontiguousarray([w.velocity * time for w in walls], dtype=np.float64)
        inward = np.ascontiguousarray(np.concatenate([w._inward for w in walls]), dtype=np.float64)
        offsets = np.ascontiguousarray(np.concatenate([w._offset for w in walls]), dtype=np.float64)
        begin = np.cumsum([0, *(len(w._offset) for w in walls)], dtype=np.int32)
    out = np.zeros((len(walls), basis.num_nodes))
    x, m = np.ascontiguousarray(x, dtype=np.float64).reshape(n, 3), np.ascontiguousarray(m, dtype=np.float64)
    _kernels().wall_shares(
        n, g, x, m, basis.dofs, basis.N, basis.num_nodes, len(walls), starts, normals, limit, tangents,
        lengths, shifts, begin, inward, offsets, out,
    )  # fmt: skip
    return out


def _same_line(a: tuple, b: tuple, tol: float) -> bool:
    """Whether two walls' keys (normal, velocity, offset) are one line (plane) moving as one.

    Normals and velocities to round-off (two facets of one inclined plane differ by ~1e-16).
    """
    return all(abs(u - v) <= _PARALLEL for u, v in zip(a[:-1], b[:-1])) and abs(a[-1] - b[-1]) <= tol


def stop_at_walls(walls: list, x: np.ndarray, dx: np.ndarray, v: np.ndarray, time: float, dt: float) -> int:
    """Stop on the wall each particle whose move ``dx`` would cross one; return how many.

    ``x`` (``(n, 3)``), ``dx`` and ``v`` (``(n, gdim)``, C-contiguous) are the positions, the moves
    and the velocities [m/s] of the step from ``time`` to ``time + dt`` [s]; ``dx`` loses the
    part beyond the wall, ``v`` its component into the wall (relative to a moving wall). Each
    particle meets the walls in their order; one compiled pass over the particles.
    """
    walls = [w for w in walls if isinstance(w, RigidWall)]
    if not walls:
        return 0
    g, n = walls[0].gdim, len(x)
    if dx.shape != (n, g) or v.shape != (n, g):
        raise ValueError(f"dx and v must have shape ({n}, {g}), got {dx.shape} and {v.shape}")
    moved2 = dx[:, 0] ** 2 + dx[:, 1] ** 2 if g == 2 else dx[:, 0] ** 2 + dx[:, 1] ** 2 + dx[:, 2] ** 2
    reach = np.sqrt(np.max(moved2, initial=0.0))  # the longest move: only particles this near can cross
    advances = [dt * (w.velocity @ w.normal) for w in walls]  # each wall's own move along its normal
    per_wall = lambda values: np.ascontiguousarray(values, dtype=np.float64)  # noqa: E731
    starts, normals = per_wall([w.start(time) for w in walls]), per_wall([w.normal for w in walls])
    limits = per_wall([reach + abs(advance) for advance in advances])
    roundoff = per_wall([ROUNDOFF * w.length for w in walls])
    if g == 2:
        tangents, lengths = per_wall([w.tangent for w in walls]), per_wall([w.length for w in walls])
        shift_t = per_wall([(w.velocity @ w.tangent) * dt for w in walls])
        shifts = inward = offsets = _NONE
        begin = np.zeros(len(walls) + 1, dtype=np.int32)
    else:
        tangents = lengths = shift_t = _NONE
        shifts = per_wall([w.velocity * time for w in walls])
        inward = per_wall(np.concatenate([w._inward for w in walls]))
        offsets = per_wall(np.concatenate([w._offset for w in walls]))
        begin = np.cumsum([0, *(len(w._offset) for w in walls)], dtype=np.int32)
    velocities, stopped = per_wall([w.velocity for w in walls]), np.zeros(1, dtype=np.int64)
    _kernels().stop_at_walls(
        n, g, np.ascontiguousarray(x, dtype=np.float64).reshape(n, 3), dx, v, len(walls), starts, normals,
        limits, per_wall(advances), roundoff, tangents, lengths, shift_t, velocities, shifts, dt, begin,
        inward, offsets, stopped,
    )  # fmt: skip
    return int(stopped[0])
