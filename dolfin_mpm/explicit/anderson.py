"""Anderson acceleration of a fixed-point iteration ``x = G(x)`` on distributed vectors."""

import numpy as np

from dolfin_mpm.parallel.reduce import sum_over_ranks

__all__ = ["Anderson"]


class Anderson:
    """Anderson mixing of depth ``depth`` for ``x = G(x)``.

    ``x_new = G(x) - dG gamma``, with ``gamma`` minimising ``|f - dF gamma|`` over the last
    ``depth`` differences of the residual ``f = G(x) - x`` and of ``G``.

    Vectors are the rank's part of a global vector; inner products are summed over ``comm``.
    """

    def __init__(self, depth: int, comm):
        self.depth, self.comm = depth, comm
        self._f = self._g = None
        self._dF: list[np.ndarray] = []
        self._dG: list[np.ndarray] = []

    def __call__(self, x: np.ndarray, g: np.ndarray) -> np.ndarray:
        """The next iterate from the current one ``x`` and its image ``g = G(x)``."""
        f = g - x
        if self._f is not None:
            self._dF.append(f - self._f)
            self._dG.append(g - self._g)
            if len(self._dF) > self.depth:
                self._dF.pop(0)
                self._dG.pop(0)
        self._f, self._g = f, g
        if not self._dF:
            return g
        dF = np.array(self._dF)  # (m, n)
        local = np.concatenate([(dF @ dF.T).ravel(), dF @ f])
        total = sum_over_ranks(self.comm, local)
        m = len(self._dF)
        A, b = total[: m * m].reshape(m, m), total[m * m :]
        A += 1e-12 * np.trace(A) * np.eye(m) + 1e-300 * np.eye(m)
        gamma = np.linalg.solve(A, b)
        return g - gamma @ np.array(self._dG)
