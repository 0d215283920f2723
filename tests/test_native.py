import ctypes
import os
import shutil
import subprocess
import sys
import zipfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest

from dolfin_mpm import native


def test_compiled_once_into_the_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("DOLFIN_MPM_CACHE_DIR", str(tmp_path / "cache"))
    source = tmp_path / "twice.c"
    source.write_text("void twice(long n, double *v) { for (long k = 0; k < n; ++k) v[k] *= 2.0; }\n")
    signature = {"twice": (ctypes.c_long, native.array(np.float64))}
    lib = native.load(source, signature)
    v = np.arange(3.0)
    lib.twice(3, v)
    (library,) = (tmp_path / "cache").glob("twice-*.so")
    built = library.stat().st_mtime_ns
    native.load(source, signature).twice(3, v)
    assert np.array_equal(v, [0.0, 4.0, 8.0]) and library.stat().st_mtime_ns == built  # not rebuilt
    source.write_text(source.read_text().replace("2.0", "3.0"))  # an edited source is rebuilt
    native.load(source, signature).twice(3, v)
    assert np.array_equal(v, [0.0, 12.0, 24.0]) and len(list(library.parent.glob("twice-*.so"))) == 2
    for wrong in (np.arange(3), np.arange(6.0).reshape(2, 3).T, [0.0, 1.0, 2.0]):  # the types are checked
        with pytest.raises(ctypes.ArgumentError, match="C-contiguous numpy array of float64"):
            lib.twice(3, wrong)


@pytest.mark.parametrize("compiler", ["false", "no-such-compiler-anywhere"])
def test_a_failing_compiler_is_named(tmp_path, monkeypatch, compiler):
    monkeypatch.setenv("DOLFIN_MPM_CACHE_DIR", str(tmp_path))
    monkeypatch.setenv("CC", compiler)
    source = Path(native.__file__).parent / "averaging" / "nonlocal_average.c"
    with pytest.raises(RuntimeError, match=f"nonlocal_average.c with {compiler} failed.*set CC"):
        native.load(source, {})
    assert list(tmp_path.glob("*.so")) == []  # no half-written library left


def test_an_unwritable_cache_is_named(tmp_path, monkeypatch):
    blocked = tmp_path / "file"
    blocked.write_text("not a folder")
    monkeypatch.setenv("DOLFIN_MPM_CACHE_DIR", str(blocked / "cache"))
    source = tmp_path / "empty.c"
    source.write_text("void nothing(void) {}\n")
    with pytest.raises(
        RuntimeError, match=r"cannot write the compiled kernels to .*cache.*DOLFIN_MPM_CACHE_DIR"
    ):
        native.load(source, {"nothing": ()})


def test_a_compiler_refusing_native_code_builds_the_portable_one(tmp_path, monkeypatch):
    cc = tmp_path / "cc"  # a compiler that knows no -march=native
    cc.write_text('#!/bin/sh\nfor a in "$@"; do [ "$a" = -march=native ] && exit 1; done\nexec cc "$@"\n')
    cc.chmod(0o755)
    monkeypatch.setenv("DOLFIN_MPM_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setenv("CC", str(cc))
    source = tmp_path / "twice.c"
    source.write_text("void twice(long n, double *v) { for (long k = 0; k < n; ++k) v[k] *= 2.0; }\n")
    v = np.arange(3.0)
    native.load(source, {"twice": (ctypes.c_long, native.array(np.float64))}).twice(3, v)
    assert np.array_equal(v, [0.0, 2.0, 4.0])


def test_the_native_build_gives_the_portable_builds_bits(tmp_path, monkeypatch):
    """No contraction into fused multiply-adds: the vectorised predictor's results are the baseline's."""
    from dolfin_mpm.materials import elastic

    rng = np.random.default_rng(3)
    n = 1001  # not a multiple of the vector length: the loop's remainder too
    sigma = rng.normal(size=(3, 3, n))
    sigma = sigma + sigma.transpose(1, 0, 2)
    Ls = {gdim: rng.normal(size=(gdim, gdim, n)) for gdim in (2, 3)}
    results = []
    for flags in (native.NATIVE, ()):
        monkeypatch.setattr(native, "NATIVE", flags)
        monkeypatch.setenv("DOLFIN_MPM_CACHE_DIR", str(tmp_path / f"cache{len(flags)}"))
        lib = native.load(Path(elastic.__file__).with_name("hypoelastic.c"), elastic._SIGNATURES)
        for gdim in (2, 3):
            p, s, q = np.empty(n), np.empty((3, 3, n)), np.empty(n)
            lib.hypoelastic_trial(n, gdim, sigma, Ls[gdim], 1e-3, 2.0, 1.5, p, s, q)
            results.append(p.tobytes() + s.tobytes() + q.tobytes())
    assert results[0] == results[2] and results[1] == results[3]


@pytest.mark.parametrize("gdim", [2, 3])
def test_the_native_pair_weights_give_the_portable_builds_bits(tmp_path, monkeypatch, gdim):
    """The weights pass in eight lanes (where the processor has AVX-512) keeps and weighs the
    scalar pass's pairs, bit for bit, for every weight, and fills the output to its last place."""
    from dolfin_mpm.averaging import nonlocal_average as na

    rng = np.random.default_rng(5)
    x = rng.uniform(0.0, 1.0, size=(700, gdim))
    x[::97] = np.inf  # dead slots: their pairs dropped
    radius = 0.12
    pairs = na._search(np.where(np.isfinite(x), x, 0.0), 1.25 * radius)
    runs, m = len(pairs.row), len(pairs.j)
    results = {}
    for flags in (native.NATIVE, ()):
        monkeypatch.setattr(native, "NATIVE", flags)
        monkeypatch.setenv("DOLFIN_MPM_CACHE_DIR", str(tmp_path / f"cache{len(flags)}"))
        lib = native.load(Path(na.__file__).with_suffix(".c"), na._SIGNATURES)
        for kind in na.WEIGHTS.values():
            near = None
            for capacity in (m, None):  # room for all; then exactly as many as are kept
                capacity = near if capacity is None else capacity
                row, begin = np.empty(runs, np.int32), np.zeros(runs + 1, np.int64)
                j, w, counts = np.empty(capacity, np.int32), np.empty(capacity), np.zeros(2, np.int64)
                lib.pair_weights(
                    runs, pairs.row, pairs.begin, pairs.j, gdim, x, 1.0 / radius, kind, capacity,
                    row, begin, j, w, counts,
                )  # fmt: skip
                near = int(counts[1])
                assert near <= capacity
                kept = (counts, row[: counts[0]], begin[: counts[0] + 1], j[:near], w[:near])
                results[len(flags), kind, capacity == m] = [a.tobytes() for a in kept]
    assert 0 < near < m
    for key in [k for k in results if k[0] > 0]:
        assert results[key] == results[(0, *key[1:])]


def test_one_process_compiles_while_the_others_wait(tmp_path, monkeypatch):
    """Ranks that miss the cache at once: one compiles, the others load its library."""
    log = tmp_path / "compiled"
    cc = tmp_path / "cc"  # a compiler that records each call and takes its time
    cc.write_text(f'#!/bin/sh\necho x >> {log}\nsleep 0.3\nexec cc "$@"\n')
    cc.chmod(0o755)
    monkeypatch.setenv("DOLFIN_MPM_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setenv("CC", str(cc))
    source = tmp_path / "twice.c"
    source.write_text("void twice(long n, double *v) { for (long k = 0; k < n; ++k) v[k] *= 2.0; }\n")
    with ThreadPoolExecutor(4) as pool:
        libraries = set(pool.map(lambda _: native.library(source), range(4)))
    assert len(libraries) == 1 and log.read_text().count("x") == 1
    assert [p.name for p in (tmp_path / "cache").glob("*.so")] == [libraries.pop().name]


@pytest.fixture(scope="module")
def wheel(tmp_path_factory):
    """The package built as a wheel, and unpacked as pip would install it."""
    folder, root = tmp_path_factory.mktemp("wheel"), Path(native.__file__).parents[1]
    source = folder / "source"  # a copy: building writes into the source tree
    shutil.copytree(root / "dolfin_mpm", source / "dolfin_mpm", ignore=shutil.ignore_patterns("__pycache__"))
    for name in ("setup.py", "pyproject.toml", "README.md", "LICENSE"):
        shutil.copy(root / name, source)
    build = [sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation", "-w", folder]
    subprocess.run([*build, str(source)], check=True, capture_output=True, cwd=folder)
    (path,) = folder.glob("*.whl")
    with zipfile.ZipFile(path) as z:
        z.extractall(folder / "site")
    return path, folder / "site"


def test_the_wheel_carries_the_kernels_for_its_platform(wheel):
    path, site = wheel
    assert path.name.startswith("dolfin_mpm-") and path.name.split("-")[2:4] == ["py3", "none"]
    sources = sorted((site / "dolfin_mpm").glob("*/*.c"))
    libraries = sorted(p.name for p in (site / "dolfin_mpm" / "_kernels").glob("*.so"))
    assert len(sources) >= 5
    assert sorted(s.stem for s in sources for _ in range(2)) == [name.rsplit("-", 1)[0] for name in libraries]


def test_an_installed_wheel_needs_no_compiler(wheel, tmp_path):
    """No compiler and no writable cache: the wheel's own libraries are loaded, for this processor."""
    _, site = wheel
    blocked = tmp_path / "file"
    blocked.write_text("not a folder")
    env = {**os.environ, "PYTHONPATH": str(site), "CC": "false", "DOLFIN_MPM_CACHE_DIR": str(blocked / "c")}
    script = (
        "import numpy as np, dolfin_mpm\n"
        "from dolfin_mpm import native\n"
        "from dolfin_mpm.materials import LinearElastic\n"
        "m = LinearElastic(E=1e6, nu=0.3, rho=1e3)\n"
        "print(dolfin_mpm.__file__)\n"
        "print(native.library(native.PACKAGED.parent / 'materials' / 'hypoelastic.c'))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", script], env=env, capture_output=True, text=True, cwd=tmp_path
    )
    assert done.returncode == 0, done.stderr
    package, library = map(Path, done.stdout.split())
    assert package.is_relative_to(site) and library.parent == site / "dolfin_mpm" / "_kernels"
    source = site / "dolfin_mpm" / "materials" / "hypoelastic.c"
    assert library.name == native._name(source, source.read_bytes(), (*native.FLAGS, *native.NATIVE))


def test_the_processor_key_names_instruction_sets_not_mitigations():
    """A kernel or microcode update adds flags such as md_clear: the native libraries still match."""
    cpuinfo = "processor\t: 0\nmodel name\t: Some CPU\nflags\t\t: fpu sse2 avx2 fma constant_tsc{}\n"
    key = native.processor_of(cpuinfo.format(""))
    assert native.processor_of(cpuinfo.format(" md_clear ibpb hypervisor")) == key
    assert "avx2" in key and "constant_tsc" not in key
    assert native.processor_of(cpuinfo.format(" avx512f")) != key  # an instruction set more
    assert native.processor_of(cpuinfo.replace("Some CPU", "Other CPU").format("")) != key
