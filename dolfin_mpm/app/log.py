"""The command line's messages: Python ``logging`` on rank 0 of the run's ranks.

Information goes to ``sys.stdout``, warnings and errors (``warning: ...``, ``error: ...``) to
``sys.stderr``, each stream as it is when the message is written. ``-q`` leaves warnings and
errors, ``-v`` adds the details (each checkpoint, the stage times and the fixed-point loop's
counts at the end). Other ranks say nothing.
"""

import logging
import sys

__all__ = ["LEVELS", "LOGGER", "configure"]

#: The logger of the command line; the library itself does not log.
LOGGER = logging.getLogger("dolfin_mpm")
#: The level of each verbosity: -1 (``-q``), 0, 1 (``-v``).
LEVELS = {-1: logging.WARNING, 0: logging.INFO, 1: logging.DEBUG}


class _Streams(logging.Handler):
    """Info and debug to stdout as they are; warnings and errors, prefixed, to stderr."""

    def emit(self, record: logging.LogRecord) -> None:
        message = self.format(record)
        if record.levelno >= logging.WARNING:
            message = f"{record.levelname.lower()}: {message}"
            stream = sys.stderr
        else:
            stream = sys.stdout
        print(message, file=stream, flush=True)


def configure(comm, verbosity: int = 0) -> None:
    """Messages at ``verbosity`` (-1, 0 or 1) on rank 0 of ``comm``, none on the other ranks."""
    LOGGER.handlers = [_Streams() if comm.rank == 0 else logging.NullHandler()]
    LOGGER.setLevel(LEVELS[max(-1, min(1, verbosity))])
    LOGGER.propagate = False
