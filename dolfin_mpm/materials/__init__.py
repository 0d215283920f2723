"""Constitutive models: frozen parameters and a vectorised stress update, free of DOLFINx."""

from dolfin_mpm.materials.base import Material, check_range
from dolfin_mpm.materials.drucker_prager import DruckerPragerViscoplastic
from dolfin_mpm.materials.elastic import LinearElastic
from dolfin_mpm.materials.mohr_coulomb_dp import MohrCoulombDruckerPrager
from dolfin_mpm.materials.von_mises import VonMises

__all__ = [
    "DruckerPragerViscoplastic",
    "LinearElastic",
    "Material",
    "MohrCoulombDruckerPrager",
    "VonMises",
    "check_range",
]
