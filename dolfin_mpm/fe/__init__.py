"""Reference finite-element solver: small-strain, plane-strain, quasi-static elasto-plasticity."""

from dolfin_mpm.fe.solver import ConvergenceError, QuasiStatic, Step

__all__ = ["ConvergenceError", "QuasiStatic", "Step"]
