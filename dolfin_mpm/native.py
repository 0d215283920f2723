"""Compiled kernels: C sources shipped beside the modules that use them, loaded with ctypes.

Building the package (a wheel, ``pip install .``) compiles every source into the package's
``_kernels`` folder twice: for a baseline processor of the platform, and for the processor that
builds it (``-march=native``, where the compiler takes it: the vectorised hypo-elastic predictor
runs three times faster in AVX2 than in the baseline's scalar code). At run time the library
built for this processor is loaded if the package has it, else the baseline one.

Where the package carries no library for a source (an editable install, an edited source), the
source is compiled on first use, for this processor, with ``$CC`` (default ``cc``, which
DOLFINx's own just-in-time compilation needs anyway) into a cache folder
(``$DOLFIN_MPM_CACHE_DIR``, else ``$XDG_CACHE_HOME/dolfin_mpm`` or ``~/.cache/dolfin_mpm``).
A library's name carries a hash of the source, flags and processor (and, in the cache, the
compiler), so an edited source is rebuilt. One process compiles while the others, e.g. the
other MPI ranks, wait on a lock file beside it; the library is written under a temporary name and renamed, so
no process ever loads a half-written file.

No fast-math and no contraction into fused multiply-adds: results are IEEE arithmetic, bit for
bit the same for either build, on every processor and rank (math functions only do not set
``errno``, so that a loop of square roots vectorises).
"""

import ctypes
import fcntl
import functools
import hashlib
import os
import platform
import shlex
import subprocess
import tempfile
from collections.abc import Callable
from pathlib import Path

__all__ = ["PACKAGED", "array", "build", "cache_dir", "kernels", "library", "load"]

FLAGS = ("-O3", "-std=c99", "-fno-math-errno", "-ffp-contract=off", "-fPIC", "-shared")
#: Tried first; dropped where the compiler refuses them.
NATIVE = ("-march=native",)
#: The libraries compiled when the package was built.
PACKAGED = Path(__file__).parent / "_kernels"


def cache_dir() -> Path:
    """The folder of the libraries compiled at run time."""
    if "DOLFIN_MPM_CACHE_DIR" in os.environ:
        return Path(os.environ["DOLFIN_MPM_CACHE_DIR"])
    return Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "dolfin_mpm"


def load(source: Path, signatures: dict[str, tuple]) -> ctypes.CDLL:
    """The library compiled from the C file ``source``, its functions typed by ``signatures``.

    ``signatures`` maps each function name to its ctypes argument types (all return void).
    Raises ``RuntimeError`` with the compiler's output when compiling fails.
    """
    lib = ctypes.CDLL(str(library(source)))
    for name, argtypes in signatures.items():
        getattr(lib, name).argtypes, getattr(lib, name).restype = argtypes, None
    return lib


def library(source: Path) -> Path:
    """The compiled library of ``source``: the package's, else the cache's (compiled if missing)."""
    text = source.read_bytes()
    for flags in ((*FLAGS, *NATIVE), FLAGS):
        packaged = PACKAGED / _name(source, text, flags)
        if packaged.exists():
            return packaged
    compiler = shlex.split(os.environ.get("CC", "cc"))
    cached = cache_dir() / _name(source, text, (*compiler, *FLAGS, *NATIVE))
    if not cached.exists():
        _compile_once(compiler, source, cached)
    return cached


def build(source: Path, folder: Path, compiler: list[str] | None = None) -> list[Path]:
    """Compile ``source`` into ``folder`` for the baseline processor and for this one.

    What building the package does; the second library is left out where the compiler refuses
    native code. Returns the libraries written. Raises ``RuntimeError`` when compiling fails.
    """
    compiler = compiler or shlex.split(os.environ.get("CC", "cc"))
    text, built = source.read_bytes(), []
    for flags in ((*FLAGS, *NATIVE), FLAGS):
        target = folder / _name(source, text, flags)
        error = _run(compiler, flags, source, target)
        if error is None:
            built.append(target)
        elif flags == FLAGS:
            raise RuntimeError(f"compiling {source.name} with {' '.join(compiler)} failed:\n{error}")
    return built


def kernels(source: Path, signatures: dict[str, tuple]) -> Callable[[], ctypes.CDLL]:
    """A function returning :func:`load` ``(source, signatures)``, loaded on its first call only."""
    return functools.cache(functools.partial(load, source, signatures))


def _name(source: Path, text: bytes, flags) -> str:
    """``<stem>-<hash>.so``: the hash of the source and the flags, and of the processor for native code."""
    parts = [*flags, _processor()] if NATIVE and NATIVE[0] in flags else list(flags)
    key = hashlib.sha256(b"\0".join([text, *map(str.encode, parts)]))
    return f"{source.stem}-{key.hexdigest()[:16]}.so"


#: The x86 flags of /proc/cpuinfo that name instruction sets (what ``-march=native`` may use), by
#: prefix; the others (mitigations, timers, virtualisation) change with the kernel and microcode.
ISA_FLAGS = (
    "3dnow", "abm", "adx", "aes", "amx", "avx", "bmi", "clflushopt", "clwb", "cx16", "cx8", "f16c", "fma",
    "fsgsbase", "gfni", "lahf", "lzcnt", "mmx", "movbe", "movdir", "pclmul", "popcnt", "prfchw", "rdpid",
    "rdrand", "rdseed", "sha", "sse", "ssse", "vaes", "vpclmul", "xop", "xsave",
)  # fmt: skip


@functools.cache
def _processor() -> str:
    """What ``-march=native`` compiles for: the machine and, on Linux, the CPU's instruction sets."""
    try:
        with open("/proc/cpuinfo") as f:
            return processor_of(f.read())
    except OSError:
        return f"{platform.machine()} {platform.processor()}"


def processor_of(cpuinfo: str) -> str:
    """The machine, the models and the instruction sets that the text of /proc/cpuinfo names.

    Of x86 ``flags`` lines only the :data:`ISA_FLAGS`; an aarch64 ``Features`` line whole.
    """
    found = set()
    for line in cpuinfo.splitlines():
        key, _, value = line.partition(":")
        key = key.strip()
        if key == "flags":
            found.add("flags: " + " ".join(sorted({f for f in value.split() if f.startswith(ISA_FLAGS)})))
        elif key in ("model name", "Features"):
            found.add(f"{key}: {value.strip()}")
    return "\n".join([platform.machine(), *sorted(found)])


def _compile_once(compiler: list[str], source: Path, library: Path) -> None:
    """Compile into the cache unless another process, holding the lock meanwhile, has done it.

    The lock file stays (removing it would let a late process lock a new file while an early
    one still holds the old). Where the file system refuses locks, every process compiles: the
    rename still keeps a half-written library from being loaded.
    """
    lock = library.with_name(f".{library.name}.lock")
    try:
        library.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(lock, os.O_RDONLY | os.O_CREAT, 0o644)
    except OSError as e:
        raise RuntimeError(
            f"cannot write the compiled kernels to {library.parent} ({e.strerror or e}); "
            "set DOLFIN_MPM_CACHE_DIR to a writable folder"
        ) from None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
        except OSError:
            pass
        if not library.exists():
            error = _run(compiler, (*FLAGS, *NATIVE), source, library)
            if error is not None:
                error = _run(compiler, FLAGS, source, library)
            if error is not None:
                what = f"compiling {source.name} with {' '.join(compiler)} failed"
                raise RuntimeError(f"{what} (set CC to a C compiler):\n{error}")
    finally:
        os.close(fd)  # and with it the lock


def _run(compiler: list[str], flags, source: Path, library: Path) -> str | None:
    """Compile ``source`` into ``library`` by way of a temporary file; the error, or None."""
    fd, tmp = tempfile.mkstemp(suffix=".so", dir=library.parent)
    os.close(fd)
    try:
        done = subprocess.run(
            [*compiler, *flags, str(source), "-o", tmp, "-lm"], capture_output=True, text=True
        )
        error = done.stderr if done.returncode else None
    except FileNotFoundError as e:
        error = str(e)
    if error is None:
        os.replace(tmp, library)
    else:
        os.remove(tmp)
    return error


@functools.cache
def array(dtype) -> type:
    """The ctypes argument type of a C-contiguous numpy array of ``dtype``: passes its data pointer.

    Raises ``TypeError`` for anything else. (numpy's ``ndpointer`` checks the same at about three
    times the cost per array; ``a.ctypes.data`` alone costs three times what a reference to the
    buffer does, and a step passes a few hundred arrays.)
    """
    import numpy as np  # here, so that building the package needs no numpy

    dtype = np.dtype(dtype)

    class Array:
        @staticmethod
        def from_param(a):
            if not isinstance(a, np.ndarray) or a.dtype != dtype or not a.flags.c_contiguous:
                raise TypeError(f"need a C-contiguous numpy array of {dtype}, got {_describe(a)}")
            try:  # a reference to the buffer's first byte: a third of the cost of a.ctypes.data
                return ctypes.byref(ctypes.c_char.from_buffer(a))
            except (TypeError, ValueError):  # read-only or empty
                return ctypes.c_void_p(a.ctypes.data)

    Array.__name__ = f"Array[{dtype}]"
    return Array


def _describe(a) -> str:
    import numpy as np

    if isinstance(a, np.ndarray):
        return f"{'a C-contiguous' if a.flags.c_contiguous else 'a non-contiguous'} array of {a.dtype}"
    return type(a).__name__
