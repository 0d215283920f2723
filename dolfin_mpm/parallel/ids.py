"""Global particle numbers: unique over all ranks, fixed for the life of a particle."""

import numpy as np
from mpi4py import MPI

from dolfin_mpm.core.particles import Particles

__all__ = ["number"]


def number(comm, particles: Particles) -> None:
    """Give every particle without a number (``id < 0``) one, after the largest in use (collective).

    New numbers follow rank order and, on a rank, the particles' order. Raises ``ValueError``
    on every rank when numbers already given repeat (on one rank or across ranks).
    """
    ids = particles.id
    given = ids[ids >= 0]
    counts = comm.allgather(len(given))
    duplicated = len(np.unique(given)) < len(given)
    if comm.size > 1 and sum(counts) and not comm.allreduce(duplicated, MPI.LOR):
        duplicated = len(np.unique(np.concatenate(comm.allgather(given)))) < sum(counts)
    if comm.allreduce(duplicated, MPI.LOR):
        raise ValueError("particles.id: numbers given to particles repeat; leave them -1 to be numbered")
    first = comm.allreduce(int(given.max(initial=-1)), MPI.MAX) + 1
    new = ids < 0
    offset = comm.exscan(int(new.sum())) or 0
    ids[new] = first + offset + np.arange(new.sum(), dtype=np.int64)
