"""The non-local average over all ranks: each rank sees copies of the other ranks' particles near its own.

:class:`Halo` gives each rank copies of the other ranks' particles within a margin of its
own; :class:`DistributedAverage` averages over them as a serial run would.

Everything here is collective over the communicator.
"""

import time

import numpy as np
from mpi4py import MPI

from dolfin_mpm.averaging.nonlocal_average import IdIndex

__all__ = ["DistributedAverage", "Halo", "over_ranks"]


def over_ranks(average, comm):
    """``average`` over the particles of all ranks of ``comm``: itself on one rank."""
    return average if comm.size == 1 else DistributedAverage(average, comm)


class DistributedAverage:
    """A :class:`~dolfin_mpm.averaging.nonlocal_average.NonlocalAverage` over all ranks' particles.

    Each :meth:`update` gathers the other ranks' particles of a :class:`Halo` of width
    ``radius + skin``; the average of this rank's particles then takes in their neighbours on
    other ranks, as a serial run would. The halo's set of particles is kept while no particle
    has moved more than half the skin since it was built and no particle has arrived on any
    rank since (a migrated particle's new neighbours may lie outside it); particles that leave
    only drop out of it. The pair list is rebuilt with it, on all ranks in the same step, so
    that no rank waits for another's rebuild; in between it only loses particles.
    """

    law = property(lambda self: self.average.law)

    def __init__(self, average, comm):
        self.average, self.comm = average, comm
        self.halo: Halo | None = None
        self.halo_builds = 0  #: halos built so far
        self.halo_seconds = 0.0  #: time spent building and exchanging halos [s]

    def update(self, x: np.ndarray, volume: np.ndarray, ids: np.ndarray) -> None:
        start = time.perf_counter()
        rebuild = self.halo is None or not self.halo.follow(x, ids, 0.5 * self.average.skin)
        if rebuild:
            self.halo = Halo(self.comm, x, ids, self.average.radius + self.average.skin)
            self.halo_builds += 1
        self.n = len(x)
        x, volume, ids = (np.concatenate([a, self.halo.gather(a)]) for a in (x, volume, ids))
        self.halo_seconds += time.perf_counter() - start
        self.average.update(x, volume, ids, rebuild=rebuild)

    def __call__(self, e: np.ndarray) -> np.ndarray:
        start = time.perf_counter()
        e = np.concatenate([e, self.halo.gather(e)])
        self.halo_seconds += time.perf_counter() - start
        return self.average(e)[: self.n]

    @property
    def metric(self) -> np.ndarray:
        """The wrapped average's metric of this rank's particles (its halo's left out)."""
        return self.average.metric[: self.n]

    @property
    def own_weight(self) -> np.ndarray:
        """The wrapped average's own weights of this rank's particles (its halo's left out)."""
        return self.average.own_weight[: self.n]

    def state(self) -> dict:
        """The wrapped average's :meth:`~NonlocalAverage.state`, and the halo's under ``"halo"``."""
        state = self.average.state()
        if state:
            state["halo"] = self.halo.state()
        return state

    def restore(self, state: dict) -> None:
        """Continue from :meth:`state`: the same halo and pair list, bit for bit."""
        state = dict(state)
        halo = state.pop("halo", None)
        self.halo = Halo.restored(self.comm, halo) if halo is not None else None
        self.average.restore(state)

    def __getattr__(self, name):
        # radius, skin, weight, rebuilds: the wrapped average's (its pair list is this rank's).
        return getattr(self.average, name)


class Halo:
    """Copies of the other ranks' particles within ``margin`` of this rank's particles.

    Space is cut into cubes of side ``margin``; each rank sends the particles in the cubes
    next to (or in) a cube another rank has particles in, a superset of those within
    ``margin`` of them. :meth:`gather` fetches any per-particle field for the halo, and
    :meth:`follow` keeps it for the particles of later steps.

    Args:
        comm: the communicator of the grid.
        x: this rank's particle positions, ``shape=(n, gdim)``.
        ids: their global numbers, ``shape=(n,)``.
        margin: distance [m] the halo must cover, > 0.

    """

    def __init__(self, comm, x: np.ndarray, ids: np.ndarray, margin: float):
        self.comm = comm
        gdim = x.shape[1]
        # Column by column: numpy is slow over the short rows of an (n, gdim) array.
        columns = [x[:, c] for c in range(gdim)]
        lo, hi = np.full(gdim, np.inf), np.full(gdim, -np.inf)
        comm.Allreduce(np.array([c.min(initial=np.inf) for c in columns]), lo, MPI.MIN)
        comm.Allreduce(np.array([c.max(initial=-np.inf) for c in columns]), hi, MPI.MAX)
        shape = np.floor((hi - lo) / margin).astype(np.int64) + 3  # one spare cube each side
        cube = tuple(np.floor((c - a) / margin).astype(np.int64) + 1 for c, a in zip(columns, lo))
        key = np.ravel_multi_index(cube, shape)
        # Sets of cubes as flags over all cubes (linear time) where there are at most 8 cubes
        # per particle, sorted keys otherwise (a sparse cloud).
        num_cubes = int(np.prod(shape))
        dense = num_cubes <= 8 * len(x)
        occupied = comm.allgather(np.flatnonzero(_flags(key, num_cubes)) if dense else np.unique(key))
        offsets = np.stack(np.meshgrid(*[[-1, 0, 1]] * gdim, indexing="ij"), -1).reshape(-1, gdim)
        send = []  # per rank: indices of the particles it gets
        for rank, keys in enumerate(occupied):
            if rank == comm.rank or keys.size == 0:
                send.append(np.zeros(0, dtype=np.intp))
                continue
            near = np.unravel_index(keys, shape)
            near = np.ravel_multi_index((np.stack(near, -1)[:, None, :] + offsets).reshape(-1, gdim).T, shape)
            is_near = _flags(near, num_cubes)[key] if dense else np.isin(key, near)
            send.append(np.flatnonzero(is_near))
        self._built(x, ids, send)

    def _built(self, x: np.ndarray, ids: np.ndarray, send: list[np.ndarray]) -> None:
        """Keep the build: particles ``x`` and ``ids`` of this rank, ``send`` the indices per rank."""
        self.x_built, self.ids_built, self.send_built = x.copy(), ids.copy(), send
        self._index_built = IdIndex(ids)
        self._ids, self._index, self.send = self.ids_built, None, send  # now: the build's particles

    def follow(self, x: np.ndarray, ids: np.ndarray, limit: float) -> bool:
        """Keep the halo for this rank's particles now, ``x`` and ``ids`` (collective).

        It holds if, on every rank, every particle was there at the build and none has moved
        more than ``limit`` [m] since; :meth:`gather` then sends the build's particles still
        present, in the build's order. Returns whether it holds.
        """
        index, arrived = self._index, False  # index: each particle's place at the build
        if not (ids is self._ids or np.array_equal(ids, self._ids)):
            index = self._index_built(ids)
            arrived = bool(np.any(index < 0))
        moved = 0.0
        if not arrived and len(ids):
            x_then = self.x_built if index is None else self.x_built[index]
            moved = max(np.max((x[:, c] - x_then[:, c]) ** 2) for c in range(x.shape[1]))
        if self.comm.allreduce(arrived or moved > limit**2, MPI.LOR):
            return False
        if index is not self._index:
            now = np.full(len(self.ids_built), -1, dtype=np.intp)
            now[index] = np.arange(len(ids))
            self.send = [i[i >= 0] for i in (now[s] for s in self.send_built)]
            self._ids, self._index = ids, index
        return True

    def state(self) -> dict[str, np.ndarray]:
        """The build: positions and ids of this rank's particles, and the indices sent to each rank."""
        return {
            "x_built": self.x_built,
            "ids_built": self.ids_built,
            "send": np.concatenate(self.send_built),
            "send_counts": np.array([len(s) for s in self.send_built]),
        }

    @classmethod
    def restored(cls, comm, state: dict[str, np.ndarray]) -> "Halo":
        """The halo of :meth:`state`."""
        halo = cls.__new__(cls)
        halo.comm = comm
        send = np.split(np.asarray(state["send"], dtype=np.intp), np.cumsum(state["send_counts"])[:-1])
        halo._built(np.asarray(state["x_built"]), np.asarray(state["ids_built"]), send)
        return halo

    def gather(self, values: np.ndarray) -> np.ndarray:
        """The halo's copies of ``values`` (particle axis first), from all other ranks in turn."""
        received = self.comm.alltoall([values[s] for s in self.send])
        return np.concatenate(received) if received else values[:0]


def _flags(cubes: np.ndarray, num_cubes: int) -> np.ndarray:
    """The set ``cubes`` (cube numbers below ``num_cubes``) as flags, ``shape=(num_cubes,)``."""
    flags = np.zeros(num_cubes, dtype=bool)
    flags[cubes] = True
    return flags
