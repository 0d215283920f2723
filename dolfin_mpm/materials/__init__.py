"""Constitutive models: frozen parameters and a vectorised stress update, free of DOLFINx."""

from dolfin_mpm.materials.base import Material, check_range
from dolfin_mpm.materials.elastic import LinearElastic

__all__ = ["LinearElastic", "Material", "check_range"]
