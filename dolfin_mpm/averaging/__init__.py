"""Non-local averaging of particle fields over a radius (the paper's eqs. 2, 3 and 5)."""

from dolfin_mpm.averaging.nonlocal_average import WEIGHTS, NonlocalAverage

__all__ = ["WEIGHTS", "NonlocalAverage"]
