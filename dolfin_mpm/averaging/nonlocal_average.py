"""Non-local averaging over particles (the paper's eqs. 2, 3 and 5).

::

    avg(e)_i = sum_j w(s_ij) e_j V_j / sum_j w(s_ij) V_j,   s_ij = |x_i - x_j| / r,

over all particles within the radius ``r`` (a circle in 2D, a sphere in 3D), self included.
Neighbour pairs are found for the radius plus a skin, by sorting the particles into cubes of
that side, and kept while no particle has moved more than half the skin since they were found
(the Verlet list of molecular dynamics); weights are recomputed on the kept pairs every step,
in double precision from the current positions. The set of particles may change between steps
without a rebuild: a removed particle (a sink, or one that moved to another rank) keeps a dead
slot until the next rebuild, and a particle that arrives (from another rank, or into the halo
of another rank's particles) gets a slot and its pairs from a search around it alone (scipy's
KD-tree). Once particles have arrived the rebuild comes at a third of the skin: pairs found
at different times stay complete for that long.

The loops over the pairs (~10^7 for 10^5 particles at r = 2h) are compiled C
(``nonlocal_average.c``): the weights and the symmetric product, each one pass a step where
numpy would stream every intermediate through memory, and the search of a rebuild. They
are bound by memory bandwidth, so the pairs are stored in runs of equal first index (its
value once per run) and the weight pass hands the products only the pairs closer than r
(about two thirds of those within r + skin), in room for as many as the last update found and
a tenth more (it makes more room when more came within r). The first average of an update
sums the denominators in the same pass, the two fields side by side in memory.
"""

import ctypes
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from dolfin_mpm import native
from dolfin_mpm.averaging.law import NonlocalLaw
from dolfin_mpm.params import Range

__all__ = ["WEIGHTS", "IdIndex", "NonlocalAverage", "ball_weight"]

#: The weights w(s), s = distance / r, zero for s >= 1: ``1 + s^2 (2s - 3)``, ``1``,
#: ``exp(-2.5 s^2)`` and Wendland's ``(1 - s)^4 (1 + 4 s)``; the value is the kernel's code for
#: each. Wendland's alone is positive definite (in 2D and 3D): the average of a field that
#: alternates from point to point keeps its sign, where the others' can turn it over (the least
#: eigenvalue of the average on a lattice of spacing r/2 is -0.04 for the cubic, -0.03 for the
#: Gaussian, -0.33 for the constant, +0.20 for Wendland's). The laws that iterate the end
#: states through the average need that (:mod:`dolfin_mpm.averaging.law`).
WEIGHTS = {"cubic": 0, "constant": 1, "gaussian": 2, "wendland": 3}

_INDEX, _OFFSET, _REAL = native.array(np.int32), native.array(np.int64), native.array(np.float64)
_SIGNATURES = {
    "pair_weights": (
        ctypes.c_int64, _INDEX, _OFFSET, _INDEX, ctypes.c_int32, _REAL, ctypes.c_double, ctypes.c_int32,
        ctypes.c_int64, _INDEX, _OFFSET, _INDEX, _REAL, _OFFSET,
    ),
    "pair_apply": (ctypes.c_int64, ctypes.c_int64, _INDEX, _OFFSET, _INDEX, _REAL, _REAL, _REAL),
    "pair_apply2": (ctypes.c_int64, ctypes.c_int64, _INDEX, _OFFSET, _INDEX, _REAL, _REAL, _REAL),
    "subsequence": (ctypes.c_int64, _OFFSET, ctypes.c_int64, _OFFSET, _OFFSET),
    "max_moved2": (ctypes.c_int64, ctypes.c_int32, _REAL, _OFFSET, _REAL, _REAL),
    "pair_search": (
        ctypes.c_int64, ctypes.c_int32, _REAL, ctypes.c_double, _REAL, ctypes.c_double, _OFFSET,
        ctypes.c_int64, _INDEX, _OFFSET, _INDEX, _OFFSET, _INDEX, _OFFSET, _OFFSET,
    ),
}  # fmt: skip
_kernels = native.kernels(Path(__file__).with_suffix(".c"), _SIGNATURES)


class IdIndex:
    """Where particle ids sit in the array ``ids`` (``shape=(n,)``, unique) it is made from."""

    def __init__(self, ids: np.ndarray):
        self._order = np.argsort(ids, kind="stable")
        self._sorted = ids[self._order]

    def __call__(self, ids: np.ndarray) -> np.ndarray:
        """The index of each of ``ids`` in the array, -1 for those not in it."""
        if len(self._sorted) == 0:
            return np.full(len(ids), -1, dtype=np.intp)
        k = np.minimum(np.searchsorted(self._sorted, ids), len(self._sorted) - 1)
        return np.where(self._sorted[k] == ids, self._order[k], -1)


@dataclass
class _Pairs:
    """Pairs ``(i, j)`` in runs of equal ``i``.

    Run ``r`` holds the pairs ``(row[r], j[k])``, ``begin[r] <= k < begin[r + 1]``; particles
    are int32, offsets int64.
    """

    row: np.ndarray
    begin: np.ndarray
    j: np.ndarray

    @classmethod
    def of(cls, i: np.ndarray, j: np.ndarray) -> "_Pairs":
        """The pairs ``(i[k], j[k])``; equal ``i`` next to each other share a run."""
        first = np.flatnonzero(np.r_[True, i[1:] != i[:-1]]) if len(i) else np.zeros(0, dtype=np.int64)
        return cls(i[first].astype(np.int32), np.r_[first, len(i)].astype(np.int64), j.astype(np.int32))

    @classmethod
    def empty(cls, runs: int, m: int) -> "_Pairs":
        """Room for ``runs`` runs of ``m`` pairs in all."""
        row, begin = np.empty(runs, dtype=np.int32), np.zeros(runs + 1, dtype=np.int64)
        return cls(row, begin, np.empty(m, dtype=np.int32))

    def __add__(self, other: "_Pairs") -> "_Pairs":
        begin = np.r_[self.begin[:-1], other.begin + len(self.j)]
        return _Pairs(np.r_[self.row, other.row], begin, np.r_[self.j, other.j])

    def expand(self, first_run: int = 0) -> np.ndarray:
        """The pairs of the runs from ``first_run`` on, ``shape=(m, 2)``."""
        begin = self.begin[first_run:]
        return np.c_[np.repeat(self.row[first_run:], np.diff(begin)), self.j[begin[0] :]]


class NonlocalAverage:
    """Weighted average of a particle field over a ball of radius ``radius``.

    Args:
        radius: support radius r [m], >= 0; 0 switches averaging off (local model).
        weight: ``"cubic"``, ``"constant"``, ``"gaussian"`` or ``"wendland"`` (:data:`WEIGHTS`).
        skin: extra search distance [m] that lets pairs be reused, >= 0; default ``r / 4``.
        law: how the average enters the stress, a :class:`~dolfin_mpm.averaging.law.NonlocalLaw`
            or its name (see :mod:`dolfin_mpm.averaging.law`).
        boundary_correction: the weight a point misses beyond a free surface or a wall (the
            ball's full weight less its neighbours') goes to its own value (Borino, Failla &
            Parrinello 2003): ``avg_i = (sum_j w_ij V_j e_j + max(W - D_i, 0) e_i) / max(W, D_i)``,
            ``D_i = sum_j w_ij V_j``, ``W`` the integral of the weight over the ball.

    """

    #: The allowed radius and skin [m].
    RADIUS = SKIN = Range(0.0, math.inf, "m", (True, False))

    def __init__(
        self,
        radius: float,
        weight: str = "cubic",
        skin: float | None = None,
        law: NonlocalLaw | str = "max",
        boundary_correction: bool = False,
    ):
        self.RADIUS.check("radius", radius)
        if weight not in WEIGHTS:
            raise ValueError(f"weight must be one of {sorted(WEIGHTS)}, got {weight!r}")
        skin = 0.25 * radius if skin is None else skin
        self.SKIN.check("skin", skin)
        self.radius, self.weight, self.skin = float(radius), weight, float(skin)
        self.law = law if isinstance(law, NonlocalLaw) else NonlocalLaw(law)
        if self.law.iterative and weight != "wendland":
            raise ValueError(
                f"law {self.law.name!r} needs the positive-definite weight 'wendland', got {weight!r}: "
                "with the others its iteration does not converge (see dolfin_mpm.averaging.law)"
            )
        if not isinstance(boundary_correction, bool):
            raise ValueError(f"boundary_correction must be true or false, got {boundary_correction!r}")
        self.boundary_correction = boundary_correction
        self._slot_ids = None
        self._pairs = _Pairs.empty(0, 0)
        self._within, self._w = _Pairs.empty(0, 0), np.zeros(0)  # the pairs closer than r, weights
        self._within_count = None  # how many there were at the last update
        self._within_of = None  # the pairs they were found among
        self.rebuilds = 0
        if not self.is_local:
            _kernels()  # compiled now, before any long work

    @property
    def is_local(self) -> bool:
        return self.radius == 0.0

    # -- slots: every particle the pair list knows, in the order it became known -------------------
    # Slots ``[0, base)`` are the particles of the last rebuild, the first ``base_pairs`` pairs
    # theirs; later slots arrived since, their pairs (with any slot) appended. ``x_ref`` is each
    # slot's position when its pairs were found, ``x_slot`` its position now (infinity for a
    # dead slot: a removed particle's). The caller's particles map to their slots through
    # ``slot``, their ids to their index through ``index``. Pairs ``(i, j)`` are int32, each
    # unordered pair once.

    def _rebuild(self, x: np.ndarray, ids: np.ndarray) -> None:
        n = len(x)
        m = len(self._pairs.j)  # room for as many pairs as last time and a tenth more: one search
        self._pairs = _search(x, self.radius + self.skin, m + m // 10 + 1024 if self.rebuilds else None)
        self._slot_ids, self._x_ref, self._base = ids.copy(), x.copy(), n
        self._base_runs = len(self._pairs.row)
        self._x_slot = x.copy()
        self._set_live(np.arange(len(ids)), ids)
        self.rebuilds += 1

    def _set_live(self, slot: np.ndarray, ids: np.ndarray) -> None:
        """The caller's particles ``ids`` are the slots ``slot``; every other slot is dead.

        Dead slots move to infinity: the weight pass drops their pairs, whatever their history.
        """
        live = np.zeros(len(self._slot_ids), dtype=bool)
        live[slot] = True
        self._x_slot[~live] = np.inf
        self._slot, self._ids, self._index = slot, ids.copy(), None  # the index: made when needed
        n = len(self._slot_ids)
        self._identity = len(slot) == n and np.array_equal(slot, np.arange(n))

    def _slots_of(self, ids: np.ndarray) -> np.ndarray:
        """Live slot of each of ``ids``, -1 for particles not known (or removed) since."""
        known = np.ascontiguousarray(self._ids, dtype=np.int64)
        ids = np.ascontiguousarray(ids, dtype=np.int64)
        if len(ids) <= len(known):  # the common case: some removed (a sink), the order kept
            at = np.empty(len(ids), dtype=np.int64)
            _kernels().subsequence(len(known), known, len(ids), ids, at)
            if len(ids) == 0 or at[0] >= 0:
                return self._slot[at]
        if self._index is None:
            self._index = IdIndex(self._ids)
        at = self._index(ids)
        return np.where(at >= 0, self._slot[at], -1) if len(self._slot) else at

    def _add_slots(self, ids: np.ndarray, x: np.ndarray) -> None:
        self._slot_ids = np.r_[self._slot_ids, ids]
        self._x_ref = np.r_[self._x_ref, x]
        self._x_slot = np.r_[self._x_slot, x]

    def _add(self, x: np.ndarray, slot: np.ndarray, ids: np.ndarray) -> np.ndarray:
        """Slots and pairs for the particles with ``slot == -1``; returns the completed ``slot``."""
        new = slot < 0
        first, m = len(self._slot_ids), int(new.sum())
        slot = slot.copy()
        slot[new] = first + np.arange(m)
        self._add_slots(ids[new], x[new])
        reach = self.radius + self.skin
        among = cKDTree(x[new]).query_pairs(reach, output_type="ndarray")
        old = np.flatnonzero(~new)
        old = old[_near(x[new], x[old], reach)]
        found = cKDTree(x[new]).sparse_distance_matrix(cKDTree(x[old]), reach, output_type="ndarray")
        rows = np.r_[first + among[:, 1], first + found["i"]]
        cols = np.r_[first + among[:, 0], slot[old][found["j"]]]
        order = np.argsort(rows, kind="stable")
        self._pairs += _Pairs.of(rows[order], cols[order])
        return slot

    # -- the average ------------------------------------------------------------------------------
    def state(self) -> dict[str, np.ndarray]:
        """What rebuilds the kept pair list exactly (empty before the first update).

        Positions ``(m, gdim)`` and ids at the last rebuild, the ids now (those still present
        and those that arrived since), the rebuild count and, if particles arrived since the
        rebuild, their slots' ids and positions and their pairs.
        """
        if self._slot_ids is None:
            return {}
        b = self._base
        state = {
            "x_built": self._x_ref[:b],
            "ids_built": self._slot_ids[:b],
            "ids": self._ids,
            "rebuilds": np.array(self.rebuilds),
        }
        if len(self._slot_ids) > b:
            added = self._pairs.expand(self._base_runs)
            state.update(ids_added=self._slot_ids[b:], x_added=self._x_ref[b:], pairs_added=added)
        return state

    def restore(self, state: dict[str, np.ndarray]) -> None:
        """Rebuild the pair list of :meth:`state`: same pairs in the same order, bit for bit."""
        if not state:
            self._slot_ids = None
            return
        self._rebuild(np.ascontiguousarray(state["x_built"]), np.asarray(state["ids_built"]))
        if "ids_added" in state:
            self._add_slots(np.asarray(state["ids_added"]), np.asarray(state["x_added"]))
            self._pairs += _Pairs.of(*np.asarray(state["pairs_added"]).T)
        ids = np.asarray(state["ids"])
        self._set_live(np.arange(len(self._slot_ids)), self._slot_ids)
        slot = self._slots_of(ids)
        if np.any(slot < 0):
            raise ValueError("state: particle ids now that the pair list does not know")
        self._set_live(slot, ids)
        self.rebuilds = int(state["rebuilds"])

    def update(self, x: np.ndarray, volume: np.ndarray, ids: np.ndarray, rebuild: bool | None = None) -> None:
        """Weights for the current positions ``x`` (``(n, gdim)``) and volumes ``(n,)``.

        ``ids`` (``(n,)``) identify the particles, in any order. The pair list is rebuilt when
        a particle has moved more than half the skin since the last rebuild (a third, once
        particles have arrived since), or when the removed ones outnumber a quarter of those
        present; removed particles only lose their slot, arrived ones get one. ``rebuild``
        True or False overrides the first test, for a caller that knows (all ranks at once).
        """
        if self.is_local:
            return
        x = np.ascontiguousarray(x, dtype=np.float64)
        if self._slot_ids is None or rebuild:
            self._rebuild(x, ids)
        else:
            slot = self._slot if np.array_equal(ids, self._ids) else self._slots_of(ids)
            num_known = len(ids) if slot is self._slot else int(np.count_nonzero(slot >= 0))
            dead = len(self._slot_ids) - num_known
            if dead > 0.25 * len(ids) or (rebuild is None and self._moved_far(x, slot, num_known < len(ids))):
                self._rebuild(x, ids)
            elif slot is not self._slot:
                if num_known < len(ids):
                    slot = self._add(x, slot, ids)
                self._set_live(slot, ids)
        if self._identity:
            np.copyto(self._x_slot, x)
        else:
            self._x_slot[self._slot] = x
        pairs = self._pairs
        if self._within_of is not pairs:  # new pairs: room for as many closer than r as before
            self._within_room(len(pairs.j) if self._within_count is None else self._within_count)
        counts = np.zeros(2, dtype=np.int64)
        while True:
            within = self._within
            _kernels().pair_weights(
                len(pairs.row), pairs.row, pairs.begin, pairs.j, x.shape[1], self._x_slot, 1.0 / self.radius,
                WEIGHTS[self.weight], len(within.j), within.row, within.begin, within.j, self._w, counts,
            )  # fmt: skip
            if counts[1] <= len(within.j):
                break
            self._within_room(int(counts[1]))  # more pairs came closer than r than there was room for
        self._runs_within, self._within_count = int(counts[0]), int(counts[1])
        self._volume = volume
        self._denominator = None  # with the first average: one pass over the pairs for both

    def _within_room(self, m: int) -> None:
        """Room for ``m`` pairs closer than r, a tenth more and a run of the longest (a run is kept whole)."""
        pairs = self._pairs
        longest = int(np.max(np.diff(pairs.begin), initial=0))
        room = min(m + m // 10 + longest, len(pairs.j))
        self._within, self._w = _Pairs.empty(len(pairs.row), room), np.empty(room)
        self._within_of = pairs

    def _moved_far(self, x: np.ndarray, slot: np.ndarray, arriving: bool) -> bool:
        """Whether a known particle has moved too far since its pairs were found.

        Half the skin, a third once particles have arrived; ``slot``: each particle's, -1 if
        not known.
        """
        largest = np.zeros(1)
        slot = np.ascontiguousarray(slot, dtype=np.int64)
        _kernels().max_moved2(len(x), x.shape[1], x, slot, self._x_ref, largest)
        limit = self.skin / 3.0 if arriving or len(self._slot_ids) > self._base else 0.5 * self.skin
        return largest[0] > limit**2

    def _slot_field(self, v: np.ndarray) -> np.ndarray:
        """The caller's particle field ``v`` on the slots, zero on the dead ones."""
        if self._identity:
            return np.ascontiguousarray(v, dtype=np.float64)
        y = np.zeros(len(self._slot_ids))
        y[self._slot] = v
        return y

    def _apply(self, v: np.ndarray, v2: np.ndarray | None = None) -> np.ndarray | tuple[np.ndarray, ...]:
        """``A v`` (and ``A v2``, in the same pass) for fields of the caller's particles."""
        y = self._slot_field(v)
        z = np.empty_like(y)
        within, kernels = self._within, _kernels()
        args = (len(y), self._runs_within, within.row, within.begin, within.j, self._w)
        if v2 is None:
            kernels.pair_apply(*args, y, z)
            return z if self._identity else z[self._slot]
        y = np.stack([y, self._slot_field(v2)], axis=1)  # side by side: one place per pair for both
        z = np.empty_like(y)
        kernels.pair_apply2(*args, y, z)
        z = z if self._identity else z[self._slot]
        return z[:, 0], z[:, 1]

    @property
    def denominator(self) -> np.ndarray:
        """``D_i = sum_j w_ij V_j`` with the weights and volumes of the last update, ``shape=(n,)``."""
        if self._denominator is None:
            self._set_denominator(self._apply(self._volume))
        return self._denominator

    @property
    def metric(self) -> np.ndarray:
        """``G_i = V_i D_i``, ``shape=(n,)``: the average is self-adjoint in ``<u, v> = sum_i G_i u_i v_i``.

        (``G A = V W V``, plus the diagonal of the missing weights with ``boundary_correction``.)
        """
        return self._volume * self.denominator

    @property
    def own_weight(self) -> np.ndarray:
        """``A_ii``, each point's share of its own average [-], ``shape=(n,)``.

        ``V_i / D_i`` (``w(0) = 1``); with ``boundary_correction``, ``(V_i + W - D_i) / W`` where
        ``D_i < W``. It falls as r spans more points.
        """
        D = self.denominator
        return (self._volume + self._missing) / D if self.boundary_correction else self._volume / D

    def _set_denominator(self, D: np.ndarray) -> None:
        if self.boundary_correction:
            full = ball_weight(self.weight, self.radius, self._x_slot.shape[1])
            self._missing = np.maximum(full - D, 0.0)  # W - D_i where D_i < W
            D = np.maximum(D, full)
        self._denominator = D

    def __call__(self, e: np.ndarray) -> np.ndarray:
        """The average of the field ``e`` (``shape=(n,)``) with the weights of the last update."""
        if self.is_local:
            return e
        if self._denominator is None:  # the first average since the update: D in the same pass
            numerator, D = self._apply(self._volume * e, self._volume)
            self._set_denominator(D)
        else:
            numerator = self._apply(self._volume * e)
        if self.boundary_correction:
            return (numerator + self._missing * e) / self._denominator
        return numerator / self._denominator


def ball_weight(weight: str, radius: float, gdim: int) -> float:
    """The integral of the weight ``w(|x| / r)`` over the ball of radius r [m^gdim] (a disc in 2D)."""
    s = np.linspace(0.0, 1.0, 2001)
    w = {
        "cubic": 1.0 + s * s * (2.0 * s - 3.0),
        "constant": np.ones_like(s),
        "gaussian": np.exp(-2.5 * s * s),
        "wendland": (1.0 - s) ** 4 * (1.0 + 4.0 * s),
    }
    sphere = 2.0 * math.pi if gdim == 2 else 4.0 * math.pi  # the unit circle's length, sphere's area
    f = w[weight] * s ** (gdim - 1)
    return float(sphere * radius**gdim * np.sum(0.5 * (f[1:] + f[:-1]) * np.diff(s)))


def _search(x: np.ndarray, reach: float, capacity: int | None = None) -> _Pairs:
    """Every unordered pair of the points ``x`` (``(n, gdim)``) at most ``reach`` apart, once.

    ``capacity`` is a guess of their number, default ``16 n`` (the search runs again if it
    was short).
    """
    n, gdim = x.shape
    if n == 0:
        return _Pairs.empty(0, 0)
    columns = [x[:, c] for c in range(gdim)]  # by columns: numpy is slow over short rows
    lo = np.array([c.min() for c in columns])
    extent = np.array([c.max() for c in columns]) - lo
    # Cubes of side >= reach, at most about two per point (a sparse cloud gets larger ones).
    side = reach
    while math.prod(int(e / side) + 1 for e in extent) > 2 * n + 8:
        side *= 1.5
    num_cubes = (extent / side).astype(np.int64) + 1
    cube, order = np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int32)
    start = np.empty(math.prod(num_cubes) + 1, dtype=np.int64)
    counts = np.zeros(2, dtype=np.int64)
    capacity = 16 * n if capacity is None else capacity
    while True:
        pairs = _Pairs.empty(n, capacity)
        _kernels().pair_search(
            n, gdim, x, reach, lo, side, num_cubes, capacity, pairs.row, pairs.begin, pairs.j,
            cube, order, start, counts,
        )  # fmt: skip
        if counts[1] <= capacity:
            runs, m = counts
            return _Pairs(pairs.row[:runs], pairs.begin[: runs + 1], pairs.j[:m])
        capacity = int(counts[1])


def _near(points: np.ndarray, others: np.ndarray, distance: float) -> np.ndarray:
    """Mask of ``others`` in the cubes of side ``distance`` holding or next to one of ``points``.

    A superset of the ``others`` within ``distance`` of a point; both ``shape=(n, gdim)``.
    """
    if len(points) == 0 or len(others) == 0:
        return np.zeros(len(others), dtype=bool)
    lo = np.minimum(points.min(axis=0), others.min(axis=0))
    hi = np.maximum(points.max(axis=0), others.max(axis=0))
    shape = np.floor((hi - lo) / distance).astype(np.int64) + 3
    cube = lambda y: np.floor((y - lo) / distance).astype(np.int64) + 1  # noqa: E731
    gdim = points.shape[1]
    offsets = np.stack(np.meshgrid(*[[-1, 0, 1]] * gdim, indexing="ij"), -1).reshape(-1, gdim)
    near = np.unique(np.ravel_multi_index((cube(points)[:, None, :] + offsets).reshape(-1, gdim).T, shape))
    return np.isin(np.ravel_multi_index(cube(others).T, shape), near)
