"""Sums and maxima over the ranks of the step's loop, on buffers: cheap on one rank and on many.

mpi4py's lower-case ``allreduce`` pickles its argument, a few to tens of microseconds a call
even on one rank, and the fixed-point loop makes several a step. These reduce float64 buffers
in place with MPI's own operations, and on one rank return at once.
"""

import numpy as np
from mpi4py import MPI

__all__ = ["max_over_ranks", "sum_over_ranks"]


def sum_over_ranks(comm, values) -> np.ndarray:
    """The elementwise sum over ``comm``'s ranks of ``values`` (numbers), a new float64 array."""
    out = np.array(values, dtype=np.float64)
    if comm.size > 1:
        comm.Allreduce(MPI.IN_PLACE, out, op=MPI.SUM)
    return out


def max_over_ranks(comm, value: float) -> float:
    """The largest of ``value`` over ``comm``'s ranks."""
    if comm.size == 1:
        return float(value)
    out = np.array([value], dtype=np.float64)
    comm.Allreduce(MPI.IN_PLACE, out, op=MPI.MAX)
    return float(out[0])
