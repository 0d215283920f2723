"""Building the package compiles its C kernels into ``dolfin_mpm/_kernels`` (see ``dolfin_mpm.native``).

The metadata are in ``pyproject.toml``. The kernels are plain shared libraries loaded with ctypes,
not Python extensions: a wheel is tagged for its platform only (``py3-none-<platform>``). An
editable install compiles nothing; its kernels are compiled on first use, into the cache.
"""

import importlib.util
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from setuptools import Distribution, setup
from setuptools.command.build_py import build_py

try:
    from setuptools.command.bdist_wheel import bdist_wheel
except ImportError:  # setuptools < 70.1
    from wheel.bdist_wheel import bdist_wheel


def _native():
    """``dolfin_mpm.native``, read without importing the package (which needs DOLFINx)."""
    spec = importlib.util.spec_from_file_location(
        "_native", Path(__file__).parent / "dolfin_mpm" / "native.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


class BuildWithKernels(build_py):
    """Copies the package, then compiles every C source of it (in parallel)."""

    def run(self):
        super().run()
        if getattr(self, "editable_mode", False):
            return
        native, package = _native(), Path(self.build_lib) / "dolfin_mpm"
        folder = package / native.PACKAGED.name
        folder.mkdir(exist_ok=True)
        for old in folder.glob("*.so"):
            old.unlink()
        with ThreadPoolExecutor() as pool:
            built = list(pool.map(lambda c: native.build(c, folder), sorted(package.rglob("*.c"))))
        print(f"compiled {sum(map(len, built))} kernel libraries into {folder}")


class WithLibraries(Distribution):
    """Installed where compiled code goes (platlib), though the libraries are not extension modules."""

    def has_ext_modules(self):
        return True


class PlatformWheel(bdist_wheel):
    """A wheel for the platform, any Python 3: the libraries load through ctypes, not the C API."""

    def get_tag(self):
        return ("py3", "none", super().get_tag()[2])


setup(distclass=WithLibraries, cmdclass={"build_py": BuildWithKernels, "bdist_wheel": PlatformWheel})
