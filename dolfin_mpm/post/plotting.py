"""Headless matplotlib figures: created, laid out, saved and closed in one place."""

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

__all__ = ["figure"]


@contextmanager
def figure(path: Path, *, dpi: int = 120, tight: bool = True, **subplots) -> Iterator:
    """The axes of ``plt.subplots(**subplots)`` on the Agg backend (no display needed).

    On leaving the block the figure is laid out (``tight``), saved to ``path`` and closed; it
    is closed without saving if the block raises.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(**subplots)
    try:
        yield axes
        if tight:
            fig.tight_layout()
        fig.savefig(path, dpi=dpi)
    finally:
        plt.close(fig)
