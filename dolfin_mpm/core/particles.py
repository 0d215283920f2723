"""Material points as flat arrays (particle axis first), their move, and sinks that take them out."""

import ctypes
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from dolfin_mpm import native
from dolfin_mpm.materials.tensor import component_first, component_view, particle_first

__all__ = ["Particles", "Sink", "move"]

_REAL = native.array(np.float64)
_kernels = native.kernels(
    Path(__file__).with_suffix(".c"),
    {"move": (ctypes.c_int64, ctypes.c_int32, _REAL, _REAL, _REAL, _REAL, _REAL, native.array(np.int64))},
)


class Particles:
    """The time-varying state of all material points on this rank.

    Every per-particle quantity is one array whose first axis is the particle, so that
    particles can be added, removed or sent to another rank by fancy indexing alone.

    Attributes:
        x: positions [m], ``shape=(n, 3)`` (z = 0 in 2D, as DOLFINx stores points).
        v: velocities [m/s], ``shape=(n, gdim)``.
        mass: [kg] (per metre of depth in 2D), ``shape=(n,)``.
        volume: current volume [m^3] (m^2 in 2D), ``shape=(n,)``.
        sigma: Cauchy stress [Pa], ``shape=(n, 3, 3)`` (sigma_zz kept in plane strain).
        material: index into the solver's list of materials, ``shape=(n,)``.
        id: global particle number, fixed for the life of the particle, ``shape=(n,)``; -1
            until the solver numbers it (see :func:`dolfin_mpm.parallel.ids.number`).
        cell: local cell holding the particle, or -1 when unknown, ``shape=(n,)``.
        state: material state arrays by name, each with particle axis first.

    """

    _fields = ("x", "v", "mass", "volume", "sigma", "material", "id", "cell")

    def __init__(self, x, v, mass, volume, sigma=None, material=None, id=None, state=None):
        n = len(mass)
        self.x = np.ascontiguousarray(x, dtype=np.float64).reshape(n, 3)
        v = np.ascontiguousarray(v, dtype=np.float64)
        self.v = v if v.ndim == 2 else v.reshape(n, -1)  # (0, gdim) stays: a rank may hold none
        self.mass = np.ascontiguousarray(mass, dtype=np.float64)
        self.volume = np.ascontiguousarray(volume, dtype=np.float64)
        self.sigma = np.zeros((n, 3, 3)) if sigma is None else np.array(sigma, dtype=np.float64)
        self.material = np.zeros(n, np.int32) if material is None else np.asarray(material, np.int32)
        self.id = np.full(n, -1, dtype=np.int64) if id is None else np.array(id, np.int64)
        self.cell = np.full(n, -1, dtype=np.int32)
        self.state: dict[str, np.ndarray] = dict(state or {})

    def __len__(self) -> int:
        return self.mass.shape[0]

    @property
    def gdim(self) -> int:
        return self.v.shape[1]

    def arrays(self) -> Iterator[tuple[str, np.ndarray]]:
        """All per-particle arrays by name, state arrays as ``state/<name>``."""
        for name in self._fields:
            yield name, getattr(self, name)
        for name, a in self.state.items():
            yield f"state/{name}", a

    def ensure_state(self, fields: dict[str, tuple[int, ...]]) -> None:
        """Add, as zeros, the state arrays of ``fields`` (name -> trailing shape) not yet held."""
        for name, shape in fields.items():
            self.state.setdefault(name, np.zeros((len(self), *shape)))

    def _set(self, name: str, a: np.ndarray) -> None:
        if name.startswith("state/"):
            self.state[name[6:]] = a
        else:
            setattr(self, name, a)

    def keep(self, mask: np.ndarray) -> None:
        """Keep only the particles where ``mask`` is true (in place)."""
        index = np.flatnonzero(mask)  # once, not once per array
        for name, a in list(self.arrays()):
            self._set(name, _select(a, index))

    def take(self, index: np.ndarray) -> "Particles":
        """A new Particles holding copies of the selected particles."""
        out = Particles.__new__(Particles)
        out.state = {}
        for name, a in self.arrays():
            out._set(name, _select(a, index))
        return out

    def extend(self, other: "Particles") -> None:
        """Append the particles of ``other`` (same fields)."""
        for name, a in list(self.arrays()):
            b = dict(other.arrays())[name]
            if _component_first(a):
                self._set(name, particle_first(np.concatenate([component_first(a), component_first(b)], -1)))
            else:
                self._set(name, np.concatenate([a, b]))


def move(P: "Particles", dx: np.ndarray) -> bool:
    """Move the particles by ``dx`` [m] (``shape=(n, gdim)``), in place; whether they stayed sound.

    Sound: every stress, velocity and position finite and every volume > 0. One compiled pass
    over the arrays, in place of a pass for the move and one for each test; the stresses in
    either layout (the test does not care which component a value is).
    """
    n, gdim = dx.shape
    sigma = P.sigma if P.sigma.flags.c_contiguous else component_view(P.sigma)
    P.x = np.ascontiguousarray(P.x, dtype=np.float64)  # as it is (no copy)
    real = lambda a: np.ascontiguousarray(a, dtype=np.float64)  # noqa: E731
    bad = np.zeros(1, np.int64)
    _kernels().move(n, gdim, P.x, real(dx), real(P.v), real(sigma), real(P.volume), bad)
    return bad[0] == 0


def _component_first(a: np.ndarray) -> bool:
    """Whether ``a`` is a particle-first view of component-first memory (as the kernels write)."""
    return a.ndim > 1 and not a.flags.c_contiguous and component_view(a).flags.c_contiguous


def _select(a: np.ndarray, index: np.ndarray) -> np.ndarray:
    """A copy of the particles ``index`` (integers) of ``a``, in the memory layout of ``a``."""
    if _component_first(a):  # the kernels read it so: no transposed copy at each use
        return particle_first(np.take(component_first(a), index, axis=-1))  # (not [..., index]: transposed)
    return np.take(a, index, axis=0)


@dataclass
class Sink:
    """Takes particles out of the computation and records what they carried.

    Args:
        name: label used in reports.
        region: ``region(x) -> mask`` on positions ``x.shape=(3, n)``; particles inside are
            absorbed each step. ``None``: the sink only receives particles that left the grid.

    Attributes:
        mass: total absorbed mass [kg] (per metre in 2D).
        momentum: total absorbed momentum [kg m/s], ``shape=(gdim,)``.
        count: number of absorbed particles.
        energy: the kinetic, strain and potential energy [J] the absorbed particles carried
            (per metre in 2D), as the caller of :meth:`absorb` counts it.
        history: ``(time [s], cumulative mass [kg])`` after each step that absorbed something.

    """

    name: str
    region: Callable[[np.ndarray], np.ndarray] | None = None
    mass: float = 0.0
    momentum: np.ndarray = field(default_factory=lambda: np.zeros(0))
    count: int = 0
    energy: float = 0.0
    history: list[tuple[float, float]] = field(default_factory=list)

    def absorb(self, particles: Particles, mask: np.ndarray, time: float, energy: float = 0.0) -> None:
        """Record and remove the particles where ``mask`` is true, carrying ``energy`` [J]."""
        if self.momentum.size == 0:
            self.momentum = np.zeros(particles.gdim)
        if not np.any(mask):
            return
        m = particles.mass[mask]
        self.mass += float(m.sum())
        self.momentum += (m[:, None] * particles.v[mask]).sum(axis=0)
        self.count += int(mask.sum())
        self.energy += energy
        self.history.append((time, self.mass))
        particles.keep(~mask)
