"""Non-local averaging over particles (the paper's eqs. 2, 3 and 5).

    avg(e)_i = sum_j w(s_ij) e_j V_j / sum_j w(s_ij) V_j,   s_ij = |x_i - x_j| / r,

over all particles within the radius ``r`` (a circle in 2D, a sphere in 3D), self included.
Neighbour pairs come from scipy's KD-tree for the radius plus a skin and are kept while no
particle has moved more than half the skin since they were found (the Verlet-list idea of
molecular dynamics); weights are recomputed on the kept pairs every step. The set of particles
may change between steps without a rebuild: a removed particle (a sink, or one that moved to
another rank) keeps a dead slot until the next rebuild, and a particle that arrives (from
another rank, or into the halo of another rank's particles) gets a slot and its pairs from a
search around it alone. Once particles have arrived the rebuild comes at a third of the skin:
pairs found at different times stay complete for that long.

The distances are the pair offsets at the time they were found plus the displacements since,
in single precision: this halves the memory traffic of the refresh, the costliest part of the
non-local step, and keeps the weights to ~1e-6 (the coordinates enter only through the
offsets, so the size of the domain does not matter). The refresh runs over blocks of pairs
small enough for the CPU cache, so that its chain of element-wise operations does not stream
every intermediate through memory.
"""

from collections.abc import Callable

import numpy as np
from scipy.sparse import csr_matrix, spmatrix
from scipy.spatial import cKDTree

from dolfin_mpm.materials.base import check_range

__all__ = ["WEIGHTS", "NonlocalAverage"]

#: Pairs per block of the weight refresh: its float32 scratch (< 1 MB) stays in cache.
PAIR_BLOCK = 32768


def _cubic(t: np.ndarray, out: np.ndarray) -> np.ndarray:
    # (1 - t)^2 (1 + 2t) = 1 + t^2 (2t - 3), without the cancellation near t = 1
    np.multiply(t, 2.0, out=out)
    out += 1.0
    out *= np.square(1.0 - t)
    return out


def _constant(t: np.ndarray, out: np.ndarray) -> np.ndarray:
    return np.less(t, 1.0, out=out)


def _gaussian(t: np.ndarray, out: np.ndarray) -> np.ndarray:
    np.multiply(t, t, out=out)
    out *= -2.5
    np.exp(out, out=out)
    out *= t < 1.0
    return out


#: Weights ``w(t, out)`` of ``t = min(s, 1)``, ``s = distance / r``, written into ``out``:
#: ``1 + t^2 (2t - 3)``, ``1`` and ``exp(-2.5 t^2)`` inside the ball, zero at ``t = 1`` (outside).
WEIGHTS: dict[str, Callable[[np.ndarray, np.ndarray], np.ndarray]] = {
    "cubic": _cubic,
    "constant": _constant,
    "gaussian": _gaussian,
}


class NonlocalAverage:
    """Weighted average of a particle field over a ball of radius ``radius``.

    Args:
        radius: support radius r [m], >= 0; 0 switches averaging off (local model).
        weight: ``"cubic"``, ``"constant"`` or ``"gaussian"``.
        skin: extra search distance [m] that lets pairs be reused, >= 0; default ``r / 4``.

    """

    def __init__(self, radius: float, weight: str = "cubic", skin: float | None = None):
        check_range("radius", radius, 0.0, np.inf, closed=(True, False))
        if weight not in WEIGHTS:
            raise ValueError(f"weight must be one of {sorted(WEIGHTS)}, got {weight!r}")
        skin = 0.25 * radius if skin is None else skin
        check_range("skin", skin, 0.0, np.inf, closed=(True, False))
        self.radius, self.weight, self.skin = float(radius), weight, float(skin)
        self._w = WEIGHTS[weight]
        self._slot_ids = None
        self.rebuilds = 0

    @property
    def is_local(self) -> bool:
        return self.radius == 0.0

    # -- slots: every particle the pair list knows, in the order it became known -------------------
    # Slots ``[0, base)`` are the particles of the last rebuild, their pairs in ``U``; later ones
    # arrived since, their pairs (with any slot) in ``U_added``, one row per arrived slot.
    # ``x_ref`` is each slot's position when its pairs were found; ``live`` is False for removed
    # particles. The caller's particles map to their slots through ``slot``.

    def _rebuild(self, x: np.ndarray, ids: np.ndarray) -> None:
        pairs = cKDTree(x).query_pairs(self.radius + self.skin, output_type="ndarray")
        # Grouped by row, as CSR needs; columns stay unsorted within a row, and as nothing
        # sorts U, its data keeps the order of the pairs.
        order = np.argsort(pairs[:, 0].astype(np.int32), kind="stable")
        i, j = np.ascontiguousarray(pairs.take(order, axis=0).T)
        self._slot_ids, self._x_ref, self._base = ids.copy(), x.copy(), len(ids)
        self._pairs = self._pair_list(i, j, len(ids))
        self._added = self._pair_list(np.zeros(0, np.intp), np.zeros(0, np.intp), len(ids))
        self._set_live(np.arange(len(ids)), ids)
        self.rebuilds += 1

    def _pair_list(self, i: np.ndarray, j: np.ndarray, n: int) -> tuple:
        """Pairs ``(i, j)`` grouped by ``i`` as ``(i, j, offset, U)``: ``U`` ``(n, n)`` holds
        their weights, ``offset`` ``x_ref[i] - x_ref[j]`` (float32, ``(len(i), gdim)``).

        The weights are symmetric, each pair is listed once: the average applies
        ``A = I + U + U^T``. Gathers are fastest with native-size indices; the matrix keeps
        its own 32-bit copy.
        """
        i, j = i.astype(np.intp), j.astype(np.intp)
        offset = (self._x_ref.take(i, axis=0) - self._x_ref.take(j, axis=0)).astype(np.float32)
        indptr = np.r_[0, np.cumsum(np.bincount(i, minlength=n))].astype(np.int32)
        return i, j, offset, csr_matrix((np.zeros(len(i)), j.astype(np.int32), indptr), shape=(n, n))

    def _set_live(self, slot: np.ndarray, ids: np.ndarray) -> None:
        """The caller's particles ``ids`` are the slots ``slot``; every other slot is dead."""
        self._live = np.zeros(len(self._slot_ids), dtype=bool)
        self._live[slot] = True
        self._slot, self._ids = slot, ids.copy()
        order = np.argsort(ids, kind="stable")
        self._sorted_ids, self._sorted_slots = ids[order], slot[order]
        n = len(self._slot_ids)
        self._identity = len(slot) == n and np.array_equal(slot, np.arange(n))

    def _slots_of(self, ids: np.ndarray) -> np.ndarray:
        """Live slot of each of ``ids``, -1 for particles not known (or removed) since."""
        if len(self._sorted_ids) == 0:
            return np.full(len(ids), -1, dtype=np.intp)
        k = np.minimum(np.searchsorted(self._sorted_ids, ids), len(self._sorted_ids) - 1)
        slot = self._sorted_slots[k]
        return np.where((self._sorted_ids[k] == ids) & self._live[slot], slot, -1)

    def _add(self, x: np.ndarray, slot: np.ndarray, ids: np.ndarray) -> np.ndarray:
        """Slots and pairs for the particles with ``slot == -1``; returns the completed ``slot``."""
        new = slot < 0
        first, m = len(self._slot_ids), int(new.sum())
        slot = slot.copy()
        slot[new] = first + np.arange(m)
        self._slot_ids = np.r_[self._slot_ids, ids[new]]
        self._x_ref = np.r_[self._x_ref, x[new]]
        reach = self.radius + self.skin
        among = cKDTree(x[new]).query_pairs(reach, output_type="ndarray")
        old = np.flatnonzero(~new)
        old = old[_near(x[new], x[old], reach)]
        found = cKDTree(x[new]).sparse_distance_matrix(cKDTree(x[old]), reach, output_type="ndarray")
        rows = np.r_[first + among[:, 1], first + found["i"]].astype(np.intp)
        cols = np.r_[first + among[:, 0], slot[old][found["j"]]].astype(np.intp)
        order = np.argsort(rows, kind="stable")
        i_old, j_old = self._added[:2]
        self._added = self._pair_list(np.r_[i_old, rows[order]], np.r_[j_old, cols[order]], len(self._slot_ids))
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
            i, j = self._added[:2]
            state.update(ids_added=self._slot_ids[b:], x_added=self._x_ref[b:], pairs_added=np.c_[i, j])
        return state

    def restore(self, state: dict[str, np.ndarray]) -> None:
        """Rebuild the pair list of :meth:`state`: same pairs in the same order, bit for bit."""
        if not state:
            self._slot_ids = None
            return
        self._rebuild(np.ascontiguousarray(state["x_built"]), np.asarray(state["ids_built"]))
        if "ids_added" in state:
            self._slot_ids = np.r_[self._slot_ids, state["ids_added"]]
            self._x_ref = np.r_[self._x_ref, state["x_added"]]
            i, j = np.asarray(state["pairs_added"]).T
            self._added = self._pair_list(i, j, len(self._slot_ids))
        ids = np.asarray(state["ids"])
        self._set_live(np.arange(len(self._slot_ids)), self._slot_ids)
        slot = self._slots_of(ids)
        if np.any(slot < 0):
            raise ValueError("state: particle ids now that the pair list does not know")
        self._set_live(slot, ids)
        self.rebuilds = int(state["rebuilds"])

    def update(self, x: np.ndarray, volume: np.ndarray, ids: np.ndarray) -> None:
        """Weights for the current positions ``x`` (``(n, gdim)``) and volumes ``(n,)``.

        ``ids`` (``(n,)``) identify the particles, in any order. The pair list is rebuilt when
        a particle has moved more than half the skin since the last rebuild (a third, once
        particles have arrived since), or when the removed ones outnumber a quarter of those
        present; removed particles only lose their slot, arrived ones get one.
        """
        if self.is_local:
            return
        x = np.ascontiguousarray(x)
        if self._slot_ids is None:
            self._rebuild(x, ids)
        else:
            slot = self._slot if np.array_equal(ids, self._ids) else self._slots_of(ids)
            known = slot >= 0
            u = x[known] - self._x_ref[slot[known]]
            arrived = len(self._slot_ids) > self._base or not known.all()
            limit = self.skin / 3.0 if arrived else 0.5 * self.skin
            dead = len(self._slot_ids) - known.sum()
            if np.max(np.sum(u * u, axis=1), initial=0.0) > limit**2 or dead > 0.25 * len(ids):
                self._rebuild(x, ids)
            elif slot is not self._slot:
                if not known.all():
                    slot = self._add(x, slot, ids)
                self._set_live(slot, ids)
        u = np.zeros((len(self._slot_ids), x.shape[1]), dtype=np.float32)
        u[self._slot] = x - self._x_ref[self._slot]
        for i, j, offset, U in (self._pairs, self._added):
            self._refresh_weights(i, j, offset, U, u)
        self._volume = volume
        self._denominator = self._apply(volume)

    def _refresh_weights(self, i, j, offset, U: spmatrix, u: np.ndarray) -> None:
        """``U``'s values from the slots' displacements ``u`` (float32, ``(n_slots, gdim)``).

        Block by block of pairs: ``s = |offset + u_i - u_j| / r``, ``U_ij = w(min(s, 1))``.
        """
        m, gdim = len(i), u.shape[1]
        d_buf, dj_buf = np.empty((2, min(PAIR_BLOCK, m), gdim), dtype=np.float32)
        s_buf, w_buf = np.empty((2, min(PAIR_BLOCK, m)), dtype=np.float32)
        inv_r = np.float32(1.0 / self.radius)
        for a in range(0, m, PAIR_BLOCK):
            b = min(a + PAIR_BLOCK, m)
            d, d_j, s = d_buf[: b - a], dj_buf[: b - a], s_buf[: b - a]
            np.take(u, i[a:b], axis=0, out=d, mode="clip")  # "clip": no buffered copy
            d -= np.take(u, j[a:b], axis=0, out=d_j, mode="clip")
            d += offset[a:b]
            d *= d
            for c in range(1, gdim):
                d[:, 0] += d[:, c]
            np.sqrt(d[:, 0], out=s)
            s *= inv_r
            np.minimum(s, 1.0, out=s)
            U.data[a:b] = self._w(s, w_buf[: b - a])

    def _apply(self, v: np.ndarray) -> np.ndarray:
        """``A v`` for a field ``v`` of the caller's particles (dead slots hold zero)."""
        if self._identity:
            y = v
        else:
            y = np.zeros(len(self._slot_ids))
            y[self._slot] = v
        z = y.copy()
        b, U, U_added = self._base, self._pairs[3], self._added[3]
        z[:b] += U @ y[:b] + U.T @ y[:b]
        if U_added.nnz:
            z += U_added @ y + U_added.T @ y
        return z if self._identity else z[self._slot]

    def __call__(self, e: np.ndarray) -> np.ndarray:
        """The average of the field ``e`` (``shape=(n,)``) with the weights of the last update."""
        if self.is_local:
            return e
        return self._apply(self._volume * e) / self._denominator


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
