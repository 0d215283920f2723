"""Non-local averaging over particles (the paper's eqs. 2, 3 and 5).

    avg(e)_i = sum_j w(s_ij) e_j V_j / sum_j w(s_ij) V_j,   s_ij = |x_i - x_j| / r,

over all particles within the radius ``r`` (a circle in 2D, a sphere in 3D), self included.
Neighbour pairs come from scipy's KD-tree for the radius plus a skin and are kept while no
particle has moved more than half the skin since they were found (the Verlet-list idea of
molecular dynamics); weights are recomputed on the kept pairs every step. The distances are
the pair offsets at the last rebuild plus the displacements since, in single precision: this
halves the memory traffic of the refresh, the costliest part of the non-local step, and keeps
the weights to ~1e-6 (the coordinates enter only through the offsets, so the size of the
domain does not matter). The refresh runs over blocks of pairs small enough for the CPU cache,
so that its chain of element-wise operations does not stream every intermediate through memory.
"""

from collections.abc import Callable

import numpy as np
from scipy.sparse import csr_matrix
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
        self._ids = None
        self.rebuilds = 0

    @property
    def is_local(self) -> bool:
        return self.radius == 0.0

    def _rebuild(self, x: np.ndarray, ids: np.ndarray) -> None:
        pairs = cKDTree(x).query_pairs(self.radius + self.skin, output_type="ndarray")
        # Grouped by row, as CSR needs; columns stay unsorted within a row, and as nothing
        # sorts U, its data keeps the order of the pairs.
        order = np.argsort(pairs[:, 0].astype(np.int32), kind="stable")
        i, j = np.ascontiguousarray(pairs.take(order, axis=0).T)
        offset = (x.take(i, axis=0) - x.take(j, axis=0)).astype(np.float32)
        self._set_pairs(i, j, offset, x.shape[0])
        self._x_built, self._ids = x.copy(), ids.copy()
        self._built_from = (self._x_built, self._ids)  # kept by _drop_removed, for state()
        self.rebuilds += 1

    def _set_pairs(self, i: np.ndarray, j: np.ndarray, offset: np.ndarray, n: int) -> None:
        """Store the pairs ``i < j``, grouped by ``i``, as the sparsity of ``U``.

        The weights are symmetric: ``A = U + U^T + I`` with ``U`` the strictly upper triangle,
        whose sparsity stays fixed between rebuilds (only its values change each step).
        ``offset`` holds ``x_i - x_j`` at the rebuild, ``shape=(len(i), gdim)``.
        """
        # Gathers are fastest with native-size indices; the matrix keeps its own 32-bit copy.
        self._i, self._j, self._offset = i.astype(np.intp), j.astype(np.intp), offset
        indptr = np.r_[0, np.cumsum(np.bincount(self._i, minlength=n))].astype(np.int32)
        self._U = csr_matrix((np.zeros(len(i)), j.astype(np.int32), indptr), shape=(n, n))

    def _drop_removed(self, ids: np.ndarray) -> bool:
        """Keep the pairs of the particles still present, when ``ids`` only lost some, in order."""
        if not 0 < len(ids) <= len(self._ids):
            return False
        old = np.minimum(np.searchsorted(self._ids, ids), len(self._ids) - 1)
        if not (np.array_equal(self._ids[old], ids) and np.all(np.diff(old) > 0)):
            return False
        new_index = np.full(len(self._ids), -1, dtype=np.int64)
        new_index[old] = np.arange(len(ids))
        i, j = new_index[self._i], new_index[self._j]
        both = (i >= 0) & (j >= 0)
        self._set_pairs(i[both], j[both], self._offset[both], len(ids))  # still grouped by i
        self._x_built, self._ids = self._x_built[old], ids.copy()
        return True

    def state(self) -> dict[str, np.ndarray]:
        """What rebuilds the kept pair list exactly (empty before the first update).

        Positions ``(m, gdim)`` and ids at the last rebuild, the ids now (fewer if particles
        were removed since) and the rebuild count.
        """
        if self._ids is None:
            return {}
        x_built, ids_built = self._built_from
        return {
            "x_built": x_built,
            "ids_built": ids_built,
            "ids": self._ids,
            "rebuilds": np.array(self.rebuilds),
        }

    def restore(self, state: dict[str, np.ndarray]) -> None:
        """Rebuild the pair list of :meth:`state`: same pairs in the same order, bit for bit."""
        if not state:
            self._ids = None
            return
        self._rebuild(np.ascontiguousarray(state["x_built"]), np.asarray(state["ids_built"]))
        ids = np.asarray(state["ids"])
        if not (np.array_equal(ids, self._ids) or self._drop_removed(ids)):
            raise ValueError("state: the particle ids are not those of the last rebuild minus removed ones")
        self.rebuilds = int(state["rebuilds"])

    def update(self, x: np.ndarray, volume: np.ndarray, ids: np.ndarray) -> None:
        """Weights for the current positions ``x`` (``(n, gdim)``) and volumes ``(n,)``.

        ``ids`` (``(n,)``) identify the particles: the pair list is rebuilt when
        particles were added or reordered, or when one has moved more than half the skin since
        the last rebuild; particles that were removed (sinks) only drop their pairs.
        """
        if self.is_local:
            return
        x = np.ascontiguousarray(x)
        kept = self._ids is not None and (np.array_equal(ids, self._ids) or self._drop_removed(ids))
        u = x - self._x_built if kept else None  # displacements since the last rebuild
        if u is None or np.max(np.sum(u * u, axis=1), initial=0.0) > (0.5 * self.skin) ** 2:
            self._rebuild(x, ids)
            u = np.zeros_like(x)
        self._refresh_weights(u.astype(np.float32))
        self._volume = volume
        self._denominator = self._apply(volume)

    def _refresh_weights(self, u: np.ndarray) -> None:
        """``U``'s values from the displacements ``u`` since the rebuild, ``shape=(n, gdim)`` float32.

        Block by block of pairs: ``s = |offset + u_i - u_j| / r``, ``U_ij = w(min(s, 1))``.
        """
        m, gdim = len(self._i), u.shape[1]
        d_buf, dj_buf = np.empty((2, min(PAIR_BLOCK, m), gdim), dtype=np.float32)
        s_buf, w_buf = np.empty((2, min(PAIR_BLOCK, m)), dtype=np.float32)
        inv_r = np.float32(1.0 / self.radius)
        for a in range(0, m, PAIR_BLOCK):
            b = min(a + PAIR_BLOCK, m)
            d, d_j, s = d_buf[: b - a], dj_buf[: b - a], s_buf[: b - a]
            np.take(u, self._i[a:b], axis=0, out=d, mode="clip")  # "clip": no buffered copy
            d -= np.take(u, self._j[a:b], axis=0, out=d_j, mode="clip")
            d += self._offset[a:b]
            d *= d
            for c in range(1, gdim):
                d[:, 0] += d[:, c]
            np.sqrt(d[:, 0], out=s)
            s *= inv_r
            np.minimum(s, 1.0, out=s)
            self._U.data[a:b] = self._w(s, w_buf[: b - a])

    def _apply(self, v: np.ndarray) -> np.ndarray:
        return v + self._U @ v + self._U.T @ v

    def __call__(self, e: np.ndarray) -> np.ndarray:
        """The average of the field ``e`` (``shape=(n,)``) with the weights of the last update."""
        if self.is_local:
            return e
        return self._apply(self._volume * e) / self._denominator
