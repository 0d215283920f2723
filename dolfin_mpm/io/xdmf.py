"""XDMF/HDF5 time series of particles (moving point cloud) and grid fields, for ParaView.

Each write appends one time to HDF5 (flushed) and rewrites the small XDMF file atomically, so a
run that stops at any point leaves a valid, readable series. How the ranks' data reaches the
disk (:data:`LAYOUTS`):

- ``"gather"``: gathered to rank 0, which writes one ``.h5`` file (the default on one rank);
  rank 0 holds the whole output in memory while it writes.
- ``"collective"``: every rank writes its own rows of each dataset of one ``.h5`` file through
  MPI-IO (h5py built with MPI; the default under MPI where it is).
- ``"per-rank"``: every rank writes its own ``<name>-rank<r>.h5``, and each time of the XDMF
  file is a spatial collection of the ranks' pieces, which ParaView shows as one data set (the
  default under MPI where h5py is serial).

With the last two no rank holds more than its own share. The grid is then written as each
rank's owned cells and the nodes they use (a node on a partition boundary once per rank that
uses it) with a field ``node``, its number in the mesh's input; :func:`read` joins the pieces
of any layout and puts such a grid back in that order.
"""

import os
import xml.etree.ElementTree as ET
from pathlib import Path

import h5py
import numpy as np
from mpi4py import MPI

from dolfin_mpm.core import compat
from dolfin_mpm.io.disk import ensure_room, tree_bytes
from dolfin_mpm.materials.tensor import invariants

__all__ = ["LAYOUTS", "Output", "XDMFSeries", "default_layout", "particle_fields", "read", "times"]

_TYPES = {1: "Scalar", 3: "Vector", 9: "Tensor"}


#: How the ranks' data reaches the disk (see the module's docstring).
LAYOUTS = ("gather", "collective", "per-rank")


def default_layout(comm) -> str:
    """``"gather"`` on one rank; under MPI ``"collective"`` where h5py has MPI, else ``"per-rank"``."""
    if comm.size == 1:
        return "gather"
    return "collective" if h5py.get_config().mpi else "per-rank"


def check_layout(layout: str) -> str:
    """``layout`` if this h5py can write it, else a ``ValueError`` naming the choices."""
    if layout not in LAYOUTS:
        raise ValueError(f"output layout: {layout!r} is not one of {', '.join(LAYOUTS)}")
    if layout == "collective" and not h5py.get_config().mpi:
        raise ValueError(
            "output layout: 'collective' needs h5py built with MPI (this one is serial); "
            "use 'per-rank' or 'gather'"
        )
    return layout


class XDMFSeries:
    """A temporal collection of grids in one ``.xdmf`` file, its data in HDF5.

    Collective over ``comm``: every rank constructs it and calls :meth:`write` with its own
    piece (its points, cells and fields); rank 0 alone writes the XDMF text.

    Args:
        path: the ``.xdmf`` file; the data goes to the same name with ``.h5`` (``-rank<r>.h5``
            for the layout ``"per-rank"``).
        after: extend the series already there, keeping its times up to ``after`` [s] and
            dropping the later ones (a run resumed from a checkpoint at ``after`` writes them
            again); ``None``, or no series there: a new series.
        comm: the ranks (default: this process alone).
        layout: one of :data:`LAYOUTS`.

    """

    def __init__(self, path, after: float | None = None, *, comm=None, layout: str = "gather"):
        self.path = Path(path)
        self.comm = MPI.COMM_SELF if comm is None else comm
        self.layout = check_layout(layout)
        self.count = 0
        self.root = self.series = self.h5 = None
        rank = self.comm.rank
        if self.layout == "per-rank":
            self.h5_path = self.path.with_name(f"{self.path.stem}-rank{rank}.h5")
        else:
            self.h5_path = self.path.with_suffix(".h5")
        extend, error, meshes = False, None, set()
        if rank == 0:
            try:
                self.path.parent.mkdir(parents=True, exist_ok=True)
                extend = after is not None and self.path.exists()  # in any layout: the text names the files
                if extend:
                    self._read_xml(after)
                    meshes = self._mesh_groups()
                else:
                    self.root = ET.Element("Xdmf", Version="3.0")
                    domain = ET.SubElement(self.root, "Domain")
                    self.series = ET.SubElement(
                        domain, "Grid", Name="series", GridType="Collection", CollectionType="Temporal"
                    )
            except (OSError, ValueError, ET.ParseError) as e:  # a file that is not a series
                error = e
            except (AttributeError, IndexError, TypeError) as e:  # one with parts missing
                error = ValueError(f"{self.path}: not a series to extend ({type(e).__name__}: {e})")
        extend, self.count, error, meshes = self.comm.bcast((extend, self.count, error, meshes), root=0)
        if error is not None:  # on every rank: the others must not wait for rank 0
            raise error
        #: The static meshes' groups the series refers to (in any file) and those written here.
        self._meshes, self._written = meshes, set()
        error = None
        try:
            self._open("a" if extend else "w")
        except OSError as e:  # a data file that is not HDF5, or a folder not writable
            error = f"{self.h5_path}: {e}"
        errors = [e for e in self.comm.allgather(error) if e is not None]
        if errors:  # on every rank, whichever failed
            self.close()
            raise OSError(errors[0])

    def _open(self, mode: str) -> None:
        """Open the data file of this rank, if it has one; on extending, drop the later times' data."""
        if self.layout == "collective":
            self.h5 = h5py.File(self.h5_path, mode, driver="mpio", comm=self.comm)
        elif self.layout == "per-rank" or self.comm.rank == 0:
            self.h5 = h5py.File(self.h5_path, mode)
        if mode == "a" and self.h5 is not None:
            # the dropped times' data, and any a stopped write left beyond what the XDMF file lists
            for name in sorted(n for n in self.h5 if n.startswith("step") and int(n[4:]) >= self.count):
                del self.h5[name]

    def _read_xml(self, after: float) -> None:
        """The XDMF text of the series being extended, its times after ``after`` dropped (rank 0)."""
        self.root = ET.parse(self.path).getroot()
        self.series = self.root.find("Domain/Grid")
        if self.series is None or self.series.get("CollectionType") != "Temporal":
            raise ValueError(f"{self.path}: not a time series to extend")
        grids = list(self.series)
        keep = [g for g in grids if float(g.find("Time").get("Value")) <= after]
        if keep != grids[: len(keep)]:
            raise ValueError(f"{self.path}: its times are not in order")
        for g in grids[len(keep) :]:
            self.series.remove(g)
        self.count = len(keep)

    def _mesh_groups(self) -> set[str]:
        """The groups of the static meshes the listed times refer to, in any file (rank 0)."""
        groups = set()
        for item in self.series.iter("DataItem"):
            _, name = item.text.strip().split(":/")
            if name.startswith("mesh"):
                groups.add(name.split("/")[0])
        return groups

    def new_mesh_group(self) -> str:
        """A name for a static mesh no time of the series uses yet: ``mesh``, ``mesh1``, ... (collective)."""
        k = 0
        while (name := "mesh" if k == 0 else f"mesh{k}") in self._meshes:
            k += 1
        return name

    @property
    def last_time(self) -> float | None:
        """The series' last time [s], ``None`` while it is empty (on rank 0; ``None`` elsewhere)."""
        if self.series is None:
            return None
        grids = list(self.series)
        return float(grids[-1].find("Time").get("Value")) if grids else None

    def write(self, t: float, points, cells, cell_type: str, fields: dict[str, np.ndarray], mesh=None):
        """Append this rank's piece of the grid at time ``t`` (collective).

        Args:
            points: ``shape=(num_points, 3)``.
            cells: ``shape=(num_cells, nodes_per_cell)``, indices into this piece's ``points``.
            cell_type: XDMF topology type (``Polyvertex``, ``Triangle``, ``Tetrahedron``).
            fields: nodal data by name, ``shape=(num_points,)``, ``(num_points, 3)`` or ``(num_points, 9)``.
            mesh: the group of a static mesh (from :meth:`new_mesh_group`): points and cells
                are stored there the first time and referred to after (the caller keeps the
                same pieces under one name); ``None``: stored at every time.

        """
        k, comm = self.count, self.comm
        fields = {n: v.reshape(len(points), int(np.prod(v.shape[1:]))) for n, v in fields.items()}
        fields = {n: v if v.shape[1] > 1 else v[:, 0] for n, v in fields.items()}
        group = mesh or f"step{k}"
        arrays = {} if mesh in self._written else {f"{group}/x": points, f"{group}/cells": cells}
        if arrays and group in (self.h5 or ()):  # left by a time the series dropped
            del self.h5[group]
        arrays |= {f"step{k}/{name}": v for name, v in fields.items()}
        counts = np.array(comm.allgather((len(points), len(cells))), dtype=np.int64).reshape(-1, 2)
        self._ensure_room(arrays)
        if self.layout == "per-rank":
            for name, a in arrays.items():
                self.h5.create_dataset(name, data=a)
            pieces = [(f"{self.path.stem}-rank{j}.h5", n) for j, n in enumerate(counts) if n[0] > 0]
            pieces = pieces or [(f"{self.path.stem}-rank0.h5", counts[0])]  # all empty: rank 0's
        else:
            self._write_rows(arrays, counts)
            pieces = [(self.h5_path.name, counts.sum(axis=0))]
        if mesh is not None:
            self._meshes.add(mesh)
            self._written.add(mesh)
        self.count += 1
        if self.h5 is not None:
            self.h5.flush()
        comm.Barrier()  # every rank's data on disk before the XDMF text names it
        if comm.rank == 0:
            self._write_xml(t, k, group, pieces, cell_type, points.dtype, cells, fields)

    def _ensure_room(self, arrays: dict[str, np.ndarray]) -> None:
        """The disk's room for every rank's ``arrays`` and the XDMF text, checked on rank 0 for all."""
        total = self.comm.allreduce(tree_bytes(list(arrays.values())))
        error = None
        if self.comm.rank == 0:
            xml = self.path.stat().st_size if self.path.exists() else 0
            try:
                ensure_room(self.path.parent, total + 2 * xml)
            except OSError as e:
                error = e
        error = self.comm.bcast(error, root=0)
        if error is not None:
            raise error

    def _write_rows(self, arrays: dict[str, np.ndarray], counts: np.ndarray) -> None:
        """Each array as one dataset of every rank's rows in rank order (cells renumbered).

        ``"gather"``: sent to rank 0, which writes; ``"collective"``: each rank writes its rows.
        """
        comm, rank = self.comm, self.comm.rank
        first = np.concatenate([[0, 0], np.cumsum(counts, axis=0)[:-1].ravel()]).reshape(-1, 2)[rank]
        for name, a in arrays.items():
            row = first[1] if name.endswith("/cells") else first[0]
            if name.endswith("/cells"):
                a = (a + first[0]).astype(a.dtype)  # this piece's points start at row first[0]
            if self.layout == "gather":
                parts = comm.gather(a, root=0)
                if rank == 0:
                    self.h5.create_dataset(name, data=np.concatenate(parts))
                continue
            total = counts[:, 1 if name.endswith("/cells") else 0].sum()
            dset = self.h5.create_dataset(name, (total, *a.shape[1:]), dtype=a.dtype)
            if len(a):
                dset[row : row + len(a)] = a

    def _write_xml(self, t, k, group, pieces, cell_type, points, cells, fields) -> None:
        """The XDMF text with time ``t`` added, replaced atomically (rank 0)."""
        grid = ET.SubElement(self.series, "Grid", Name=f"t{k}", GridType="Uniform")
        ET.SubElement(grid, "Time", Value=repr(float(t)))
        if len(pieces) != 1:  # one piece per rank: a spatial collection, which ParaView shows as one
            grid.set("GridType", "Collection")
            grid.set("CollectionType", "Spatial")
        for file, (num_points, num_cells) in pieces:
            piece = grid if len(pieces) == 1 else ET.SubElement(grid, "Grid", Name=file, GridType="Uniform")
            topo = ET.SubElement(
                piece, "Topology", TopologyType=cell_type, NumberOfElements=str(num_cells),
                NodesPerElement=str(cells.shape[1]),
            )  # fmt: skip
            number = _NUMBERS[cells.dtype.kind]
            _item(topo, file, f"{group}/cells", (num_cells, cells.shape[1]), number, cells.dtype.itemsize)
            geom = ET.SubElement(piece, "Geometry", GeometryType="XYZ")
            _item(geom, file, f"{group}/x", (num_points, 3), "Float", points.itemsize)
            for name, values in fields.items():
                shape = (num_points, *values.shape[1:])
                width = values.shape[1] if values.ndim > 1 else 1
                attr = ET.SubElement(
                    piece, "Attribute", Name=name, AttributeType=_TYPES.get(width, "Matrix"), Center="Node"
                )
                _item(
                    attr, file, f"step{k}/{name}", shape, _NUMBERS[values.dtype.kind], values.dtype.itemsize
                )
        tmp = self.path.with_name(self.path.name + ".tmp")
        ET.ElementTree(self.root).write(tmp, xml_declaration=True, encoding="utf-8")
        os.replace(tmp, self.path)

    def close(self) -> None:
        if self.h5 is not None:
            self.h5.close()
            self.h5 = None


_NUMBERS = {"f": "Float", "i": "Int", "u": "UInt"}


def _item(parent, file: str, name: str, shape: tuple, number: str, precision: int) -> None:
    item = ET.SubElement(
        parent, "DataItem", Dimensions=" ".join(map(str, shape)), Format="HDF", NumberType=number,
        Precision=str(precision),
    )  # fmt: skip
    item.text = f"{file}:/{name}"


def particle_fields(P) -> dict[str, np.ndarray]:
    """The particle output of this rank's particles ``P``, each ``shape=(n, width)`` or ``(n,)``.

    Velocity (padded to 3), stress (9), p, q, mass, volume, id and every material state array.
    """
    p, q = invariants(P.sigma)
    fields = {
        "velocity": _pad3(P.v), "stress": P.sigma.reshape(-1, 9), "p": p, "q": q,
        "mass": P.mass, "volume": P.volume, "id": P.id.astype(np.float64),
    }  # fmt: skip
    # Explicit widths: a rank may hold no particles.
    fields.update({name: a.reshape(len(P), int(np.prod(a.shape[1:]))) for name, a in P.state.items()})
    return fields


def _gather(comm, a: np.ndarray) -> np.ndarray | None:
    parts = comm.gather(a, root=0)
    return np.concatenate(parts) if comm.rank == 0 else None


class Output:
    """Writes ``particles.xdmf`` and ``grid.xdmf`` in ``folder`` at each :meth:`write`.

    ``after`` [s]: extend the series in ``folder``, from their times up to ``after`` on (see
    :class:`XDMFSeries`): a run resumed from its checkpoint at ``after`` continues its files.
    ``layout``: one of :data:`LAYOUTS`, ``None`` for :func:`default_layout`.

    Particle fields: velocity, stress (full 3x3), p, q, mass, volume, id, and every material
    state array. Grid fields: mass, momentum, velocity, internal, external and contact force;
    with a layout of pieces also ``node``, the node's number in the mesh's input.
    """

    def __init__(self, folder, comm, after: float | None = None, layout: str | None = None):
        self.folder = Path(folder)
        self.comm = comm
        self.layout = check_layout(default_layout(comm) if layout is None else layout)
        self._mesh = None
        self.particles = self.grid = None
        try:
            self.particles = XDMFSeries(self.folder / "particles.xdmf", after, comm=comm, layout=self.layout)
            self.grid = XDMFSeries(self.folder / "grid.xdmf", after, comm=comm, layout=self.layout)
        except (OSError, ValueError) as e:  # a file that is not a series, or not writable
            if self.particles is not None:
                self.particles.close()
            raise OSError(str(e)) from None
        #: The time last written [s] (of the series extended, with ``after``).
        self.last_time: float | None = comm.bcast(self.particles.last_time, root=0)

    def write(self, solver) -> None:
        """Append the solver's current state (once per simulated time; collective)."""
        if solver.time == self.last_time:
            return
        self.last_time = solver.time
        P = solver.particles
        cells = np.arange(len(P), dtype=np.int32).reshape(-1, 1)
        self.particles.write(solver.time, P.x, cells, "Polyvertex", particle_fields(P))
        if self._mesh is None or self._mesh["grid"] is not solver.grid:  # a rebalance brings a new grid
            self._mesh = self._pieces(solver.grid) if self.layout != "gather" else self._gathered(solver.grid)
        m = self._mesh
        g = solver.grid
        fields = {"mass": self._values(m, g.mass, 1)[:, 0]}
        for f in (g.momentum, g.velocity, g.f_int, g.f_ext, g.f_contact):
            fields[f.name] = _pad3(self._values(m, f, g.gdim))
        if self.layout == "gather":  # on rank 0 in input order; the others send theirs and write none
            every = {name: _gather(self.comm, a) for name, a in fields.items()}
            fields = {n: every[n][m["order"]] if self.comm.rank == 0 else a[:0] for n, a in fields.items()}
        else:
            fields["node"] = m["node"]
        cell_type = "Triangle" if g.tdim == 2 else "Tetrahedron"
        self.grid.write(solver.time, m["x"], m["cells"], cell_type, fields, mesh=m["group"])

    def _gathered(self, grid) -> dict:
        """The whole mesh on rank 0, its nodes in input order (empty pieces elsewhere).

        The input numbering does not change with the partition: after a
        :meth:`~dolfin_mpm.explicit.solver.Solver.rebalance` the mesh written stays the same.
        """
        msh = grid.mesh
        geom_dofs = compat.geometry_dofmap(msh)
        # Values at geometry nodes (P1: geometry node i of a cell carries dof i of the cell).
        node_of_geom = np.empty(msh.geometry.x.shape[0], dtype=np.int64)
        node_of_geom[geom_dofs] = grid.cell_dofs
        owned = msh.geometry.index_map().size_local
        inputs = np.asarray(msh.geometry.input_global_indices, dtype=np.int64)
        cells = _gather(self.comm, inputs[geom_dofs[: grid.num_owned_cells]])
        ids = _gather(self.comm, inputs[:owned])
        x = _gather(self.comm, msh.geometry.x[:owned])
        # the same mesh on every partition: one group for the run (a new one on extending a series)
        group = self._mesh["group"] if self._mesh is not None else self.grid.new_mesh_group()
        mesh = {"grid": grid, "nodes": node_of_geom[:owned], "group": group, "scatter": False}
        if self.comm.rank != 0:
            return mesh | {"x": np.zeros((0, 3)), "cells": np.zeros((0, grid.tdim + 1), dtype=np.int64)}
        order = np.argsort(ids)
        return mesh | {"x": x[order], "cells": np.searchsorted(ids[order], cells), "order": order}

    def _pieces(self, grid) -> dict:
        """The piece of this rank: its owned cells and the nodes they use, each with its input number."""
        from dolfinx import fem

        used = grid.cell_dofs[: grid.num_owned_cells]
        nodes = np.unique(used)
        geometry_node = np.empty(grid.num_nodes, dtype=np.int64)  # P1: a dof sits on a geometry node
        geometry_node[grid.cell_dofs] = compat.geometry_dofmap(grid.mesh)
        x = grid.mesh.geometry.x[geometry_node[nodes]]
        return {
            "grid": grid, "nodes": nodes, "x": x, "node": grid.node_inputs()[nodes],
            "cells": np.searchsorted(nodes, used), "group": self.grid.new_mesh_group(), "scatter": True,
            "buffers": {1: fem.Function(grid.Q), grid.gdim: fem.Function(grid.V)},
        }  # fmt: skip

    @staticmethod
    def _values(mesh: dict, f, width: int) -> np.ndarray:
        """``f`` (``width`` values a node) at the piece's nodes, ``shape=(n, width)``.

        A piece's ghost nodes take their owners' values, through a copy: the solver's own
        arrays stay as they are.
        """
        grid = mesh["grid"]
        values = f.x.array.reshape(-1, width)
        if mesh["scatter"]:
            owned = values[: grid.num_owned_nodes].ravel()
            values = grid.refresh_ghosts(mesh["buffers"][width], owned).reshape(-1, width)
        return values[mesh["nodes"]]

    def close(self) -> None:
        self.particles.close()
        self.grid.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def times(path) -> list[float]:
    """The times [s] of a series this module wrote, in order: ``read(path, k)`` is at the k-th."""
    return [float(grid.find("Time").get("Value")) for grid in ET.parse(path).getroot().find("Domain/Grid")]


def read(path, index: int = -1) -> tuple[float, np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """One time of a series this module wrote, whatever its layout: ``(t, points, cells, fields)``.

    Every rank's piece joined in rank order (cells renumbered); a grid written in pieces is put
    back in its nodes' input order (the ``node`` field), each node once.
    """
    path = Path(path)
    grid = list(ET.parse(path).getroot().find("Domain/Grid"))[index]
    pieces = [grid] if grid.get("GridType") == "Uniform" else list(grid.findall("Grid"))

    def data(item) -> np.ndarray:
        file, name = item.text.strip().split(":/")
        with h5py.File(path.parent / file, "r") as h5:
            return h5[name][()]

    points, cells, fields, offset = [], [], {}, 0
    for piece in pieces:
        points.append(data(piece.find("Geometry/DataItem")))
        cells.append(data(piece.find("Topology/DataItem")) + offset)
        offset += len(points[-1])
        for attr in piece.findall("Attribute"):
            fields.setdefault(attr.get("Name"), []).append(data(attr.find("DataItem")))
    t = float(grid.find("Time").get("Value"))
    points, cells = np.concatenate(points), np.concatenate(cells)
    fields = {name: np.concatenate(parts) for name, parts in fields.items()}
    if "node" in fields:
        nodes, first = np.unique(fields["node"], return_index=True)
        cells = np.searchsorted(nodes, fields["node"])[cells]
        points, fields = points[first], {name: v[first] for name, v in fields.items()}
    return t, points, cells, fields


def _pad3(a: np.ndarray) -> np.ndarray:
    """Vectors of 1–3 components as 3-vectors (ParaView's Vector attribute)."""
    out = np.zeros((a.shape[0], 3))
    out[:, : a.shape[1]] = a
    return out
