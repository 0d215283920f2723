"""Compiled kernels: C sources shipped beside the modules that use them, loaded with ctypes.

A source is compiled once per machine with the C compiler that DOLFINx's own just-in-time
compilation needs anyway (``$CC``, default ``cc``), into a cache folder
(``$DOLFIN_MPM_CACHE_DIR``, else ``$XDG_CACHE_HOME/dolfin_mpm`` or ``~/.cache/dolfin_mpm``).
The library's name carries a hash of the source, compiler, flags and processor, so an edited
source is rebuilt; it is written under a temporary name and renamed, so MPI ranks that compile
at the same time never load a half-written file. The code is compiled for the processor it runs
on (``-march=native``, where the compiler takes it: the vectorised hypo-elastic predictor runs
three times faster in AVX2 than in the baseline's scalar code). No fast-math and no contraction into fused
multiply-adds: results are IEEE arithmetic, bit for bit the same on every processor and rank
(math functions only do not set ``errno``, so that a loop of square roots vectorises).
"""

import ctypes
import functools
import hashlib
import os
import platform
import shlex
import subprocess
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

__all__ = ["array", "cache_dir", "kernels", "load"]

FLAGS = ("-O3", "-std=c99", "-fno-math-errno", "-ffp-contract=off", "-fPIC", "-shared")
#: Tried first; dropped where the compiler refuses them.
NATIVE = ("-march=native",)


def cache_dir() -> Path:
    """The folder of the compiled libraries."""
    if "DOLFIN_MPM_CACHE_DIR" in os.environ:
        return Path(os.environ["DOLFIN_MPM_CACHE_DIR"])
    return Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "dolfin_mpm"


def load(source: Path, signatures: dict[str, tuple]) -> ctypes.CDLL:
    """The library compiled from the C file ``source``, its functions typed by ``signatures``.

    ``signatures`` maps each function name to its ctypes argument types (all return void).
    Raises ``RuntimeError`` with the compiler's output when compiling fails.
    """
    compiler = shlex.split(os.environ.get("CC", "cc"))
    text = source.read_bytes()
    key = hashlib.sha256(b"\0".join([text, *map(str.encode, [*compiler, *FLAGS, *NATIVE, _processor()])]))
    library = cache_dir() / f"{source.stem}-{key.hexdigest()[:16]}.so"
    if not library.exists():
        _compile(compiler, source, library)
    lib = ctypes.CDLL(str(library))
    for name, argtypes in signatures.items():
        getattr(lib, name).argtypes, getattr(lib, name).restype = argtypes, None
    return lib


def kernels(source: Path, signatures: dict[str, tuple]) -> Callable[[], ctypes.CDLL]:
    """A function returning :func:`load` ``(source, signatures)``, loaded on its first call only."""
    return functools.cache(functools.partial(load, source, signatures))


@functools.cache
def _processor() -> str:
    """What ``-march=native`` compiles for: the machine and, on Linux, the CPU's model and flags."""
    try:
        with open("/proc/cpuinfo") as f:
            lines = [line for line in f if line.startswith(("model name", "flags", "Features"))]
        return platform.machine() + "".join(sorted(set(lines)))
    except OSError:
        return f"{platform.machine()} {platform.processor()}"


def _compile(compiler: list[str], source: Path, library: Path) -> None:
    try:
        library.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(suffix=".so", dir=library.parent)
    except OSError as e:
        raise RuntimeError(
            f"cannot write the compiled kernels to {library.parent} ({e.strerror or e}); "
            "set DOLFIN_MPM_CACHE_DIR to a writable folder"
        ) from None
    os.close(fd)
    for flags in ([*FLAGS, *NATIVE], FLAGS):
        try:
            command = [*compiler, *flags, str(source), "-o", tmp, "-lm"]
            done = subprocess.run(command, capture_output=True, text=True)
        except FileNotFoundError as e:
            error = str(e)
            break
        error = done.stderr if done.returncode else None
        if error is None:
            break
    if error is None:
        os.replace(tmp, library)
    else:
        os.remove(tmp)
        what = f"compiling {source.name} with {' '.join(compiler)} failed"
        raise RuntimeError(f"{what} (set CC to a C compiler):\n{error}")


@functools.cache
def array(dtype) -> type:
    """The ctypes argument type of a C-contiguous numpy array of ``dtype``: passes its data pointer.

    Raises ``TypeError`` for anything else. (numpy's ``ndpointer`` checks the same at about three
    times the cost per array.)
    """
    dtype = np.dtype(dtype)

    class Array:
        @staticmethod
        def from_param(a):
            if not isinstance(a, np.ndarray) or a.dtype != dtype or not a.flags.c_contiguous:
                raise TypeError(f"need a C-contiguous numpy array of {dtype}, got {_describe(a)}")
            return ctypes.c_void_p(a.ctypes.data)

    Array.__name__ = f"Array[{dtype}]"
    return Array


def _describe(a) -> str:
    if isinstance(a, np.ndarray):
        return f"{'a C-contiguous' if a.flags.c_contiguous else 'a non-contiguous'} array of {a.dtype}"
    return type(a).__name__
