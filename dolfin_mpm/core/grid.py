"""The background grid: a DOLFINx mesh, its P1 spaces and the nodal fields of one MPM step."""

import functools
from collections.abc import Callable

import numpy as np
from dolfinx import fem

from dolfin_mpm.core import compat

__all__ = ["Grid"]


class Grid:
    """Background mesh of affine simplices with lumped nodal fields in DOLFINx Functions.

    Nodal fields live in the degrees of freedom of a vector P1 space ``V`` (and a scalar P1
    space ``Q`` for the mass), indexed by *node* = block dof, owned nodes first, then ghosts.
    Each step they are assembled from particles with :meth:`assemble`, which sums ghost
    contributions into their owners and refreshes the ghosts (correct under MPI; on one rank,
    where there are no ghosts, it only copies).

    Attributes:
        mesh: the DOLFINx mesh (triangles in 2D, tetrahedra in 3D; ``gdim == tdim``).
        V, Q: vector and scalar P1 spaces.
        mass, momentum, f_ext, f_int, f_contact, velocity, acceleration: nodal Functions
            [kg, kg m/s, N, N, N, m/s, m/s^2] (per metre of depth in 2D).
        scratch, scratch_vector: a scalar and a vector nodal Function for other sums (the walls'
            shares of the mass, the aggregated nodes').
        cell_dofs: nodes of each cell, ``shape=(num_cells, gdim + 1)``.
        num_owned_cells: cells this rank owns; they come first, then the ghosts.
        cell_owner: rank owning each local cell, ``shape=(num_cells,)``.
        K: inverse Jacobian of each cell's affine map, ``shape=(tdim, gdim, num_cells)``.
        grad_N: P1 basis gradients in each cell [1/m], ``shape=(num_cells, gdim + 1, gdim)``
            (cell-first: the transfers read a cell's gradients from one cache line).
        node_x: node coordinates, ``shape=(num_nodes, 3)``.
        h_min: smallest cell height over the local cells [m].
        diameter: longest cell edge over the local cells [m].

    """

    def __init__(self, msh):
        self.mesh = msh
        self.comm = msh.comm
        self._serial = msh.comm.size == 1  # no ghosts: assembly needs no scatters
        self._comm_owner = msh  # DOLFINx frees a mesh's communicator with the mesh
        #: How a repartitioned mesh was dealt (:meth:`repartitioned`), ``None`` for the first.
        self.partition: tuple[np.ndarray, np.ndarray] | None = None
        self.gdim = msh.geometry.dim
        self.tdim = msh.topology.dim
        if self.gdim != self.tdim or self.tdim not in (2, 3):
            raise ValueError(
                f"mesh: need triangles in 2D or tetrahedra in 3D with gdim == tdim, "
                f"got tdim={self.tdim}, gdim={self.gdim}"
            )
        geom_dofs = compat.geometry_dofmap(msh)
        if geom_dofs.shape[1] != self.tdim + 1:
            raise ValueError(
                f"mesh: cells must be affine simplices ({self.tdim + 1} nodes), "
                f"got {geom_dofs.shape[1]} nodes per cell"
            )
        self.V = compat.vector_space(msh)
        self.Q = compat.scalar_space(msh)
        self.cell_dofs = compat.cell_dofs(self.V).astype(np.int64)
        if not np.array_equal(self.cell_dofs, compat.cell_dofs(self.Q)):
            raise RuntimeError("scalar and vector P1 dofmaps differ; nodal fields cannot share nodes")
        index_map = self.V.dofmap.index_map
        self.num_owned_nodes = index_map.size_local
        self.num_nodes = index_map.size_local + index_map.num_ghosts
        self.num_cells = self.cell_dofs.shape[0]
        cell_map = msh.topology.index_map(self.tdim)
        self.num_owned_cells = cell_map.size_local
        self.cell_owner = np.concatenate(
            [np.full(cell_map.size_local, self.comm.rank, dtype=np.int32), cell_map.owners.astype(np.int32)]
        )
        self.node_x = self.V.tabulate_dof_coordinates()[: self.num_nodes]

        self.mass = fem.Function(self.Q, name="mass")
        self.momentum = fem.Function(self.V, name="momentum")
        self.f_ext = fem.Function(self.V, name="f_ext")
        self.f_int = fem.Function(self.V, name="f_int")
        self.f_contact = fem.Function(self.V, name="f_contact")
        self.velocity = fem.Function(self.V, name="velocity")
        self.acceleration = fem.Function(self.V, name="acceleration")
        self.scratch = fem.Function(self.Q, name="scratch")  # assembly buffers of nodal sums
        self.scratch_vector = fem.Function(self.V, name="scratch_vector")

        # Affine map x = x0 + J xi per cell; barycentric gradients are constant in a cell.
        X = msh.geometry.x[geom_dofs, : self.gdim]  # (num_cells, gdim+1, gdim)
        x0 = X[:, 0, :]
        J = np.swapaxes(X[:, 1:, :] - X[:, :1, :], 1, 2)  # (num_cells, gdim, tdim)
        detJ = np.linalg.det(J)
        if np.any(np.abs(detJ) <= 0.0):
            raise ValueError("mesh: degenerate cell with zero volume")
        K = np.linalg.inv(J)  # xi = K (x - x0)
        grad_N = np.concatenate([-K.sum(axis=1, keepdims=True), K], axis=1)
        # Component-first copies: per-particle gathers from them read contiguous memory.
        self.K = np.ascontiguousarray(np.moveaxis(K, 0, -1))  # (tdim, gdim, num_cells)
        self.grad_N = np.ascontiguousarray(grad_N)  # (num_cells, gdim+1, gdim)
        self.x0_T = np.ascontiguousarray(x0.T)  # (gdim, num_cells)
        self.cell_dofs_T = np.ascontiguousarray(self.cell_dofs.T, dtype=np.int32)  # (gdim+1, num_cells)
        factorial = 2.0 if self.tdim == 2 else 6.0
        self.cell_volume = np.abs(detJ) / factorial
        facet_measure = _largest_facet_measure(X)
        self.cell_height = self.tdim * self.cell_volume / facet_measure
        self.h_min = float(self.cell_height.min()) if self.num_cells else np.inf
        edges = X[:, :, None, :] - X[:, None, :, :]  # (num_cells, d+1, d+1, gdim), d+1 small
        self.diameter = float(np.sqrt((edges**2).sum(axis=-1)).max()) if self.num_cells else 0.0
        self.tree = compat.bounding_box_tree(msh)

    def node_inputs(self) -> np.ndarray:
        """Each node's number in the mesh's input (a file's point), the same on every partition.

        ``shape=(num_nodes,)``; P1: a cell's geometry node i carries its dof i.
        """
        out = np.empty(self.num_nodes, dtype=np.int64)
        inputs = np.asarray(self.mesh.geometry.input_global_indices, dtype=np.int64)
        out[self.cell_dofs] = inputs[compat.geometry_dofmap(self.mesh)]
        return out

    def repartitioned(self, msh, partition: tuple[np.ndarray, np.ndarray]) -> "Grid":
        """The grid of ``msh``, this grid's mesh dealt to the ranks anew, on this grid's ``comm``.

        ``partition``: ``(cells, ranks)`` the mesh was created from, every cell's vertices by
        their input numbers and its rank, on rank 0 (empty arrays elsewhere); a checkpoint
        stores it to create the same mesh again. The communicator stays the one the run's
        other parts hold; its mesh (the run's first) is kept alive with the new grid, for
        DOLFINx frees a mesh's communicator with it.
        """
        grid = Grid(msh)
        grid.comm, grid._comm_owner, grid.partition = self.comm, self._comm_owner, partition
        return grid

    def assemble(self, u: fem.Function, values: np.ndarray) -> np.ndarray:
        """Set ``u`` from per-node local sums, add ghost sums into owners, refresh ghosts.

        Args:
            u: nodal Function of this grid.
            values: local sums, ``shape=(num_nodes,)`` or ``(num_nodes, gdim)``.

        Returns:
            The assembled nodal values as a view, same shape as ``values``.

        """
        x = u.x
        a = x.array
        a[:] = values.ravel()
        if not self._serial:
            compat.scatter_reverse_add(x)
            x.scatter_forward()
        return a.reshape(values.shape)

    def refresh_ghosts(self, u: fem.Function, owned: np.ndarray) -> np.ndarray:
        """Set the owned values of ``u`` to ``owned`` (flat) and its ghosts from their owners.

        Returns:
            All of ``u``'s values, a flat view.

        """
        x = u.x
        a = x.array
        a[: owned.size] = owned
        if not self._serial:
            x.scatter_forward()
        return a

    @functools.cached_property
    def grad_N_norms(self) -> np.ndarray:
        """``|grad N|`` of each cell's nodes [1/m], ``shape=(num_cells, gdim + 1)``."""
        return np.sqrt((self.grad_N**2).sum(axis=2))

    @functools.cached_property
    def node_neighbours(self) -> tuple[np.ndarray, np.ndarray]:
        """Each local node's neighbours through the local cells, CSR ``(indptr, indices)``, ascending."""
        dofs = self.cell_dofs
        k = dofs.shape[1]
        a, b = np.repeat(dofs, k, axis=1).ravel(), np.tile(dofs, (1, k)).ravel()  # a cell's node pairs
        pairs = np.unique(np.stack([a[a != b], b[a != b]], axis=1), axis=0)
        indptr = np.zeros(self.num_nodes + 1, dtype=np.int64)
        np.cumsum(np.bincount(pairs[:, 0], minlength=self.num_nodes), out=indptr[1:])
        return indptr, pairs[:, 1].copy()

    def nodes_where(self, predicate: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
        """Nodes whose coordinates satisfy ``predicate(x)``, ``x.shape=(3, num_points)``."""
        return fem.locate_dofs_geometrical(self.V, predicate).astype(np.int64)


def _largest_facet_measure(X: np.ndarray) -> np.ndarray:
    """Length (2D) or area (3D) of the largest facet of each simplex, ``X.shape=(n, d+1, d)``."""
    d = X.shape[2]
    measures = []
    for omit in range(d + 1):  # loop over the d+1 facets of a simplex, not over cells
        F = np.delete(X, omit, axis=1)
        edges = F[:, 1:, :] - F[:, :1, :]
        if d == 2:
            measures.append(np.linalg.norm(edges[:, 0], axis=1))
        else:
            measures.append(0.5 * np.linalg.norm(np.cross(edges[:, 0], edges[:, 1]), axis=1))
    return np.max(measures, axis=0)
