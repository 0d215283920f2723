"""Small-strain, plane-strain, quasi-static elasto-plasticity on DOLFINx.

The reference the MPM is compared with. Displacements are continuous Lagrange (P2 by
default); stresses and the material state live at the quadrature points (degree 2: three per
triangle). At every point the return mapping of :mod:`dolfin_mpm.materials` -- the one the
MPM calls -- gives the stress and its consistent tangent, so Newton's method converges
quadratically. One load parameter ``lam`` scales every prescribed displacement and every
applied traction (proportional loading); :meth:`QuasiStatic.advance` steps it and halves the
step when Newton fails.

Strains and stresses enter the forms as Mandel 4-vectors ``(xx, yy, zz, sqrt2 xy)`` with
``eps_zz = 0`` (plane strain); ``sigma_zz`` is part of the state.
"""

import math
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import dolfinx.fem.petsc
import numpy as np
import ufl
from dolfinx import fem, mesh
from mpi4py import MPI
from petsc4py import PETSc

from dolfin_mpm.core import compat
from dolfin_mpm.materials.tensor import from_mandel, to_mandel

__all__ = ["ConvergenceError", "QuasiStatic", "Step"]

_PLANE = [0, 1, 2, 5]  # Mandel components of a plane-strain state: xx, yy, zz, sqrt2 xy


class ConvergenceError(RuntimeError):
    """Newton failed even with the smallest load step; ``load`` is the last converged level."""

    def __init__(self, message: str, load: float):
        super().__init__(message)
        self.load = load


@dataclass
class Step:
    """One converged load step: load parameter, Newton iterations, wall time [s]."""

    load: float
    iterations: int
    seconds: float


class QuasiStatic:
    """Plane-strain equilibrium ``div sigma = 0`` under proportional loading.

    Args:
        msh: triangle mesh (2D).
        material: a :class:`~dolfin_mpm.materials.Material`; its ``small_strain_update`` gives
            the stress, the consistent tangent and the state at the quadrature points.
        degree: polynomial degree of the displacement, 1 or 2.
        quadrature_degree: degree of the quadrature rule of the stresses.
        tol: Newton converges when the out-of-balance force is below ``tol`` times the larger
            of the applied load and the internal force (reactions included).
        max_iter: Newton iterations per step before the step is cut.
        max_backtracks: halvings of a Newton step that does not reduce the out-of-balance
            force (line search); 0 takes every full step.

    """

    def __init__(self, msh, material, degree: int = 2, quadrature_degree: int = 2, tol: float = 1e-8,
                 max_iter: int = 25, max_backtracks: int = 4):  # fmt: skip
        if msh.topology.dim != 2 or msh.topology.cell_name() != "triangle":
            raise ValueError("msh must be a 2D triangle mesh")
        if degree not in (1, 2):
            raise ValueError(f"degree must be 1 or 2, got {degree!r}")
        if not 0.0 < tol < 1.0:
            raise ValueError(f"tol must be in (0, 1), got {tol!r}")
        if not (isinstance(max_backtracks, (int, np.integer)) and max_backtracks >= 0):
            raise ValueError(f"max_backtracks must be an integer >= 0, got {max_backtracks!r}")
        self.msh, self.material, self.tol, self.max_iter = msh, material, tol, max_iter
        self.max_backtracks = max_backtracks
        self.comm = msh.comm
        self.V = compat.function_space(msh, "Lagrange", degree, (2,))
        self.u = fem.Function(self.V, name="displacement")
        points, _ = compat.quadrature_points(msh, quadrature_degree)
        self._stress_q = fem.Function(compat.quadrature_space(msh, quadrature_degree, 4))
        self._tangent_q = fem.Function(compat.quadrature_space(msh, quadrature_degree, 16))
        self._q_dofs = compat.cell_dofs(self._stress_q.function_space).ravel()

        v, du = ufl.TestFunction(self.V), ufl.TrialFunction(self.V)
        dx = ufl.Measure("dx", domain=msh, metadata={"quadrature_degree": quadrature_degree,
                                                     "quadrature_scheme": "default"})  # fmt: skip
        D = ufl.as_matrix([[self._tangent_q[4 * i + j] for j in range(4)] for i in range(4)])
        self._residual = fem.form(ufl.dot(self._stress_q, _strain(v)) * dx)
        self._jacobian = fem.form(ufl.dot(D * _strain(du), _strain(v)) * dx)
        self._strain_expr = fem.Expression(_strain(self.u), points)

        tdim = msh.topology.dim
        msh.topology.create_connectivity(tdim - 1, tdim)
        imap = msh.topology.index_map(tdim)
        self._cells = np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32)
        n = len(self._cells) * len(points)
        self.sigma = np.zeros((n, 3, 3))  # converged stress at the quadrature points [Pa]
        self.state = {k: np.zeros((n, *shape)) for k, shape in material.state_fields().items()}
        self._eps = np.zeros((n, 6))  # converged strain (Mandel)
        self._iterate = None  # stress, state and strain at the current u

        self.load = 0.0
        self.history: list[Step] = []
        self._bc_dofs = np.zeros(0, dtype=np.int32)
        self._bc_values = np.zeros(0)
        self._f_unit = np.zeros(self.u.x.array.size)  # external force per unit load [N/m]
        self._ksp = PETSc.KSP().create(self.comm)
        self._ksp.setType("preonly")
        self._ksp.getPC().setType("lu")
        if PETSc.Sys.hasExternalPackage("mumps"):
            self._ksp.getPC().setFactorSolverType("mumps")
        self._update_stress()

    # -- set-up ------------------------------------------------------------------------------
    def fix(self, facets: np.ndarray, component: int, value: float = 0.0) -> None:
        """Prescribe ``u[component] = lam * value`` [m] on the dofs of boundary ``facets``."""
        if component not in (0, 1):
            raise ValueError(f"component must be 0 or 1, got {component!r}")
        nodes = fem.locate_dofs_topological(self.V, self.msh.topology.dim - 1, facets)
        dofs = 2 * np.asarray(nodes, dtype=np.int32) + component
        self._bc_dofs = np.concatenate([self._bc_dofs, dofs])
        self._bc_values = np.concatenate([self._bc_values, np.full(len(dofs), float(value))])

    def pressure(self, facets: np.ndarray, value: float) -> None:
        """Apply a normal pressure ``lam * value`` [Pa] (positive pushes inwards) on ``facets``."""
        fdim = self.msh.topology.dim - 1
        facets = np.unique(np.asarray(facets, dtype=np.int32))
        tags = mesh.meshtags(self.msh, fdim, facets, np.ones(len(facets), dtype=np.int32))
        ds = ufl.Measure("ds", domain=self.msh, subdomain_data=tags)
        n, v = ufl.FacetNormal(self.msh), ufl.TestFunction(self.V)
        b = dolfinx.fem.petsc.assemble_vector(fem.form(-value * ufl.dot(n, v) * ds(1)))
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        self._f_unit[: b.getLocalSize()] += b.getArray()
        b.destroy()

    # -- results -----------------------------------------------------------------------------
    def internal_force(self) -> np.ndarray:
        """Nodal internal forces of the converged state [N/m], reactions included, unrolled dofs."""
        b = dolfinx.fem.petsc.assemble_vector(self._residual)
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        f = b.getArray().copy()
        b.destroy()
        return f

    def reaction(self, facets: np.ndarray, component: int) -> float:
        """Total reaction [N/m] on the dofs of ``facets`` in direction ``component`` (owned dofs)."""
        nodes = fem.locate_dofs_topological(self.V, self.msh.topology.dim - 1, facets)
        owned = self.V.dofmap.index_map.size_local
        nodes = np.asarray(nodes)[np.asarray(nodes) < owned]
        return self.comm.allreduce(float(self.internal_force()[2 * nodes + component].sum()), MPI.SUM)

    def cell_average(self, values: np.ndarray) -> np.ndarray:
        """Mean over each cell's quadrature points of ``values`` (``shape=(n_points, ...)``)."""
        return values.reshape(len(self._cells), -1, *values.shape[1:]).mean(axis=1)

    # -- solving -----------------------------------------------------------------------------
    def advance(self, loads: Iterable[float], min_step: float,
                on_step: Callable[["QuasiStatic"], None] | None = None) -> None:  # fmt: skip
        """Step the load parameter through ``loads``, cutting a failing step in halves.

        Args:
            loads: increasing or decreasing target load levels.
            min_step: smallest load increment tried before giving up, > 0.
            on_step: called after every converged step (record, write output).

        Raises:
            ConvergenceError: the step to the next level failed down to ``min_step``; the
                solver keeps the last converged state (``self.load``).

        """
        if not min_step > 0.0:
            raise ValueError(f"min_step must be > 0, got {min_step!r}")
        for target in loads:
            step = target - self.load
            while self.load != target:
                step = math.copysign(min(abs(step), abs(target - self.load)), step)
                if self._try_step(self.load + step):
                    if on_step is not None:
                        on_step(self)
                elif abs(step) / 2 < min_step:
                    raise ConvergenceError(
                        f"Newton did not converge from load {self.load:.6g} with steps down to "
                        f"{abs(step):.3g} (min_step {min_step:.3g})", self.load
                    )  # fmt: skip
                else:
                    step /= 2

    def _try_step(self, load: float) -> bool:
        """Newton from the converged state to ``load``; on success the new state is kept.

        The first iteration imposes the prescribed displacements; every later Newton step is
        halved (at most ``max_backtracks`` times) until the out-of-balance force decreases,
        which keeps iterates out of states far from equilibrium (e.g. whole regions pushed to
        the apex of a cone, where the tangent vanishes and the matrix becomes singular). A step
        that decreases it at no size is taken at the smallest.
        """
        start = time.perf_counter()
        u_converged = self.u.x.array.copy()
        owned = 2 * self.V.dofmap.index_map.size_local
        bc = self._bc_dofs[self._bc_dofs < owned]
        bc_values = self._bc_values[self._bc_dofs < owned]
        free = np.ones(owned, dtype=bool)
        free[bc] = False
        rows = (bc + 2 * self.V.dofmap.index_map.local_range[0]).astype(PETSc.IntType)
        f_ext = load * self._f_unit[:owned]
        R, r, scale = self._out_of_balance(f_ext, free)
        for it in range(1, self.max_iter + 1):
            A = dolfinx.fem.petsc.assemble_matrix(self._jacobian)
            A.assemble()
            b, du, x = A.createVecRight(), A.createVecLeft(), A.createVecLeft()
            b.setArray(-R)
            gap = np.zeros(owned)
            gap[bc] = load * bc_values - self.u.x.array[bc]
            x.setArray(gap)
            A.zeroRowsColumns(rows, 1.0, x, b)  # lifting: b -= A x, then b[rows] = x[rows]
            self._ksp.setOperators(A)
            self._ksp.solve(b, du)
            step = du.getArray().copy()
            for obj in (A, b, du, x):
                obj.destroy()
            if not self.comm.allreduce(bool(np.isfinite(step).all()), MPI.LAND):
                break
            u_start, r_start, s = self.u.x.array[:owned].copy(), r, 1.0
            for _ in range(self.max_backtracks + 1):
                self.u.x.array[:owned] = u_start + s * step
                self.u.x.scatter_forward()
                self._update_stress()
                R, r, scale = self._out_of_balance(f_ext, free)
                if it == 1 or r < r_start:
                    break
                s /= 2
            if not np.isfinite(r):
                break
            if r <= self.tol * scale:
                self.load = load
                self.sigma, self.state, self._eps = self._iterate
                self.history.append(Step(load, it, time.perf_counter() - start))
                return True
        self.u.x.array[:] = u_converged
        self._update_stress()
        return False

    def _out_of_balance(self, f_ext: np.ndarray, free: np.ndarray) -> tuple[np.ndarray, float, float]:
        """Out-of-balance force at the current iterate.

        Returns ``f_int - f_ext`` on the owned dofs [N/m], its norm on the free dofs and the
        force scale of the convergence test (the larger of ``|f_ext|`` and ``|f_int|``).
        """
        f_int = self.internal_force()[: len(free)]
        R = f_int - f_ext
        norms = self.comm.allreduce(np.array([R[free] @ R[free], f_ext @ f_ext, f_int @ f_int]), MPI.SUM)
        return R, math.sqrt(norms[0]), max(math.sqrt(norms[1:].max()), 1e-300)

    def _update_stress(self) -> None:
        """Return mapping at every quadrature point from the converged state to the current ``u``."""
        eps4 = compat.evaluate(self._strain_expr, self.msh, self._cells).reshape(-1, 4)
        eps = np.zeros((len(eps4), 6))
        eps[:, _PLANE] = eps4
        sigma, D, state = self.material.small_strain_update(
            self.sigma, from_mandel(eps - self._eps), self.state
        )
        self._iterate = (sigma, state, eps)
        self._stress_q.x.array.reshape(-1, 4)[self._q_dofs] = to_mandel(sigma)[:, _PLANE]
        self._tangent_q.x.array.reshape(-1, 16)[self._q_dofs] = D[:, _PLANE][:, :, _PLANE].reshape(-1, 16)
        self._stress_q.x.scatter_forward()
        self._tangent_q.x.scatter_forward()


def _strain(u) -> ufl.core.expr.Expr:
    """Plane-strain Mandel 4-vector of ``sym grad u``."""
    e = ufl.sym(ufl.grad(u))
    return ufl.as_vector([e[0, 0], e[1, 1], 0.0, math.sqrt(2.0) * e[0, 1]])
