"""XDMF/HDF5 time series of particles (moving point cloud) and grid fields, for ParaView.

Each write appends one time to an HDF5 file (flushed) and rewrites the small XDMF file
atomically, so a run that stops at any point leaves a valid, readable series. Data from all
ranks is gathered to rank 0, which alone writes.
"""

import os
import xml.etree.ElementTree as ET
from pathlib import Path

import h5py
import numpy as np

from dolfin_mpm.core import compat
from dolfin_mpm.io.disk import ensure_room, tree_bytes
from dolfin_mpm.materials.tensor import invariants

__all__ = ["Output", "XDMFSeries", "particle_fields"]

_TYPES = {1: "Scalar", 3: "Vector", 9: "Tensor"}


class XDMFSeries:
    """A temporal collection of grids in one ``.xdmf`` + ``.h5`` pair.

    Args:
        path: the ``.xdmf`` file; the data goes to the same name with ``.h5``.
        after: extend the series already there, keeping its times up to ``after`` [s] and
            dropping the later ones (a run resumed from a checkpoint at ``after`` writes them
            again); ``None``, or no series there: a new series.

    """

    def __init__(self, path, after: float | None = None):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.h5_path = self.path.with_suffix(".h5")
        self.count = 0
        if after is not None and self.path.exists() and self.h5_path.exists():
            self._extend(after)
            return
        self.h5 = h5py.File(self.h5_path, "w")
        self.root = ET.Element("Xdmf", Version="3.0")
        domain = ET.SubElement(self.root, "Domain")
        self.series = ET.SubElement(
            domain, "Grid", Name="series", GridType="Collection", CollectionType="Temporal"
        )

    def _extend(self, after: float) -> None:
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
        self.h5 = h5py.File(self.h5_path, "a")
        # the dropped times' data, and any a stopped write left beyond what the XDMF file lists
        for name in [n for n in self.h5 if n.startswith("step") and int(n[4:]) >= len(keep)]:
            del self.h5[name]
        self.count = len(keep)

    @property
    def last_time(self) -> float | None:
        """The series' last time [s], ``None`` while it is empty."""
        grids = list(self.series)
        return float(grids[-1].find("Time").get("Value")) if grids else None

    def _item(self, parent, name: str, data: np.ndarray) -> None:
        if name not in self.h5:
            self.h5.create_dataset(name, data=data)
        number = {"float64": "Float", "float32": "Float", "int32": "Int", "int64": "Int"}[data.dtype.name]
        item = ET.SubElement(
            parent, "DataItem", Dimensions=" ".join(map(str, data.shape)), Format="HDF",
            NumberType=number, Precision=str(data.dtype.itemsize),
        )  # fmt: skip
        item.text = f"{self.h5_path.name}:/{name}"

    def write(
        self, t: float, points, cells, cell_type: str, fields: dict[str, np.ndarray], static_mesh=False
    ):
        """Append the grid at time ``t``.

        Args:
            points: ``shape=(num_points, 3)``.
            cells: ``shape=(num_cells, nodes_per_cell)``.
            cell_type: XDMF topology type (``Polyvertex``, ``Triangle``, ``Tetrahedron``).
            fields: nodal data by name, ``shape=(num_points,)``, ``(num_points, 3)`` or ``(num_points, 9)``.
            static_mesh: store points and cells once and refer to them at every time.

        """
        k = self.count
        new = [] if static_mesh and k > 0 else [points, cells]
        xml = self.path.stat().st_size if self.path.exists() else 0
        ensure_room(self.path.parent, tree_bytes([*new, *fields.values()]) + 2 * xml)
        grid = ET.SubElement(self.series, "Grid", Name=f"t{k}", GridType="Uniform")
        ET.SubElement(grid, "Time", Value=repr(float(t)))
        mesh_group = "mesh" if static_mesh else f"step{k}"
        topo = ET.SubElement(
            grid, "Topology", TopologyType=cell_type, NumberOfElements=str(len(cells)),
            NodesPerElement=str(cells.shape[1]),
        )  # fmt: skip
        self._item(topo, f"{mesh_group}/cells", cells)
        geom = ET.SubElement(grid, "Geometry", GeometryType="XYZ")
        self._item(geom, f"{mesh_group}/x", points)
        for name, values in fields.items():
            values = values.reshape(len(points), int(np.prod(values.shape[1:])))
            attr = ET.SubElement(
                grid,
                "Attribute",
                Name=name,
                AttributeType=_TYPES.get(values.shape[1], "Matrix"),
                Center="Node",
            )
            self._item(attr, f"step{k}/{name}", values if values.shape[1] > 1 else values[:, 0])
        self.count += 1
        self.h5.flush()
        tmp = self.path.with_name(self.path.name + ".tmp")
        ET.ElementTree(self.root).write(tmp, xml_declaration=True, encoding="utf-8")
        os.replace(tmp, self.path)

    def close(self) -> None:
        self.h5.close()


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

    Particle fields: velocity, stress (full 3x3), p, q, mass, volume, id, and every material
    state array. Grid fields: mass, momentum, velocity, internal, external and contact force.
    """

    def __init__(self, folder, comm, after: float | None = None):
        self.folder = Path(folder)
        self.comm = comm
        self.particles = self.grid = None
        last = error = None
        self._mesh = None
        if comm.rank == 0:
            try:
                self.folder.mkdir(parents=True, exist_ok=True)
                self.particles = XDMFSeries(self.folder / "particles.xdmf", after)
                self.grid = XDMFSeries(self.folder / "grid.xdmf", after)
                last = self.particles.last_time
            except (OSError, ValueError, KeyError, ET.ParseError) as e:  # a file that is not a series
                error = str(e)
        last, error = comm.bcast((last, error), root=0)
        if error is not None:  # on every rank: the others must not wait for rank 0
            raise OSError(error)
        #: The time last written [s] (of the series extended, with ``after``).
        self.last_time: float | None = last

    def write(self, solver) -> None:
        """Append the solver's current state (once per simulated time)."""
        if solver.time == self.last_time:
            return
        self.last_time = solver.time
        P, comm = solver.particles, self.comm
        x = _gather(comm, P.x)
        fields = {name: _gather(comm, a) for name, a in particle_fields(P).items()}
        if comm.rank == 0:
            cells = np.arange(len(x), dtype=np.int32).reshape(-1, 1)
            self.particles.write(solver.time, x, cells, "Polyvertex", fields)
        self._write_grid(solver)

    def _grid_mesh(self, grid):
        """The static mesh, gathered: owned nodes' P1 dofs, and on rank 0 the mesh in input order.

        The nodes are numbered as in the mesh's input, which no partition changes: after a
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
        if self.comm.rank != 0:
            return grid, node_of_geom[:owned], None, None, None
        order = np.argsort(ids)
        return grid, node_of_geom[:owned], x[order], np.searchsorted(ids[order], cells), order

    def _write_grid(self, solver) -> None:
        grid = solver.grid
        if self._mesh is None or self._mesh[0] is not grid:  # a rebalance brings a new grid
            self._mesh = self._grid_mesh(grid)
        _, nodes, points, cells, order = self._mesh
        fields = {"mass": grid.mass.x.array[nodes]}
        for f in (grid.momentum, grid.velocity, grid.f_int, grid.f_ext, grid.f_contact):
            fields[f.name] = _pad3(f.x.array.reshape(-1, grid.gdim)[nodes])
        fields = {name: _gather(self.comm, a) for name, a in fields.items()}
        if self.comm.rank == 0:
            cell_type = "Triangle" if grid.tdim == 2 else "Tetrahedron"
            fields = {name: a[order] for name, a in fields.items()}
            self.grid.write(solver.time, points, cells, cell_type, fields, static_mesh=True)

    def close(self) -> None:
        if self.comm.rank == 0:
            self.particles.close()
            self.grid.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _pad3(a: np.ndarray) -> np.ndarray:
    """Vectors of 1–3 components as 3-vectors (ParaView's Vector attribute)."""
    out = np.zeros((a.shape[0], 3))
    out[:, : a.shape[1]] = a
    return out
