"""Non-local averaging over particles (the paper's eqs. 2, 3 and 5).

    avg(e)_i = sum_j w(s_ij) e_j V_j / sum_j w(s_ij) V_j,   s_ij = |x_i - x_j| / r,

over all particles within the radius ``r`` (a circle in 2D, a sphere in 3D), self included.
Neighbour pairs come from scipy's KD-tree for the radius plus a skin and are kept while no
particle has moved more than half the skin since they were found (the Verlet-list idea of
molecular dynamics); weights are recomputed on the kept pairs every step.
"""

from collections.abc import Callable

import numpy as np
from scipy.sparse import csr_matrix
from scipy.spatial import cKDTree

from dolfin_mpm.materials.base import check_range

__all__ = ["WEIGHTS", "NonlocalAverage"]

#: Weight functions w(s) on 0 <= s <= 1 (zero outside).
WEIGHTS: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "cubic": lambda s: 1.0 + s * s * (2.0 * s - 3.0),
    "constant": lambda s: np.ones_like(s),
    "gaussian": lambda s: np.exp(-2.5 * s * s),
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
        pairs = pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]  # i < j, row-major: CSR order
        self._set_pairs(pairs[:, 0], pairs[:, 1], x.shape[0])
        self._x_built, self._ids = x.copy(), ids.copy()
        self.rebuilds += 1

    def _set_pairs(self, i: np.ndarray, j: np.ndarray, n: int) -> None:
        """Store the pairs ``i < j`` (row-major) as the sparsity of ``U``.

        The weights are symmetric: ``A = U + U^T + I`` with ``U`` the strictly upper triangle,
        whose sparsity stays fixed between rebuilds (only its values change each step).
        """
        self._i, self._j = i.astype(np.int64), j.astype(np.int32)
        indptr = np.r_[0, np.cumsum(np.bincount(self._i, minlength=n))].astype(np.int32)
        self._U = csr_matrix((np.zeros(len(i)), self._j, indptr), shape=(n, n))

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
        self._set_pairs(i[both], j[both], len(ids))  # the order i < j, row-major, is kept
        self._x_built, self._ids = self._x_built[old], ids.copy()
        return True

    def update(self, x: np.ndarray, volume: np.ndarray, ids: np.ndarray) -> None:
        """Weights for the current positions ``x`` (``(n, gdim)``) and volumes ``(n,)``.

        ``ids`` (``(n,)``) identify the particles: the pair list is rebuilt when
        particles were added or reordered, or when one has moved more than half the skin since
        the last rebuild; particles that were removed (sinks) only drop their pairs.
        """
        if self.is_local:
            return
        x = np.ascontiguousarray(x)
        if (
            self._ids is None
            or not (np.array_equal(ids, self._ids) or self._drop_removed(ids))
            or np.max(np.sum((x - self._x_built) ** 2, axis=1), initial=0.0) > (0.5 * self.skin) ** 2
        ):
            self._rebuild(x, ids)
        s = np.zeros(len(self._i))
        for c in range(x.shape[1]):
            xc = np.ascontiguousarray(x[:, c])
            dx = xc.take(self._i)
            dx -= xc.take(self._j)
            dx *= dx
            s += dx
        np.sqrt(s, out=s)
        s *= 1.0 / self.radius
        outside = s > 1.0
        s[outside] = 1.0
        w = self._w(s)
        w[outside] = 0.0
        self._U.data = w
        self._volume = volume
        self._denominator = self._apply(volume)

    def _apply(self, v: np.ndarray) -> np.ndarray:
        return v + self._U @ v + self._U.T @ v

    def __call__(self, e: np.ndarray) -> np.ndarray:
        """The average of the field ``e`` (``shape=(n,)``) with the weights of the last update."""
        if self.is_local:
            return e
        return self._apply(self._volume * e) / self._denominator
