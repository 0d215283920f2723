"""gmsh physical groups of a mesh file on the grid: the cells and the nodes each tag names.

A gmsh ``.msh`` file tags its elements with physical groups (``gmsh:physical`` in meshio). Read
on rank 0 beside the mesh (:func:`dolfin_mpm.core.compat.read_mesh`), they are carried to each
rank's cells by DOLFINx's original cell numbers and to its nodes by the geometry's input
numbers, so that scenarios can name bodies and walls by tag.
"""

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from dolfin_mpm.core import compat
from dolfin_mpm.core.grid import Grid

__all__ = ["PhysicalGroups", "read_groups"]


@dataclass
class PhysicalGroups:
    """The physical groups of a mesh file on this rank's part of the grid.

    Attributes:
        cell_tags: each of the rank's cells' tag (owned first, then ghosts), -1 if it has none;
            ``shape=(num_cells,)``.
        node_tags: tag -> the rank's grid nodes on the lower-dimensional elements of that tag
            (lines in 2D; triangles, lines and points in 3D), ascending.
        names: tag -> the group's name where the file gives one, by dimension (``(dim, tag)``).
        cell_dim: the cells' dimension.

    """

    cell_tags: np.ndarray
    node_tags: dict[int, np.ndarray] = field(default_factory=dict)
    names: dict[tuple[int, int], str] = field(default_factory=dict)
    cell_dim: int = 2

    def describe(self) -> str:
        """The tags there are, by dimension, with their names: for error messages."""
        cells = sorted(set(np.unique(self.cell_tags[self.cell_tags >= 0]).tolist()))
        show = lambda dim, tags: ", ".join(  # noqa: E731
            f"{t} ({self.names[dim, t]})" if (dim, t) in self.names else str(t) for t in tags
        )
        return (
            f"cells of dimension {self.cell_dim}: {show(self.cell_dim, cells) or 'none'}; "
            f"lower-dimensional: {show(-1, sorted(self.node_tags)) or 'none'}"
        )


_MESHIO_FACETS = {2: ("line", "vertex"), 3: ("triangle", "line", "vertex")}


def read_groups(comm, path, grid: Grid) -> PhysicalGroups:
    """The physical groups of the mesh file ``path`` that ``grid``'s mesh was read from (collective).

    A file without them (or not a gmsh file) gives none: every cell untagged.
    """
    gdim, msh = grid.gdim, grid.mesh
    cell_tags, nodes_of, names = None, {}, {}
    if comm.rank == 0:
        cell_tags, nodes_of, names = _read(Path(path), gdim)
    cell_tags, nodes_of, names = comm.bcast((cell_tags, nodes_of, names), root=0)
    original = np.asarray(msh.topology.original_cell_index, dtype=np.int64)
    local = cell_tags[original] if len(cell_tags) else np.full(len(original), -1, dtype=np.int32)
    point_of = grid.node_inputs()  # each grid node's point in the file
    node_tags = {tag: np.flatnonzero(np.isin(point_of, points)) for tag, points in nodes_of.items()}
    # names of lower-dimensional groups under -1: a wall's tag is any of them
    names = {(gdim if dim == gdim else -1, tag): name for (dim, tag), name in names.items()}
    return PhysicalGroups(np.asarray(local, dtype=np.int32), node_tags, names, gdim)


def _read(path: Path, gdim: int) -> tuple[np.ndarray, dict, dict]:
    """On rank 0: the file's cells' tags, each lower-dimensional tag's points and the names."""
    if path.suffix == ".xdmf":
        return np.zeros(0, dtype=np.int32), {}, {}
    import meshio

    m = meshio.read(path)
    tags = m.cell_data.get("gmsh:physical")
    if tags is None:
        return np.zeros(0, dtype=np.int32), {}, {}
    _, _, renumber = compat.meshio_simplices(m, gdim)
    cell_name = {2: "triangle", 3: "tetra"}[gdim]
    cell_tags = np.concatenate([t for b, t in zip(m.cells, tags) if b.type == cell_name]).astype(np.int32)
    points = {}
    for b, t in zip(m.cells, tags):
        if b.type in _MESHIO_FACETS[gdim]:
            for tag in np.unique(t):
                on = renumber[b.data[t == tag].ravel()]
                points.setdefault(int(tag), []).append(on[on >= 0])
    points = {tag: np.unique(np.concatenate(p)) for tag, p in points.items()}
    names = {(int(dim), int(tag)): name for name, (tag, dim) in m.field_data.items()}
    return cell_tags, points, names
