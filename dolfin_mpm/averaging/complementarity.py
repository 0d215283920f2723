"""The paper's non-local law at the end of a step: a complementarity problem in the rates.

Each point has a rate ``u_i >= 0`` [-] (``dt`` times its equivalent viscoplastic strain rate)
and its stress applies the averaged increment ``d = A u`` (eq. 5). Its own law gives ``u`` of
its end state ``q = q_trial - 2 G d``; written the other way round, the material gives the
increment ``delta_i(u_i)`` whose end state has the rate ``u_i``
(:meth:`~dolfin_mpm.materials.drucker_prager.DruckerPragerViscoplastic.increment_of_rate`):
``(q_trial - y (1 + (u / c)^(1/N))) / 2G`` on a Perzyna cone, ``q_trial / 2G`` at its apex.
A point flows (``u_i > 0``) where ``(A u)_i = delta_i(u_i)``, and stays put (``u_i = 0``) where
the averaged increment leaves it inside its cone, ``(A u)_i >= delta_i(0)``:

    u >= 0,   r(u) = A u - delta(u) >= 0,   u_i r_i(u) = 0.

For ``N = 1`` ``delta`` is linear and this is a linear complementarity problem with the matrix
``A + diag(1 / a)``, ``a = 3 G gamma dt / y``; with a positive-definite weight (Wendland's)
``A`` is a P-matrix, so the solution is unique and depends continuously on the trial states.
That holds across a cone's apex too: there ``1 / a -> 0`` and the point, stress free, takes
the rate that its neighbourhood's average needs. (Fixing the rate of a point at the apex
instead, ``u = q_trial / 2G``, makes the answer jump as points cross the apex between the
loop's iterates, and the loop cycles.)

It is solved by semismooth Newton on ``min(u, s r(u)) = 0`` (``s = 1 / (1 + slope)`` scales
each row to its point, ``slope = -delta'``), each Newton system by GMRES, inexactly: the
system is solved to a tenth of its residual or to half the tolerance, whichever is looser.
"""

import math
from collections.abc import Callable

import numpy as np
from mpi4py import MPI

__all__ = ["gmres", "solve_rates"]


def gmres(
    matvec: Callable[[np.ndarray], np.ndarray],
    b: np.ndarray,
    comm: MPI.Comm,
    rtol: float,
    atol: float = 0.0,
    maxiter: int = 60,
) -> tuple[np.ndarray, int]:
    """GMRES from ``x = 0`` for ``A x = b`` with dot products over ``comm``.

    Stops when the residual is at most ``max(rtol |b|, atol)`` or after ``maxiter`` iterations
    (no restart). Returns ``x`` and the iterations taken.
    """

    def norm(v):
        return math.sqrt(comm.allreduce(float(v @ v), MPI.SUM))

    beta = norm(b)
    if beta == 0.0 or beta <= atol:
        return np.zeros_like(b), 0
    basis = [b / beta]
    H = np.zeros((maxiter + 1, maxiter))
    g = np.zeros(maxiter + 1)
    g[0] = beta
    cs, sn = np.zeros(maxiter), np.zeros(maxiter)
    for j in range(maxiter):
        w = matvec(basis[j])
        for i, v in enumerate(basis):  # modified Gram-Schmidt
            H[i, j] = comm.allreduce(float(w @ v), MPI.SUM)
            w = w - H[i, j] * v
        H[j + 1, j] = norm(w)
        for i in range(j):  # the earlier rotations, then this column's
            a, b = H[i, j], H[i + 1, j]
            H[i, j], H[i + 1, j] = cs[i] * a + sn[i] * b, -sn[i] * a + cs[i] * b
        r = math.hypot(H[j, j], H[j + 1, j])
        cs[j], sn[j] = H[j, j] / r, H[j + 1, j] / r
        g[j + 1], g[j] = -sn[j] * g[j], cs[j] * g[j]
        H[j, j], H[j + 1, j] = r, 0.0
        if abs(g[j + 1]) <= max(rtol * beta, atol) or j + 1 == maxiter:
            break
        basis.append(w / max(norm(w), 1e-300))
    k = j + 1
    y = np.linalg.solve(np.triu(H[:k, :k]), g[:k])
    return sum(y[i] * basis[i] for i in range(k)), k


def solve_rates(
    average: Callable[[np.ndarray], np.ndarray],
    increment_of_rate: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
    u0: np.ndarray,
    comm: MPI.Comm,
    tol: float,
    max_newton: int = 30,
) -> tuple[np.ndarray, np.ndarray, dict]:
    """The rates ``u`` and applied increments ``d = A u`` of the paper's law, all ``shape=(n,)``.

    Args:
        average: the operator the increments take from the rates, ``d = A u`` (a callable on
            particle fields): the non-local average, or the over-non-local mix
            ``m A + (1 - m) I`` (:meth:`~dolfin_mpm.averaging.law.NonlocalLaw.applied`).
        increment_of_rate: ``u -> (delta(u), slope)``, the increment whose end state has the
            rate ``u`` and ``-d delta / d u >= 0``, both [-].
        u0: the first guess (the last iterate's or the last step's rates).
        comm: the communicator the particles are spread over.
        tol: the tolerance on ``|min(u, s r)|`` [-] (an increment: the stresses it leaves
            unbalanced are ``2 G`` times it).
        max_newton: most Newton iterations.

    Returns:
        ``(d, u, stats)``; ``stats`` counts ``newton`` and ``krylov`` iterations and says
        whether the tolerance was met (``converged``).

    """

    def evaluate(u):
        Au = average(u)
        delta, slope = increment_of_rate(u)
        r = Au - delta
        s = 1.0 / (1.0 + slope)
        phi = np.minimum(u, s * r)
        return Au, r, s, math.sqrt(comm.allreduce(float(phi @ phi), MPI.SUM))

    u = np.maximum(u0, 0.0)
    Au, r, s, res = evaluate(u)
    stats = {"newton": 0, "krylov": 0, "converged": False}
    for _ in range(max_newton):
        if res <= tol:
            stats["converged"] = True
            break
        flowing = s * r < u  # the rows where min(u, s r) takes s r
        # Still points go to u = 0; the flowing rows solve s (A du)_i + (1 - s) du_i = -s r_i.
        fixed = np.where(flowing, 0.0, -u)
        if comm.allreduce(bool(fixed.any()), MPI.LOR):  # collective: the average is
            r = r + average(fixed)
        rhs = np.where(flowing, -s * r, 0.0)

        def jacobian(v):
            v = np.where(flowing, v, 0.0)
            return np.where(flowing, s * average(v) + (1.0 - s) * v, 0.0)

        du, k = gmres(jacobian, rhs, comm, rtol=0.1, atol=0.5 * tol)
        stats["newton"] += 1
        stats["krylov"] += k
        u = u + np.where(flowing, du, fixed)
        Au, r, s, res = evaluate(u)
    else:
        stats["converged"] = res <= tol
    return Au, u, stats
