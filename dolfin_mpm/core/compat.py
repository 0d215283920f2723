"""The one place that knows which DOLFINx is installed.

Debian 12 ships DOLFINx 0.5.2; PyPI ships 0.11 (``dolfinx-solver-real``), whose wheels need
``import dolfinx_solver`` before ``dolfinx`` or ``petsc4py``. Every call whose name or
signature differs between the two lines is wrapped here; no other module touches a
version-specific name.
"""

try:  # The PyPI wheels load their MPI/PETSc libraries on this import.
    import dolfinx_solver  # noqa: F401
except ImportError:
    pass

import logging
import xml.etree.ElementTree as ET
from pathlib import Path

import basix
import dolfinx
import numpy as np
import ufl
from dolfinx import fem, geometry, la
from dolfinx import mesh as dmesh

__all__ = [
    "DOLFINX_VERSION",
    "bounding_box_tree",
    "candidate_cells",
    "cell_dofs",
    "evaluate",
    "function_space",
    "geometry_dofmap",
    "meshio_simplices",
    "quadrature_points",
    "quadrature_space",
    "read_mesh",
    "scalar_space",
    "scatter_reverse_add",
    "vector_space",
]

DOLFINX_VERSION: tuple[int, int] = tuple(int(v) for v in dolfinx.__version__.split(".")[:2])
_NEW = DOLFINX_VERSION >= (0, 8)


class _NoCompilerLines(logging.Filter):
    """Drops what distutils logs below a warning: ``running build_ext`` and the compiler's commands.

    Before DOLFINx 0.8 (the 0.5 line here), FFCx configures the root logger at import, and its C
    compiles through cffi log each step at INFO through distutils, which logs on the root logger
    itself: into the output of every script and run that compiles an element or a form.
    """

    def filter(self, record: logging.LogRecord) -> bool:
        return record.levelno >= logging.WARNING or "distutils" not in record.pathname


if not _NEW:
    logging.getLogger().addFilter(_NoCompilerLines())


def function_space(msh, family: str, degree: int, shape: tuple[int, ...] = ()) -> fem.FunctionSpace:
    """Space of ``family`` (e.g. ``"Lagrange"``, ``"DG"``) and ``degree``, values of ``shape``."""
    if _NEW:
        return fem.functionspace(msh, (family, degree, shape) if shape else (family, degree))
    if shape:
        return fem.VectorFunctionSpace(msh, (family, degree), dim=shape[0])
    return fem.FunctionSpace(msh, (family, degree))


def vector_space(msh) -> fem.FunctionSpace:
    """Vector-valued continuous P1 space on ``msh`` (block size = geometric dimension)."""
    return function_space(msh, "Lagrange", 1, (msh.geometry.dim,))


def scalar_space(msh) -> fem.FunctionSpace:
    """Scalar continuous P1 space on ``msh``."""
    return function_space(msh, "Lagrange", 1)


def quadrature_points(msh, degree: int) -> tuple[np.ndarray, np.ndarray]:
    """Reference points ``shape=(nq, tdim)`` and weights of the default rule of ``degree``.

    The points are in the order of :func:`quadrature_space`'s dofs.
    """
    cell = getattr(basix.CellType, msh.topology.cell_name())
    return basix.make_quadrature(cell, degree)


def quadrature_space(msh, degree: int, size: int) -> fem.FunctionSpace:
    """Vectors of ``size`` values at the points of :func:`quadrature_points` (``size`` >= 2)."""
    if _NEW:
        import basix.ufl

        element = basix.ufl.quadrature_element(
            msh.basix_cell(), value_shape=(size,), scheme="default", degree=degree
        )
        return fem.functionspace(msh, element)
    element = ufl.VectorElement("Quadrature", msh.ufl_cell(), degree=degree, dim=size, quad_scheme="default")
    return fem.FunctionSpace(msh, element)


def evaluate(expr: fem.Expression, msh, cells: np.ndarray) -> np.ndarray:
    """Values of ``expr`` at its points in ``cells``, ``shape=(num_cells, num_points, value_size)``."""
    cells = np.asarray(cells, dtype=np.int32)
    values = expr.eval(msh, cells) if _NEW else expr.eval(cells)
    return values.reshape(len(cells), expr.X().shape[0], -1)


def geometry_dofmap(msh) -> np.ndarray:
    """Geometry nodes of each cell, ``shape=(num_cells, nodes_per_cell)``."""
    if _NEW:
        return np.asarray(msh.geometry.dofmaps[0])
    dm = msh.geometry.dofmap
    return dm.array.reshape(len(dm.offsets) - 1, -1)


def cell_dofs(V) -> np.ndarray:
    """Block (node) dofs of each cell of ``V``, ``shape=(num_cells, dofs_per_cell)``."""
    dm = V.dofmap.list
    if _NEW:
        return np.asarray(dm)
    return dm.array.reshape(len(dm.offsets) - 1, -1)


def bounding_box_tree(msh):
    """Bounding-box tree of the cells of ``msh``."""
    tdim = msh.topology.dim
    if _NEW:
        return geometry.bb_tree(msh, tdim)
    return geometry.BoundingBoxTree(msh, tdim)


def candidate_cells(tree, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cells whose bounding box holds each point.

    Args:
        tree: tree from :func:`bounding_box_tree`.
        points: ``shape=(num_points, 3)``.

    Returns:
        ``(offsets, cells)``: the candidates of point ``i`` are ``cells[offsets[i]:offsets[i+1]]``.

    """
    points = np.ascontiguousarray(points, dtype=np.float64)
    if _NEW:
        adj = geometry.compute_collisions_points(tree, points)
    else:
        adj = geometry.compute_collisions(tree, points)
    return np.asarray(adj.offsets), np.asarray(adj.array)


def scatter_reverse_add(x) -> None:
    """Add ghost contributions of the DOLFINx vector ``x`` into their owners."""
    if _NEW:
        x.scatter_reverse(la.InsertMode.add)
    else:
        x.scatter_reverse(la.ScatterMode.add)


_MESHIO_CELLS = {2: ("triangle", "triangle"), 3: ("tetra", "tetrahedron")}  # gdim: meshio, DOLFINx


def read_mesh(comm, path, gdim: int):
    """A mesh of affine simplices from a file, partitioned over ``comm``.

    DOLFINx's own XDMF (``.xdmf``, the first uniform grid) is read by DOLFINx; any other
    format meshio reads (gmsh ``.msh``, VTK, ...) is read on rank 0 with meshio, keeping the
    cells of dimension ``gdim`` (triangles or tetrahedra) and the first ``gdim`` coordinates.

    Raises:
        ValueError: the file is not a mesh of its format, or holds no such cells.

    """
    path = Path(path)
    if path.suffix == ".xdmf":
        try:
            grids = ET.parse(path).getroot().iter("Grid")
        except ET.ParseError as e:
            raise ValueError(f"{path} is not an XDMF file ({e})") from None
        name = next((g.get("Name") for g in grids if g.get("GridType", "Uniform") == "Uniform"), "mesh")
        from dolfinx.io import XDMFFile

        with XDMFFile(comm, str(path), "r") as f:
            return f.read_mesh(name=name)
    meshio_name = _MESHIO_CELLS[gdim][0]
    cells, x = np.zeros((0, gdim + 1), np.int64), np.zeros((0, gdim))
    error = None
    if comm.rank == 0:
        import meshio

        try:
            m = meshio.read(path)
            if any(b.type == meshio_name for b in m.cells):
                cells, x, _ = meshio_simplices(m, gdim)
        except Exception as e:  # meshio's readers fail in many ways on a file that is not a mesh
            error = f"{path} is not a mesh file meshio reads ({type(e).__name__}: {e})"
    error = comm.bcast(error, root=0)  # every rank raises, or none
    if error:
        raise ValueError(error)
    if comm.bcast(len(cells) == 0, root=0):
        raise ValueError(f"{path}: no {meshio_name} cells for a mesh of dimension {gdim}")
    return create_mesh(comm, cells, x)


def meshio_simplices(m, gdim: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The triangles (tetrahedra) of a meshio mesh ``m``, as :func:`read_mesh` makes its mesh of them.

    Returns the cells (their blocks in order, ``(num_cells, gdim + 1)``), the points they use
    (``(num_points, gdim)``, in the file's order) and each file point's number among those
    (-1: a point only lower-dimensional cells use).
    """
    cells = np.concatenate([b.data for b in m.cells if b.type == _MESHIO_CELLS[gdim][0]]).astype(np.int64)
    if cells.min() < 0 or cells.max() >= len(m.points):
        raise ValueError(f"cells name points {cells.min()} to {cells.max()}, the file has {len(m.points)}")
    used = np.unique(cells)
    renumber = np.full(len(m.points), -1, dtype=np.int64)
    renumber[used] = np.arange(len(used))
    return renumber[cells], np.ascontiguousarray(m.points[used, :gdim], dtype=np.float64), renumber


def create_mesh(comm, cells: np.ndarray, x: np.ndarray, destinations=None):
    """A mesh of affine triangles or tetrahedra, partitioned over ``comm``.

    ``cells`` (``(num_cells, gdim + 1)`` vertex numbers) and ``x`` (``(num_vertices, gdim)``)
    may sit on one rank, the others passing empty arrays of those widths. DOLFINx partitions
    the cells, unless ``destinations`` (on the rank holding all cells; ``None`` on the others)
    gives each cell's ranks, owner first, as ``(data, offsets)`` (see
    :func:`dolfin_mpm.parallel.partition.destinations`).
    """
    gdim = x.shape[1]
    cell_name = _MESHIO_CELLS[gdim][1]
    cells, x = np.asarray(cells, dtype=np.int64), np.ascontiguousarray(x, dtype=np.float64)
    kwargs = {}
    if comm.allreduce(destinations is not None):
        from dolfinx.cpp.graph import AdjacencyList_int32

        data, offsets = destinations if destinations is not None else (np.zeros(0), np.zeros(1))
        ranks = AdjacencyList_int32(np.asarray(data, np.int32), np.asarray(offsets, np.int32))
        # The hook's arguments differ between the lines; the answer is the same.
        kwargs["partitioner"] = lambda *args: ranks
    if _NEW:
        import basix.ufl

        element = basix.ufl.element("Lagrange", cell_name, 1, shape=(gdim,))
        return dmesh.create_mesh(comm, cells, ufl.Mesh(element), x, **kwargs)
    domain = ufl.Mesh(ufl.VectorElement("Lagrange", cell_name, 1))
    return dmesh.create_mesh(comm, cells, x, domain, **kwargs)
