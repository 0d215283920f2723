"""The ranks and their launcher: ranks that stop when ``mpirun`` dies, the launcher's signals.

Open MPI's ``mpirun`` starts its ranks in process groups of their own, so a ``SIGKILL`` of
``mpirun``'s group leaves them running until they notice the lost connection, about a second
later, and they may write in the run folder meanwhile. Each rank therefore asks the kernel to
kill it with its parent (Linux ``prctl(PR_SET_PDEATHSIG)``): what the last complete checkpoint
holds is what a resume continues from.

Signals reach the ranks as the launcher forwards them. MPICH's ``mpiexec`` forwards ``SIGINT``
and ``SIGTERM`` as they are, and exits with the ranks' status (130, 143). Open MPI's ``mpirun``
turns both into ``SIGTERM`` for every rank, kills the ranks 1 s later (its
``odls_base_sigkill_timeout``; give ``--mca odls_base_sigkill_timeout 60`` for runs whose
checkpoint takes longer), and exits with 1 itself. A checkpoint cut by that kill leaves the
previous one, as any kill does (it is written under a temporary name and renamed).

Not covered: ``mpirun -n 1`` (one rank looks like a serial run; setting the request there would
also kill a ``nohup`` run with its shell), and launchers that start ranks from a thread that
ends before them (the kernel sends the signal when the forking thread exits).
"""

import ctypes
import ctypes.util
import os
import signal
import sys

from mpi4py import MPI

__all__ = ["die_with_launcher", "launcher_note"]

_PR_SET_PDEATHSIG = 1


def die_with_launcher(comm) -> bool:
    """On Linux under a launcher (``comm.size > 1``), let the kernel kill this rank with its parent.

    Returns:
        Whether the request was made. A rank whose parent died while it was made stops at once.

    """
    if comm.size == 1 or not sys.platform.startswith("linux"):
        return False
    libc = ctypes.CDLL(ctypes.util.find_library("c"))
    parent = os.getppid()
    if libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) != 0:
        return False
    if os.getppid() != parent:  # the parent died before the request: it will never fire
        os.kill(os.getpid(), signal.SIGKILL)
    return True


def launcher_note(comm, signum: int) -> str:
    """What to add to "stopped by SIGTERM" when Open MPI's ``mpirun`` may have sent it for a Ctrl-C."""
    if comm.size > 1 and signum == signal.SIGTERM and "Open MPI" in MPI.Get_library_version():
        return " (Open MPI's mpirun sends SIGTERM for Ctrl-C too)"
    return ""
