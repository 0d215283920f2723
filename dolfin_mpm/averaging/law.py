"""How the averaged quantity enters each point's viscoplastic return: the non-local laws.

Each point has its trial state ``(p, q_trial)`` and its own (local) law, the backward-Euler
increment ``u = c Phi(x)`` of its end state (``c = 3/2 gamma dt``, ``x`` the relative
overstress). The laws differ in what is averaged (``A``: the average over the radius r) and
in how it acts:

- ``"max"``: ``q = q_trial - 2 G max(u, A u)`` with ``u`` the purely local increment.
  Neighbours drag a point into flow; the band's core follows its local law.
- ``"paper"``: the stress is relaxed by the averaged rate, ``q = q_trial - 2 G d``,
  ``d = A u``, and each ``u`` is the rate of its point's own end state (eq. 5 read with the
  end-of-step stresses): ``u_i = c Phi(x_i(q_trial,i - 2 G d_i))``. A point at its cone's
  apex is stress free (``d_i >= q_trial,i / 2G``) and takes the rate its neighbourhood needs.
- ``"overstress"``: the averaged variable is inside the overstress function,
  ``d_i = c Phi(A x)_i``, ``q_i = q_trial,i - 2 G d_i`` (a non-local yield rule, Strömberg &
  Ristinmaa 1996); ``x = q / y - 1`` is signed, so points below the cone lower their
  neighbours' overstress, and is 0 at the apex (``y <= 0``, where a point is stress free).

The last two couple every point to its neighbours through its end state. The paper's law is
a complementarity problem in the rates, solved in each iterate of the step's loop by
semismooth Newton (:mod:`dolfin_mpm.averaging.complementarity`); the loop then iterates the
internal forces alone. Both need a positive-definite weight: with it ``A`` is a P-matrix and
the paper's law has one solution. Wendland's weight is (the least eigenvalue of the average on
a lattice of spacing r/2 is +0.20; cubic -0.04, Gaussian -0.03, constant -0.33), and the laws
take it alone (:data:`dolfin_mpm.averaging.nonlocal_average.WEIGHTS`).

The overstress law is iterated as a correction ``dq`` of the trial ``q`` [Pa] that each
point's own return takes, ``d = return(q_trial + dq)``, ``dq = y (A x - x)`` (``return`` is the
material's backward-Euler increment with the trial ``q`` replaced), together with the internal
forces under the loop's Anderson acceleration. Linearised, one pass maps an error ``e`` of
``dq`` to ``(I - A) B e``, ``B = diag(a / (1 + a))``, ``a = 3 G gamma dt / y``: a contraction if
``A`` has no negative eigenvalue, but one that approaches 1 where ``a`` is large and r spans
many particles (``lambda_min`` of Wendland's average is 0.20, 0.026, 0.005 at 2, 3, 4
spacings). That is why the paper's law, iterated this way, left steps unconverged (807 of
4576 with r = 10 mm on the silo's 5 mm mesh; ``docs/numerics.md``) and is now solved directly.

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

    def correction(self, average, d, q_trial, two_G, y) -> np.ndarray:
        """The overstress law's next correction ``dq`` [Pa] of the trial ``q``, ``shape=(n,)``.

        Args:
            average: the non-local average ``A`` (a callable on particle fields).
            d: the applied increments [-], the returns of the corrected trials.
            q_trial: the trial ``q`` [Pa].
            two_G: 2 G of each point [Pa].
            y: the yield value of ``q`` of each point [Pa] (``<= 0`` at the apex).

        """
        q = np.maximum(q_trial - two_G * d, 0.0)
        x = np.divide(q, y, out=np.ones_like(q), where=y > 0.0) - 1.0  # 0 at the apex
        return np.where(y > 0.0, y * (average(x) - x), 0.0)
