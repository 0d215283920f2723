"""The overstress law at the end of a step: the end states' overstress, a bound-constrained minimum.

Each point's increment is the Perzyna rate of the averaged overstress of the end states, the
yield function ``f = q - y`` [Pa] (``y = m (p + c cot phi)``, the yield value of ``q``) averaged
and taken relative to the point's own ``y``: ``d_i = c <(A f)_i / y_i>^N`` (``c = 3/2 gamma dt``),
with the end state ``q_i = max(q_trial,i - 2 G d_i, 0)``. In the overstress alone, with
``f_t = q_trial - y`` and ``b = 2 G c / y^N``:

    f_i = max(f_t,i - b_i <(A f)_i>^N, -y_i),

and a point at its cone's apex (``y <= 0``) is stress free, ``f = -y``, whatever its
neighbours. Each ``f_i`` lies in ``[-y_i, f_t,i]`` (``q`` between 0 and the trial's), and the
equations say: ``A f = h(f) = ((f_t - f) / b)^(1/N)`` where ``f_i`` is inside, ``A f >= h`` where
it is at ``-y``, ``A f <= 0`` where it is at ``f_t``. That is the optimality of

    min  Q(f) = 1/2 <f, A f> + sum_i G_i b_i^(-1/N) N / (N + 1) (f_t,i - f_i)^((N + 1) / N)
    over -y <= f <= f_t,

in the inner product ``<u, v> = sum_i G_i u_i v_i`` with ``G_i = V_i D_i`` (the volumes and the
average's denominators), in which ``A`` is self-adjoint, and positive definite for Wendland's
weight: ``Q`` is strictly convex and its minimum is the law's one solution. Near a free
surface ``y -> 0`` and ``b -> inf``: the point is then rate independent, and the problem stays a
convex minimum with bounds of the size of the stresses (Newton's method on the equations
instead cycles between the points' active sets there; averaged relative to each point's own
``y``, ``x = q / y - 1``, the points near the apex swamped their neighbours' averages).

It is solved by projected Newton with conjugate gradients (the gradient-projection-CG family,
Moré & Toraldo, SIAM J. Optim. 1, 1991): the bounds that hold the gradient are kept, CG in the
inner product solves the Newton system on the other points to a tenth of its residual (to
``res / res_0`` once that is smaller), and the step along it, projected onto the bounds, is
halved until ``Q`` falls enough (Armijo). Each product with the Hessian is one average. The
residual is that of the equations [Pa]: ``|f - max(f_t - b <A f>^N, -y)|``.
"""

import math
from collections.abc import Callable

import numpy as np
from mpi4py import MPI

__all__ = ["solve_overstress"]


def solve_overstress(
    average: Callable[[np.ndarray], np.ndarray],
    metric: np.ndarray,
    f_t: np.ndarray,
    b: np.ndarray,
    N: np.ndarray,
    y: np.ndarray,
    f0: np.ndarray,
    comm: MPI.Comm,
    tol: float,
    max_newton: int = 50,
) -> tuple[np.ndarray, dict]:
    """The end states' overstress ``f = q - y`` [Pa] of the overstress law, ``shape=(n,)``.

    Args:
        average: the non-local average ``A`` (a callable on particle fields).
        metric: ``G`` (the volumes times the average's denominators), in which ``A`` is
            self-adjoint.
        f_t: the trial overstress ``q_trial - y`` [Pa].
        b: ``2 G c / y^N`` [Pa^(1 - N)], finite (read where ``y > 0``).
        N: the Perzyna exponents [-].
        y: the yield values of ``q`` [Pa]; ``<= 0``: at the apex, ``f = -y``.
        f0: the first guess [Pa].
        comm: the communicator the particles are spread over.
        tol: the tolerance on ``|f - max(f_t - b <A f>^N, -y)|`` [Pa].
        max_newton: most Newton iterations.

    Returns:
        ``(f, stats)``; ``stats`` counts ``newton`` and ``krylov`` (CG) iterations and says
        whether the tolerance was met (``converged``).

    """
    free = y > 0.0  # the points whose overstress is unknown
    lo, hi = -y, np.where(free, f_t, -y)
    b = np.where(free, b, 1.0)
    inv_N = 1.0 / N

    def total(v) -> float:
        return comm.allreduce(float(v), MPI.SUM)

    def inner(u, v) -> float:
        return total(np.sum(metric * u * v))

    def h(f):  # ((f_t - f) / b)^(1/N): what A f is where f is inside its bounds
        return np.where(free, (np.maximum(hi - f, 0.0) / b) ** inv_N, 0.0)

    def Q(f, z) -> float:
        tail = b**-inv_N * (N / (N + 1.0)) * np.maximum(hi - f, 0.0) ** ((N + 1.0) * inv_N)
        return 0.5 * inner(f, z) + total(np.sum(metric * np.where(free, tail, 0.0)))

    def residual(f, z) -> float:
        F = np.where(free, f - np.maximum(f_t - b * np.maximum(z, 0.0) ** N, lo), 0.0)
        return math.sqrt(total(F @ F))

    f = np.clip(f0, lo, hi)
    z = average(f)
    res = first = residual(f, z)
    stats = {"newton": 0, "krylov": 0, "converged": False}
    for _ in range(max_newton):
        if res <= tol:
            stats["converged"] = True
            break
        g = np.where(free, z - h(f), 0.0)  # the gradient of Q in the inner product
        face = free & ~(((f <= lo) & (g > 0.0)) | ((f >= hi) & (g < 0.0)))  # not held by a bound
        with np.errstate(divide="ignore", over="ignore"):
            curvature = np.where(face, (np.maximum(hi - f, 1e-300) / b) ** (inv_N - 1.0) / (N * b), 0.0)
        p, k = _cg(lambda v: np.where(face, average(v) + curvature * v, 0.0), np.where(face, -g, 0.0),
                   inner, rtol=min(0.1, res / first))  # fmt: skip
        stats["newton"] += 1
        stats["krylov"] += k
        q, t = Q(f, z), 1.0
        for _ in range(30):  # projected search, halved until Q falls enough
            f_new = np.clip(f + t * p, lo, hi)
            z_new = average(f_new)
            if Q(f_new, z_new) <= q + 1e-4 * inner(g, f_new - f):
                break
            t *= 0.5
        else:  # no decrease left: round-off
            break
        f, z = f_new, z_new
        res = residual(f, z)
    else:
        stats["converged"] = res <= tol
    return f, stats


def _cg(matvec, b, inner, rtol: float, maxiter: int = 100) -> tuple[np.ndarray, int]:
    """Conjugate gradients from 0 for ``H p = b`` in ``inner``, to ``rtol`` of ``|b|``: ``p``, iterations."""
    p, r = np.zeros_like(b), b.copy()
    d, rr = r.copy(), inner(r, r)
    stop = rtol**2 * rr
    for k in range(maxiter):
        if rr <= stop:
            return p, k
        Hd = matvec(d)
        alpha = rr / inner(d, Hd)
        p += alpha * d
        r -= alpha * Hd
        rr, rr_old = inner(r, r), rr
        d = r + (rr / rr_old) * d
    return p, maxiter
