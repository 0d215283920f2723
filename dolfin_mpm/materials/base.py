"""The protocol every constitutive model implements, and the updates built from it.

A step splits into four parts, so that a non-local average can enter between them:

    trial = mat.trial(sigma, L, dt)              # elastic predictor, Jaumann rotation
    de = mat.increment(trial, state, dt)         # local plastic strain increment
    sigma = mat.stress(trial, de, de_nonlocal)   # end-of-step stress
    mat.record(state, de, de_nonlocal, dt)       # state arrays, in place

``de`` has one meaning for every material: the equivalent plastic (viscoplastic) strain
increment in the paper's norm, ``de = sqrt(3/2 de_p:de_p)`` of the deviatoric plastic strain,
so that a return along the trial deviator ends at ``q = q_trial - 2 G de``. The stress applies
``max(de, de_nonlocal)``, capped where ``q`` would turn negative. At an apex of a cone (the
stress-free point, or ``c cot(phi) I``) ``de = q_trial / 2G``. :meth:`Material.update` (the
explicit MPM) and :meth:`Material.small_strain_update` (the implicit FE solver, with
:meth:`Material.tangent`) are these parts in order.

Parameters are dataclass fields declared with :func:`dolfin_mpm.params.parameter`, checked
once here at construction.
"""

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from dolfin_mpm.params import check_fields

__all__ = ["Material", "Trial"]


@dataclass
class Trial:
    """Elastic predictor of one step (component-first arrays).

    A trial gives one stress: :meth:`Material.stress` may build the stress in its arrays (the
    elastic one does, to spare a copy of the deviator in every step).

    Attributes:
        p: pressure ``-tr(sigma)/3`` [Pa], ``shape=(n,)``.
        s: deviator [Pa], ``shape=(3, 3, n)``.
        q: equivalent stress ``sqrt(3/2 s:s)`` [Pa], ``shape=(n,)``.

    """

    p: np.ndarray
    s: np.ndarray
    q: np.ndarray


class Material(ABC):
    """A constitutive model: parameters fixed at construction, a vectorised stress update.

    Subclasses are frozen dataclasses whose ranged fields are validated here. Materials know
    nothing of meshes, DOLFINx or PETSc: arrays in, arrays out, particle axis first.
    """

    rho: float  # mass density [kg/m^3]
    #: Whether the material can flow plastically (its increments can be non-zero).
    plastic: ClassVar[bool] = False
    #: Critical density [kg/m^3] below which a point is apart and stress free (``None``: never;
    #: see :mod:`dolfin_mpm.materials.separation`).
    rho_c: float | None = None

    def __post_init__(self):
        check_fields(self)

    @abstractmethod
    def p_wave_speed(self) -> float:
        """Speed of elastic dilatational waves [m/s], for the explicit time step."""

    @abstractmethod
    def strain_energy_density(self, sigma: np.ndarray) -> np.ndarray:
        """Recoverable elastic energy per unit volume [J/m^3] at stress ``sigma``, ``shape=(n,)``."""

    def plastic_work_density(self, trial: Trial, sigma: np.ndarray) -> np.ndarray:
        """The step's (visco)plastic work per unit volume [J/m^3], ``shape=(n,)``.

        ``sigma : de_p`` with the plastic strain increment ``de_p = C^-1 (sigma_trial - sigma)``
        of the return (backward Euler), ``sigma`` [Pa] ``shape=(n, 3, 3)`` the stress the step
        ends with; read after :meth:`stress`. A material that does not give it has NaN: the
        energy balance does not know its dissipation.
        """
        return np.full(len(trial.q), np.nan)

    def state_fields(self) -> dict[str, tuple[int, ...]]:
        """Per-particle state arrays this material needs: name -> shape after the particle axis."""
        return {}

    # -- the four parts of a step ----------------------------------------------------------
    @abstractmethod
    def trial(self, sigma: np.ndarray, L: np.ndarray, dt: float) -> Trial:
        """Elastic predictor of the step, with the Jaumann rotation.

        Args:
            sigma: Cauchy stress at the start of the step [Pa], ``shape=(n, 3, 3)``.
            L: velocity gradient ``L_ij = dv_i/dx_j`` [1/s], ``shape=(n, gdim, gdim)``: rate of
                deformation ``d = sym L``, spin ``W = skew L`` (plane strain in 2D).
            dt: time step [s].

        """

    @abstractmethod
    def increment(self, trial: Trial, state: dict[str, np.ndarray], dt: float) -> np.ndarray:
        """Local equivalent plastic strain increment ``de`` [-] (paper's norm), ``shape=(n,)``.

        ``de >= 0`` and finite; ``state`` (start of the step) is read, not changed.
        """

    @abstractmethod
    def stress(self, trial: Trial, de: np.ndarray, de_nonlocal: np.ndarray | None = None) -> np.ndarray:
        """End-of-step stress [Pa], ``shape=(n, 3, 3)``, applying ``max(de, de_nonlocal)``."""

    @abstractmethod
    def record(
        self,
        state: dict[str, np.ndarray],
        de: np.ndarray,
        de_nonlocal: np.ndarray | None,
        dt: float,
        applied: np.ndarray | None = None,
    ) -> None:
        """Update ``state`` in place with the step's increments (``de_nonlocal=None``: ``de``).

        The accumulated strain takes ``applied``, the increment the stress applied (a
        non-local law's, :mod:`dolfin_mpm.averaging.law`); by default ``max(de, de_nonlocal)``,
        what the neighbours impose, also where :meth:`stress` caps it at the apex.
        """

    @abstractmethod
    def tangent(self, trial: Trial, de: np.ndarray, dt: float) -> np.ndarray:
        """Consistent tangent ``d sigma / d eps`` of the local step [Pa], Mandel, ``shape=(n, 6, 6)``."""

    # -- the updates built from them --------------------------------------------------------
    def update(self, sigma: np.ndarray, L: np.ndarray, dt: float, state: dict[str, np.ndarray]) -> np.ndarray:
        """Advance the stress over one explicit step (local: no non-local increment).

        Args:
            sigma: stress at the start of the step [Pa], ``shape=(n, 3, 3)``.
            L: velocity gradient [1/s], ``shape=(n, gdim, gdim)``.
            dt: time step [s].
            state: this material's state arrays, updated in place.

        Returns:
            The stress at the end of the step [Pa], ``shape=(n, 3, 3)``.

        """
        trial = self.trial(sigma, L, dt)
        de = self.increment(trial, state, dt)
        sigma = self.stress(trial, de)
        self.record(state, de, None, dt)
        return sigma

    def small_strain_update(
        self, sigma: np.ndarray, deps: np.ndarray, state: dict[str, np.ndarray], dt: float = 1.0
    ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        """Implicit small-strain step from ``sigma`` by the strain increment ``deps``.

        Args:
            sigma: converged stress [Pa], ``shape=(n, 3, 3)``.
            deps: strain increment [-], ``shape=(n, 3, 3)``.
            state: converged state arrays (every field of :meth:`state_fields`), not changed.
            dt: duration of the step [s]; matters only for rate-dependent materials.

        Returns:
            The stress [Pa] ``shape=(n, 3, 3)``, the consistent tangent (Mandel) [Pa]
            ``shape=(n, 6, 6)`` and the new state.

        """
        trial = self.trial(sigma, deps / dt, dt)
        de = self.increment(trial, state, dt)
        new = {k: np.array(v, dtype=np.float64, copy=True) for k, v in state.items()}
        self.record(new, de, None, dt)
        D = self.tangent(trial, de, dt)  # first: a trial gives one stress
        return self.stress(trial, de), D, new
