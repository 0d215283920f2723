"""How the averaged quantity enters each point's viscoplastic return: the non-local laws.

Each point has its trial state ``(p, q_trial)`` and its own (local) law, the backward-Euler
increment ``u = c Phi(x)`` of its end state (``c = 3/2 gamma dt``, ``x`` the relative
overstress). The laws differ in what is averaged (``A``: the average over the radius r) and
in how it acts:

- ``"max"``: ``q = q_trial - 2 G max(u, A u)`` with ``u`` the purely local increment.
  Neighbours drag a point into flow; the band's core follows its local law.
- ``"paper"``: the stress is relaxed by the averaged rate, ``q = q_trial - 2 G d``,
  ``d = A u``, and each ``u`` is the rate of its point's own end state (eq. 5 read with the
  end-of-step stresses): ``u_i = c Phi(x_i(q_trial,i - 2 G d_i))``.
- ``"overstress"``: the averaged variable is inside the overstress function,
  ``d_i = c Phi(A x)_i``, ``q_i = q_trial,i - 2 G d_i`` (a non-local yield rule, Strömberg &
  Ristinmaa 1996); ``x = q / y - 1`` is signed, so points below the cone lower their
  neighbours' overstress, and is 0 at the apex (``y <= 0``, where a point is stress free).

The last two couple every point to its neighbours through its end state. Written with the
non-local part as a correction ``dq`` of the trial ``q`` [Pa] that the point's own return
takes, each is one local return per point:

    paper:       u = return(q_trial + dq),  d = u - dq / 2G,  dq = -2 G (A u - u)
    overstress:  d = return(q_trial + dq),                    dq = y (A x - x)

(``return`` is the material's backward-Euler increment with the trial ``q`` replaced, the
local law when ``dq = 0``). The step's fixed-point loop iterates ``dq`` together with the
internal forces, with the same Anderson acceleration, until both stop changing: the
averaged rate then equals the average of the rates the end states give, to the loop's
tolerance. The correction of a step starts the next one.

Why it converges, and only with a positive-definite weight: linearised about the flowing
points, one pass maps an error ``e`` of ``dq`` to ``(I - A) B e`` for both laws, with
``B = diag(a / (1 + a))``, ``a = 3 G gamma dt / y`` (0 where a point stays elastic). The
eigenvalues of ``A`` lie in ``[lambda_min, 1]``, so those of the pass lie in
``[0, (1 - lambda_min) max a / (1 + a))``: below 1 if ``lambda_min >= 0``. Smooth fields
(``A e = e``) are corrected at once, fields that alternate from point to point contract by
``a / (1 + a)`` a pass, which the acceleration takes care of. With the cubic, Gaussian or
constant weight ``lambda_min < 0`` (-0.04, -0.03, -0.33 on a lattice of spacing r/2), and
where ``a`` is large (near free surfaces ``y = m p -> 0``; ``a`` ~ 30 in the silo's fill) the
pass grows those fields: the silo on h = 5 mm with the cubic weight left 1584 of 4576 steps
unconverged. Wendland's weight is positive definite (``lambda_min > 0``), and the laws take it
alone (:data:`dolfin_mpm.averaging.nonlocal_average.WEIGHTS`). Its ``lambda_min`` falls towards
0 as r spans more particles (0.20, 0.026, 0.005 at 2, 3, 4 spacings), and the contraction
approaches 1: with r of 4 spacings (r = 10 mm on the silo's 5 mm mesh) the loop stalls on the
changes of the active set and leaves steps unconverged (807 of 4576; ``docs/numerics.md``).

The over-non-local mix ``d = m A u + (1 - m) u``, ``m > 1`` (Vermeer & Brinkgreve 1994), is
not among them: written the same way its iteration stalls at a relative change of 1e-2,
because where the mix is negative ``d`` must be 0 and the end state is then the trial, whose
rate the corrected return does not give.
"""

from dataclasses import dataclass

import numpy as np

__all__ = ["LAWS", "NonlocalLaw"]

#: The laws and what each averages: the rate (``max``, ``paper``) or the relative overstress
#: (``overstress``).
LAWS = ("max", "paper", "overstress")


@dataclass(frozen=True)
class NonlocalLaw:
    """A non-local law, see the module's description.

    Args:
        name: one of :data:`LAWS`.

    """

    name: str = "max"

    def __post_init__(self):
        if self.name not in LAWS:
            raise ValueError(f"law must be one of {list(LAWS)}, got {self.name!r}")

    @property
    def iterative(self) -> bool:
        """Whether the law couples the end states (all but ``"max"``): the loop iterates it."""
        return self.name != "max"

    def applied(self, u: np.ndarray, dq: np.ndarray, two_G: np.ndarray) -> np.ndarray:
        """The increment the stress applies [-] from the returns ``u`` of the corrected trials.

        All ``shape=(n,)``; ``dq`` [Pa], ``two_G`` = 2 G of each point [Pa]. Kept >= 0: a
        viscoplastic multiplier cannot be negative; the fixed point ``d = A u`` is >= 0, only
        an iterate on the way may not be.
        """
        if self.name == "overstress":
            return u
        return np.maximum(u - dq / two_G, 0.0)

    def correction(self, average, u, d, q_trial, two_G, y) -> np.ndarray:
        """The next correction ``dq`` [Pa] of the trial ``q``, ``shape=(n,)``.

        Args:
            average: the non-local average ``A`` (a callable on particle fields).
            u: the returns of the corrected trials [-] (each point's own rate times dt).
            d: the applied increments [-].
            q_trial: the trial ``q`` [Pa].
            two_G: 2 G of each point [Pa].
            y: the yield value of ``q`` of each point [Pa] (``<= 0`` at the apex); only the
                ``"overstress"`` law reads it.

        """
        if self.name == "overstress":
            q = np.maximum(q_trial - two_G * d, 0.0)
            x = np.divide(q, y, out=np.ones_like(q), where=y > 0.0) - 1.0  # 0 at the apex
            return np.where(y > 0.0, y * (average(x) - x), 0.0)
        return -two_G * (average(u) - u)
