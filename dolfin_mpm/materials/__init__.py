"""Constitutive models: frozen, range-checked parameters and a vectorised stress update.

Free of DOLFINx, PETSc and MPI: numpy and small compiled loops. Every model implements the
protocol of :class:`Material` (``trial -> increment -> stress -> record``, ``tangent``).
"""

from dolfin_mpm.materials.base import Material, Trial
from dolfin_mpm.materials.drucker_prager import DruckerPragerViscoplastic
from dolfin_mpm.materials.elastic import LinearElastic
from dolfin_mpm.materials.mohr_coulomb_dp import MohrCoulombDruckerPrager
from dolfin_mpm.materials.radial_return import RadialReturn
from dolfin_mpm.materials.von_mises import VonMises

__all__ = [
    "DruckerPragerViscoplastic",
    "LinearElastic",
    "Material",
    "MohrCoulombDruckerPrager",
    "RadialReturn",
    "Trial",
    "VonMises",
]
