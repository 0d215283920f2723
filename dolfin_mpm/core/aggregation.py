"""Nearly empty nodes tied to their neighbours, so that the explicit step stays stable at them.

A node whose patch holds little material has a small lumped mass ``m_i``, while the points in
its patch give it stiffness through the gradient of its basis function, which does not shrink
with the mass: its own stable step ``2 sqrt(m_i / g_i)`` falls below the step. ``g_i`` is the
Gershgorin bound of the node's row of the stiffness, ``sum_p V_p M_p |grad N_i| sum_j |grad N_j|``
(``M_p`` the p-wave modulus of the point's material; by this bound the full nodes of the
footing's crossed squares are stable to Courant numbers of about 0.75). Such a node, unless a
boundary condition or wall holds it, is *aggregated*, as the aggregated unfitted
finite element method ties the degrees of freedom of cut cells to interior ones (Badia, Verdugo &
Martín, CMAME 336, 2018): its velocity is the mass-weighted mean of those of its neighbours
(nodes of a cell it is in) that are stable on their own, its *masters*, ``v_i = sum_j c_ij v_j``
with ``c_ij = m_j / sum_k m_k``, and its mass, momentum and force go to the masters in the same
shares. The force still balances (``sum_j c_ij = 1``), the momentum is conserved, and the node
moves with the material round it instead of on its own. A group of light nodes with no master
near (a lone cluster of points) moves with its heaviest node, unstrained.

Which nodes are light all ranks agree on (assembled values); each owned one is tied by its rank,
with the neighbours its local cells give it, and what goes to a master owned by another rank is
summed into it there (:meth:`~dolfin_mpm.core.grid.Grid.assemble`). A lone group whose nodes two
ranks own is tied on each rank separately.
"""

import numpy as np
from scipy import sparse
from scipy.sparse import csgraph

from dolfin_mpm.core.grid import Grid
from dolfin_mpm.core.locate import Basis

__all__ = ["ROUNDS", "Aggregation", "gershgorin_stiffness"]

#: Layers of light nodes tied through their light neighbours' ties.
ROUNDS = 4


def gershgorin_stiffness(grid: Grid, basis: Basis, modulus_volume: np.ndarray) -> np.ndarray:
    """``g_i = sum_p V_p M_p |grad N_i| sum_j |grad N_j|`` [N/m], assembled, ``shape=(num_nodes,)``.

    ``modulus_volume``: ``V_p M_p`` of each particle of ``basis`` [N m], ``shape=(n,)``. The
    gradients are constant in a cell: the particles' sums go by cell first.
    """
    W = np.bincount(basis.cells, weights=modulus_volume, minlength=grid.num_cells)
    norms = grid.grad_N_norms
    rows = W[:, None] * norms * norms.sum(axis=1, keepdims=True)
    g = np.bincount(grid.cell_dofs.ravel(), weights=rows.ravel(), minlength=grid.num_nodes)
    return grid.assemble(grid.scratch, g).copy()


class Aggregation:
    """The light nodes of one step tied to their masters; ``None`` from :meth:`of` if there are none.

    Attributes:
        light: the tied owned nodes, ``shape=(k,)``.
        rows, masters, shares: the ties, one a pair: the light node (its place in ``light``),
            the master and ``c_ij``; each light node's shares sum to 1.

    """

    def __init__(
        self, grid: Grid, light: np.ndarray, rows: np.ndarray, masters: np.ndarray, shares: np.ndarray
    ):
        self.grid, self.light, self.rows, self.masters, self.shares = grid, light, rows, masters, shares

    @classmethod
    def of(
        cls,
        grid: Grid,
        mass: np.ndarray,
        stiffness: np.ndarray,
        active: np.ndarray,
        dt: float,
        held: np.ndarray,
    ):
        """The aggregation of the active owned nodes whose own stable step is below ``dt`` [s].

        ``mass`` [kg] and ``stiffness`` (:func:`gershgorin_stiffness`) assembled, ``active``
        the nodes the solve moves, each ``shape=(num_nodes,)``; ``held``: the nodes a boundary
        condition or wall acts on, which are never light (a prescribed velocity needs no
        mass, and their force is the condition's to balance), but may be masters. A light node
        is tied to its neighbours that are not light, in shares of their mass; one whose
        neighbours are all light takes the mean of its tied light neighbours' ties, up to
        :data:`ROUNDS` layers deep; a group of light nodes with no master within reach (a lone
        cluster of points) moves with its heaviest node, as a rigid body. Collective.
        """
        n, owned = grid.num_nodes, grid.num_owned_nodes
        light = active & (4.0 * mass < stiffness * dt * dt)  # 2 sqrt(m / g) < dt
        light[held] = False
        idx = np.flatnonzero(light[:owned])  # ties are their owners' (all ranks know which are light)
        if grid.comm.allreduce(idx.size) == 0:
            return None
        indptr, indices = grid.node_neighbours
        counts = indptr[idx + 1] - indptr[idx]
        pair_row = np.repeat(np.arange(idx.size), counts)  # the light nodes' neighbours, pair by pair
        starts = np.repeat(indptr[idx] - np.cumsum(counts) + counts, counts)
        neighbour = indices[starts + np.arange(counts.sum())]
        weight = np.where(active & ~light, mass, 0.0)[neighbour]
        total = np.bincount(pair_row, weights=weight, minlength=idx.size)
        master = weight > 0.0
        rows, cols = pair_row[master], neighbour[master]
        shares = weight[master] / total[rows]
        if np.all(total > 0.0):
            return cls(grid, idx, rows, cols, shares)
        T = sparse.csr_matrix((shares, (rows, cols)), shape=(idx.size, n))
        position = np.full(n, -1)
        position[idx] = np.arange(idx.size)
        inner = position[neighbour] >= 0
        among = sparse.csr_matrix(
            (np.ones(inner.sum()), (pair_row[inner], position[neighbour[inner]])), shape=(idx.size,) * 2
        )
        for _ in range(ROUNDS):
            tied = np.diff(T.indptr) > 0
            step = _row_normalised(
                sparse.diags((~tied).astype(float)) @ among @ sparse.diags(tied.astype(float))
            )
            if step.nnz == 0:
                break
            T = (T + step @ T).tocsr()
        untied = np.diff(T.indptr) == 0
        if untied.any():  # groups with no master: each with its heaviest node
            keep = sparse.diags(untied.astype(float))
            _, group = csgraph.connected_components(keep @ among @ keep, directed=False)
            order = np.flatnonzero(untied)[np.argsort(mass[idx[untied]], kind="stable")]
            heaviest = np.full(group.max() + 1, -1)
            heaviest[group[order]] = order  # the last, heaviest, wins
            root = heaviest[group]
            follow = untied & (root != np.arange(idx.size))
            head = np.flatnonzero(follow)
            T = T + sparse.csr_matrix((np.ones(head.size), (head, idx[root[follow]])), shape=T.shape)
        T = T.tocsr()
        T.eliminate_zeros()
        tied = np.diff(T.indptr) > 0
        ties = T[tied].tocoo()
        return cls(grid, idx[tied], ties.row, ties.col, ties.data)

    def gather(self, a: np.ndarray) -> np.ndarray:
        """Nodal values ``a`` with each light node's moved to its masters in their shares.

        ``a``: assembled, ``shape=(num_nodes,)`` or ``(num_nodes, gdim)``. Returns a new array
        of that shape, 0 at the light nodes, ghosts refreshed.
        """
        grid = self.grid
        A = a.reshape(len(a), -1)
        out, moved = A.copy(), np.zeros_like(A)
        values = A[self.light][self.rows] * self.shares[:, None]
        for c in range(A.shape[1]):
            moved[:, c] = np.bincount(self.masters, weights=values[:, c], minlength=len(A))
        out[self.light] = 0.0
        if grid.comm.size == 1:
            return (out + moved).reshape(a.shape)
        buffer = grid.scratch if A.shape[1] == 1 else grid.scratch_vector
        out += grid.assemble(buffer, moved)  # what went to ghosts, summed into their owners
        owned = grid.num_owned_nodes * A.shape[1]
        return grid.refresh_ghosts(buffer, out.ravel()[:owned]).reshape(a.shape).copy()

    def extend(self, v: np.ndarray) -> None:
        """Each light node's velocity from its masters', ``v_i = sum_j c_ij v_j``, in place.

        ``v``: ``shape=(num_nodes, gdim)`` C-contiguous, ghosts refreshed from their owners.
        """
        grid = self.grid
        values = v[self.masters] * self.shares[:, None]
        for c in range(v.shape[1]):
            v[self.light, c] = np.bincount(self.rows, weights=values[:, c], minlength=len(self.light))
        if grid.comm.size > 1:
            owned = v[: grid.num_owned_nodes].ravel()
            v[:] = grid.refresh_ghosts(grid.scratch_vector, owned).reshape(v.shape)


def _row_normalised(W: sparse.spmatrix) -> sparse.csr_matrix:
    """``W`` with each non-empty row scaled to sum to 1."""
    W = W.tocsr()
    W.eliminate_zeros()
    total = np.asarray(W.sum(axis=1)).ravel()
    return (sparse.diags(np.where(total > 0.0, 1.0 / np.where(total > 0.0, total, 1.0), 0.0)) @ W).tocsr()
