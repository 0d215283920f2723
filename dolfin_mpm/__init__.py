"""dolfin_mpm: the material point method for large-strain granular flow on DOLFINx.

Import this package before ``dolfinx`` or ``petsc4py``: with the PyPI build of DOLFINx its
libraries must be loaded first (done in :mod:`dolfin_mpm.compat`).
"""

from dolfin_mpm import compat, partition
from dolfin_mpm.boundary import FixedBC, FrictionalWall, SlipBC, VelocityBC
from dolfin_mpm.grid import Grid
from dolfin_mpm.io import Output
from dolfin_mpm.materials import DruckerPragerViscoplastic, LinearElastic, MohrCoulombDruckerPrager, VonMises
from dolfin_mpm.nonlocal_average import NonlocalAverage
from dolfin_mpm.particles import Particles, Sink
from dolfin_mpm.seeding import geostatic_stress, seed
from dolfin_mpm.solver import SimulationError, Solver

__version__ = "0.1.0"

__all__ = [
    "DruckerPragerViscoplastic",
    "FixedBC",
    "FrictionalWall",
    "Grid",
    "LinearElastic",
    "MohrCoulombDruckerPrager",
    "NonlocalAverage",
    "Output",
    "Particles",
    "SimulationError",
    "Sink",
    "SlipBC",
    "Solver",
    "VelocityBC",
    "VonMises",
    "compat",
    "geostatic_stress",
    "partition",
    "seed",
]
