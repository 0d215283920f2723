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
  ``d_i = c <(A f)_i / y_i>^N``, ``q_i = q_trial,i - 2 G d_i`` (a non-local yield rule,
  Strömberg & Ristinmaa 1996): the yield function ``f = q - y`` [Pa] of the end states is
  averaged and taken relative to the point's own yield value ``y``. ``f`` is signed, so points
  below the cone lower their neighbours' overstress; a point at the apex (``y <= 0``) is stress
  free, ``f = -y``. (Averaging the relative overstress ``q / y - 1`` instead let the points
  near a free surface, where ``y -> 0``, swamp their neighbours' averages.)
- ``"overnonlocal"``: the over-non-local mix ``d = m A u + (1 - m) u``, ``m > 1`` (Vermeer &
  Brinkgreve 1994), with each ``u`` the rate of its point's own end state, as in the paper's
  law (which is ``m = 1``). The complementarity problem is the paper's with ``B = m A +
  (1 - m) I`` in place of ``A``. ``B`` is a non-negative matrix, and so ``d >= 0``, only while
  every point's own weight ``m A_ii + 1 - m`` is positive, that is ``m < 1 / (1 - A_ii)``;
  beyond it a point's own rate lowers its own increment, and at the apex or near a free
  surface (where the viscous slope ``1 / a`` of its row vanishes) a point that its neighbours
  cannot bring to its cone has no rate that solves its row. ``A_ii``, a point's own share of
  its average, falls as r spans more points, so the admissible ``m`` tends to 1 as the mesh is
  refined at fixed r; one solution for every trial state needs ``m < 1 / (1 - lambda_min(A))``,
  tighter still, and falling as the flow disorders the points. The step stops, naming the
  point, where the own weight is not positive.

The last three couple every point to its neighbours through its end state, and each iterate of
the step's loop solves them by a Newton method (semismooth, projected) with the trial states
fixed; the loop then iterates the internal forces alone. The paper's law and the mix are
complementarity problems in the rates (:mod:`dolfin_mpm.averaging.complementarity`); the
overstress law is solved in the end states' overstress
(:mod:`dolfin_mpm.averaging.overstress`). All take a positive-definite weight: with it ``A`` is
a P-matrix, the paper's law has one solution and the overstress law's Newton systems are
invertible (for the mix it is necessary, not enough: see above). Wendland's weight is (the
least eigenvalue of the average on a lattice of spacing r/2 is +0.20; cubic -0.04, Gaussian
-0.03, constant -0.33), and the laws take it alone
(:data:`dolfin_mpm.averaging.nonlocal_average.WEIGHTS`).

The paper's and the overstress law were first iterated as a correction of the trial ``q``
together with the internal forces under the loop's Anderson acceleration. Linearised, one pass
maps an error ``e`` of the correction to ``(I - A) K e``, ``K = diag(a / (1 + a))``,
``a = 3 G gamma dt / y``: a contraction if ``A`` has no negative eigenvalue, but one that
approaches 1 where ``a`` is large and r spans many particles (``lambda_min`` of Wendland's
average is 0.20, 0.026, 0.005 at 2, 3, 4 spacings). It left steps unconverged: 807 of 4576
with the paper's law and r = 10 mm on the silo's 5 mm mesh, 109 of the shear band's with the
overstress law on h = 1 mm (``docs/numerics.md``).
"""

import math
from collections.abc import Callable
from dataclasses import dataclass
from numbers import Real

import numpy as np

from dolfin_mpm.params import Range

__all__ = ["LAWS", "MIX", "NonlocalLaw"]

#: The laws and what each averages: the rate (``max``, ``paper``, ``overnonlocal``) or the
#: overstress ``q - y`` [Pa] (``overstress``).
LAWS = ("max", "paper", "overstress", "overnonlocal")
#: The over-non-local factor ``m`` (``m = 1`` is the paper's law).
MIX = Range(1.0, math.inf)


@dataclass(frozen=True)
class NonlocalLaw:
    """A non-local law, see the module's description.

    Args:
        name: one of :data:`LAWS`.
        m: the factor of the over-non-local mix, in :data:`MIX`; that law's alone.

    """

    name: str = "max"
    m: float | None = None

    def __post_init__(self):
        if self.name not in LAWS:
            raise ValueError(f"law must be one of {list(LAWS)}, got {self.name!r}")
        if self.name == "overnonlocal":
            if self.m is None:
                raise ValueError(f"law 'overnonlocal' needs its factor m, which {MIX.describe()}")
            if not isinstance(self.m, Real) or isinstance(self.m, bool):
                raise ValueError(f"m must be a number, which {MIX.describe()}, got {self.m!r}")
            MIX.check("m", self.m)
            object.__setattr__(self, "m", float(self.m))
        elif self.m is not None:
            raise ValueError(f"m is the factor of law 'overnonlocal', not of {self.name!r}, got {self.m!r}")

    @property
    def iterative(self) -> bool:
        """Whether the law couples the end states (all but ``"max"``): the loop iterates it."""
        return self.name != "max"

    @property
    def rates(self) -> bool:
        """Whether the law is solved in the rates of the end states (``paper``, ``overnonlocal``)."""
        return self.name in ("paper", "overnonlocal")

    def applied(self, average: Callable[[np.ndarray], np.ndarray]) -> Callable[[np.ndarray], np.ndarray]:
        """The increments ``d = B u`` [-] the stresses take from the rates ``u``: ``A u`` or the mix."""
        if self.name != "overnonlocal":
            return average
        m = self.m
        return lambda u: m * average(u) + (1.0 - m) * u

    def own_weights(self, average) -> np.ndarray | None:
        """Each point's own weight in ``B``, ``m A_ii + 1 - m`` [-] (``shape=(n,)``); None: not a mix."""
        if self.name != "overnonlocal":
            return None
        return self.m * average.own_weight + 1.0 - self.m
