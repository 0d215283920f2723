"""Room on the disk, checked before an HDF5 file is written.

HDF5 that meets a full disk halfway through a write leaves the file's objects open with
unwritten metadata; the interpreter then ends in a segmentation fault at exit, when HDF5 tries
to flush them once more. A write that would not fit is refused before it starts instead, with
``ENOSPC`` naming the folder, so the files written so far stay readable and the run ends
cleanly.
"""

import errno
import shutil
from pathlib import Path

import numpy as np

__all__ = ["SPARE", "ensure_room", "tree_bytes"]

#: What a write needs beyond its data [bytes]: HDF5's metadata and the XDMF text.
SPARE = 1 << 20


def tree_bytes(tree) -> int:
    """The bytes of the arrays in ``tree`` (an array, or dicts and lists of them)."""
    if isinstance(tree, dict):
        return sum(tree_bytes(v) for v in tree.values())
    if isinstance(tree, (list, tuple)):
        return sum(tree_bytes(v) for v in tree)
    return int(np.asarray(tree).nbytes)


def ensure_room(folder, nbytes: int) -> None:
    """Raise ``OSError(ENOSPC)`` unless ``folder``'s disk has ``nbytes + SPARE`` bytes free."""
    folder = Path(folder)
    free = shutil.disk_usage(folder).free
    if free < nbytes + SPARE:
        raise OSError(
            errno.ENOSPC,
            f"No space left on device: {free} bytes free in {folder}, the write needs {nbytes + SPARE}",
        )
