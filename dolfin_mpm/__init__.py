"""dolfin_mpm: the material point method for large-strain granular flow on DOLFINx.

Import this package before ``dolfinx`` or ``petsc4py``: with the PyPI build of DOLFINx its
libraries must be loaded first, which this import does. The names below are loaded when first
used, so that ``dolfin_mpm.materials`` (imported here) needs numpy alone.
"""

import importlib

try:  # The PyPI wheels load their MPI/PETSc libraries on this import.
    import dolfinx_solver  # noqa: F401
except ImportError:
    pass

from dolfin_mpm import materials  # numpy only
from dolfin_mpm.materials import *  # noqa: F403  (the constitutive models)

__version__ = "0.1.0"

#: Public name -> the module that defines it.
_PUBLIC = {
    "FixedBC": "dolfin_mpm.core.boundary",
    "FrictionalWall": "dolfin_mpm.core.boundary",
    "Grid": "dolfin_mpm.core.grid",
    "NonlocalAverage": "dolfin_mpm.averaging",
    "NonlocalLaw": "dolfin_mpm.averaging",
    "Output": "dolfin_mpm.io.xdmf",
    "Particles": "dolfin_mpm.core.particles",
    "RigidWall": "dolfin_mpm.core.walls",
    "SimulationError": "dolfin_mpm.explicit.solver",
    "Sink": "dolfin_mpm.core.particles",
    "SlipBC": "dolfin_mpm.core.boundary",
    "Solver": "dolfin_mpm.explicit.solver",
    "VelocityBC": "dolfin_mpm.core.boundary",
    "geostatic_stress": "dolfin_mpm.core.seeding",
    "seed": "dolfin_mpm.core.seeding",
}
_MODULES = {
    "compat": "dolfin_mpm.core.compat",
    "partition": "dolfin_mpm.parallel.partition",
    **{
        name: f"dolfin_mpm.{name}"
        for name in (
            "app",
            "averaging",
            "core",
            "explicit",
            "fe",
            "io",
            "native",
            "parallel",
            "params",
            "post",
        )
    },
}

__all__ = sorted([*_PUBLIC, *_MODULES, *materials.__all__])


def __getattr__(name: str):
    if name in _PUBLIC:
        value = getattr(importlib.import_module(_PUBLIC[name]), name)
    elif name in _MODULES:
        value = importlib.import_module(_MODULES[name])
    else:
        raise AttributeError(f"module 'dolfin_mpm' has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *__all__])
