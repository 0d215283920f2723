"""Non-local averaging of particle fields over a radius (the paper's eqs. 2, 3 and 5), and its laws."""

from dolfin_mpm.averaging.law import LAWS, NonlocalLaw
from dolfin_mpm.averaging.nonlocal_average import WEIGHTS, NonlocalAverage

__all__ = ["LAWS", "WEIGHTS", "NonlocalAverage", "NonlocalLaw"]
