"""Grid, particle location, P1 basis, P2G/G2P identities and the lumped mass."""

import dolfinx.fem.petsc
import numpy as np
import pytest
import ufl
from conftest import rectangle
from dolfinx import fem, mesh
from mpi4py import MPI

import dolfin_mpm as dm
from dolfin_mpm.core.locate import basis_at, locate
from dolfin_mpm.core.transfer import (
    gradient,
    grid_to_particles,
    internal_force,
    interpolate,
    particles_to_grid,
    scatter,
    volume_ratio,
)
from dolfin_mpm.explicit.step import p2g
from dolfin_mpm.materials.tensor import component_first, particle_first

EPS = np.finfo(np.float64).eps


def random_points(grid, n, seed=0):
    rng = np.random.default_rng(seed)
    lo, hi = grid.mesh.geometry.x.min(axis=0), grid.mesh.geometry.x.max(axis=0)
    x = np.zeros((n, 3))
    x[:, : grid.gdim] = lo[: grid.gdim] + rng.random((n, grid.gdim)) * (hi - lo)[: grid.gdim]
    return x


def test_partition_of_unity_and_gradients(unit_grid):
    x = random_points(unit_grid, 500)
    cells, N = locate(unit_grid, x, np.full(len(x), -1, np.int32))
    assert np.all(cells >= 0)
    basis = basis_at(unit_grid, cells, N)
    assert np.allclose(basis.N.sum(axis=0), 1.0, atol=10 * EPS)
    assert np.all(basis.N >= -1e-12)
    assert np.allclose(basis.dN.sum(axis=0), 0.0, atol=100 * EPS / unit_grid.h_min)
    # The basis reproduces linear functions and their gradients.
    f = lambda y: np.c_[2.0 * y[:, 0] - 3.0 * y[:, 1] + 0.5]  # noqa: E731
    nodal = f(unit_grid.node_x)
    assert np.allclose(interpolate(basis, nodal), f(x), atol=1e-13)
    assert np.allclose(gradient(basis, nodal)[:, 0, :], [2.0, -3.0], atol=1e-12)


@pytest.mark.parametrize("gdim", [2, 3])
def test_transfers_equal_their_dense_sums(gdim):
    # Each transfer against the dense matrices of the basis: values N[p, a], gradients dN[j][p, a].
    msh = rectangle((0, 0), (1, 1), (6, 5)) if gdim == 2 else mesh.create_unit_cube(MPI.COMM_WORLD, 3, 4, 2)
    grid = dm.Grid(msh)
    x = random_points(grid, 400, seed=3)
    basis = basis_at(grid, *locate(grid, x, np.full(len(x), -1, np.int32)))
    n, rows = len(x), np.arange(len(x))
    N, dN = np.zeros((n, grid.num_nodes)), np.zeros((gdim, n, grid.num_nodes))
    for a in range(gdim + 1):
        N[rows, basis.dofs[a]] += basis.N[a]
        for j in range(gdim):
            dN[j][rows, basis.dofs[a]] += basis.dN[a, j]
    rng = np.random.default_rng(4)
    v, volume = rng.normal(size=(n, 5)), rng.random(n)
    sigma = rng.normal(size=(n, 3, 3))
    sigma = sigma + np.swapaxes(sigma, 1, 2)
    # Field sizes the kernels have unrolled (1 and gdim components) and others (generic loops).
    assert np.allclose(scatter(basis, v[:, 0]), N.T @ v[:, 0], rtol=0, atol=1e-13)
    for k in (gdim, 5):
        assert np.allclose(scatter(basis, v[:, :k]), N.T @ v[:, :k], rtol=0, atol=1e-13)
        nodal = rng.normal(size=(grid.num_nodes, k))
        assert np.allclose(interpolate(basis, nodal), N @ nodal, rtol=0, atol=1e-13)
        L = np.stack([dN[j] @ nodal for j in range(gdim)], axis=2)  # (n, k, gdim)
        assert np.allclose(gradient(basis, nodal), L, rtol=0, atol=1e-12)
    R = sum(dN[j].T @ (volume[:, None] * sigma[:, :gdim, j]) for j in range(gdim))
    assert np.allclose(internal_force(basis, sigma, volume), R, rtol=0, atol=1e-12)


@pytest.mark.parametrize("gdim", [2, 3])
def test_scatters_add_each_nodes_terms_in_particle_order(gdim):
    # Particles in runs of one cell, a cell's run broken and resumed: the nodal sums the kernels
    # hold in registers over a run are bit for bit one term at a time, in the particles' order.
    msh = rectangle((0, 0), (1, 1), (3, 2)) if gdim == 2 else mesh.create_unit_cube(MPI.COMM_WORLD, 2, 1, 1)
    grid = dm.Grid(msh)
    x = random_points(grid, 60, seed=5)
    cells, _ = locate(grid, x, np.full(len(x), -1, np.int32))
    order = np.argsort(cells, kind="stable")
    x = np.concatenate([x[order], x[order[:7]], x[order[::-3]]])
    basis = basis_at(grid, *locate(grid, x, np.full(len(x), -1, np.int32)))
    rng = np.random.default_rng(6)
    n, nn = len(x), gdim + 1
    mass, v, volume = rng.random(n), rng.normal(size=(n, gdim)), rng.random(n)
    sigma = rng.normal(size=(n, 3, 3))
    nodes = basis.dofs.T.ravel()  # (particle, node) pairs in the particles' order

    def one_at_a_time(terms):  # np.add.at adds in index order, unbuffered
        out = np.zeros((grid.num_nodes, *terms.shape[2:]))
        np.add.at(out, nodes, terms.reshape(n * nn, *terms.shape[2:]))
        return out

    N = basis.N.T[:, :, None]  # (n, nn, 1)
    dN = np.moveaxis(basis.dN, 2, 0)  # (n, nn, gdim)
    f = np.zeros((n, nn, gdim))
    for i in range(gdim):
        for j in range(gdim):
            f[:, :, i] += (sigma[:, i, j] * volume)[:, None] * dN[:, :, j]
    want_m = one_at_a_time(N[:, :, 0] * mass[:, None])
    want_p = one_at_a_time(N * (mass[:, None] * v)[:, None])
    assert np.array_equal(scatter(basis, v), one_at_a_time(N * v[:, None]))
    assert np.array_equal(scatter(basis, mass), want_m)
    assert np.array_equal(internal_force(basis, sigma, volume), one_at_a_time(f))
    m, momentum, force = particles_to_grid(basis, mass, v, sigma, volume)
    assert np.array_equal(m, want_m) and np.array_equal(momentum, want_p)
    assert np.array_equal(force, one_at_a_time(f))
    a_node = rng.normal(size=(grid.num_nodes, gdim))
    v_node = rng.normal(size=(grid.num_nodes, gdim))
    v_interp = interpolate(basis, v_node)
    v_new, dx, momenta = grid_to_particles(basis, v_node, a_node, v, 1e-3, 0.5, mass)
    assert np.array_equal(v_new, 0.5 * (v + 1e-3 * interpolate(basis, a_node)) + 0.5 * v_interp)
    assert np.array_equal(dx, 1e-3 * v_interp)
    assert np.array_equal(momenta, one_at_a_time(N * (mass[:, None] * v_new)[:, None]))


@pytest.mark.parametrize("gdim", [2, 3])
def test_volume_ratio_is_the_determinant_of_the_step(gdim):
    L = np.random.default_rng(gdim).normal(size=(50, gdim, gdim))
    expected = np.linalg.det(np.eye(gdim) + 0.1 * L)
    for layout in (L, particle_first(component_first(L))):  # as the gradient writes it, or not
        assert volume_ratio(layout, 0.1) == pytest.approx(expected, rel=1e-14)


def test_locate_cheap_path_and_search(unit_grid):
    x = random_points(unit_grid, 300, seed=1)
    cells, _ = locate(unit_grid, x, np.full(len(x), -1, np.int32))
    # Same cells when the old cell is given (cheap path) ...
    again, _ = locate(unit_grid, x, cells)
    assert np.array_equal(again, cells)
    # ... and after a small move, the result equals a fresh search.
    x2 = x + np.r_[0.03, -0.02, 0.0]
    moved, N = locate(unit_grid, x2, cells)
    fresh, _ = locate(unit_grid, x2, np.full(len(x), -1, np.int32))
    outside = (x2[:, 0] > 1) | (x2[:, 1] < 0)
    assert np.all(moved[outside] == -1)
    lam, inside = dm.core.locate.barycentric(unit_grid, x2[~outside], fresh[~outside])
    assert inside.all()
    assert np.all(lam.min(axis=0) >= -1e-12) and np.all(N[:, ~outside].min(axis=0) >= -1e-12)


def test_lumped_mass_equals_consistent_mass_row_sum():
    grid = dm.Grid(rectangle((0, 0), (0.2, 0.3), (7, 9), "left"))
    rho = 1500.0
    P = dm.seed(grid, dm.LinearElastic(1e6, 0.3, rho), ppc=4)
    solver = dm.Solver(grid, P, dm.LinearElastic(1e6, 0.3, rho))
    cells, N = locate(grid, P.x, P.cell)
    p2g(solver.model, P, basis_at(grid, cells, N))

    u, v = ufl.TrialFunction(grid.Q), ufl.TestFunction(grid.Q)
    M = dolfinx.fem.petsc.assemble_matrix(fem.form(rho * u * v * ufl.dx))
    M.assemble()
    ones, row_sum = M.createVecRight(), M.createVecLeft()
    ones.set(1.0)
    M.mult(ones, row_sum)
    lumped = grid.mass.x.array[: grid.num_owned_nodes]
    assert np.allclose(lumped, row_sum.array, rtol=1e-12, atol=0)
    assert np.isclose(grid.comm.allreduce(lumped.sum(), MPI.SUM), rho * 0.2 * 0.3, rtol=1e-12)


@pytest.mark.parametrize("flip", [0.0, 0.5, 1.0])
def test_transfers_conserve_mass_and_momentum(unit_grid, flip):
    rng = np.random.default_rng(2)
    x = random_points(unit_grid, 400, seed=3) * np.r_[0.8, 0.8, 0] + np.r_[0.1, 0.1, 0]
    n = len(x)
    P = dm.Particles(x, rng.normal(size=(n, 2)), rng.random(n) + 0.5, np.full(n, 1e-3))
    solver = dm.Solver(unit_grid, P, dm.LinearElastic(1e3, 0.2, 1.0), flip=flip, dt=1e-4)
    m0, p0 = solver.total_mass(), solver.total_momentum()
    cells, N = locate(unit_grid, P.x, P.cell)
    basis = basis_at(unit_grid, cells, N)
    p2g(solver.model, P, basis)
    owned = slice(0, unit_grid.num_owned_nodes)
    m_grid = unit_grid.mass.x.array[owned].sum()
    p_grid = unit_grid.momentum.x.array.reshape(-1, 2)[owned].sum(axis=0)
    assert np.isclose(unit_grid.comm.allreduce(m_grid, MPI.SUM), m0, rtol=1e-14)
    assert np.allclose(unit_grid.comm.allreduce(p_grid, MPI.SUM), p0, rtol=0, atol=1e-13 * np.abs(p0).max())
    solver.step()  # no stress, no gravity: the step must not create momentum
    assert np.allclose(solver.total_momentum(), p0, atol=1e-12 * np.abs(p0).max())
    assert solver.total_mass() == pytest.approx(m0, rel=1e-15)


def test_3d_grid_basis():
    msh = mesh.create_box(MPI.COMM_WORLD, [np.zeros(3), np.ones(3)], [3, 3, 3], mesh.CellType.tetrahedron)
    grid = dm.Grid(msh)
    x = random_points(grid, 200)
    cells, N = locate(grid, x, np.full(len(x), -1, np.int32))
    assert np.all(cells >= 0)
    b = basis_at(grid, cells, N)
    assert np.allclose(b.N.sum(axis=0), 1.0) and np.allclose(b.dN.sum(axis=0), 0.0, atol=1e-12)
    assert np.isclose(
        grid.comm.allreduce(grid.cell_volume[: msh.topology.index_map(3).size_local].sum(), MPI.SUM), 1.0
    )


def test_quadrilateral_mesh_is_refused():
    msh = mesh.create_rectangle(
        MPI.COMM_WORLD, [np.zeros(2), np.ones(2)], [2, 2], mesh.CellType.quadrilateral
    )
    with pytest.raises(ValueError, match="affine simplices"):
        dm.Grid(msh)


def test_compiling_a_form_prints_nothing(tmp_path):
    """A fresh JIT cache: FFCx compiles a space's elements and a form without the compiler's lines."""
    import os
    import subprocess
    import sys

    script = (
        "import dolfin_mpm as dm, ufl\n"
        "from dolfinx import fem, mesh\n"
        "from mpi4py import MPI\n"
        "grid = dm.Grid(mesh.create_unit_square(MPI.COMM_SELF, 2, 2))\n"
        "fem.form(ufl.TestFunction(grid.Q) * ufl.dx)\n"
        "print('built')\n"
    )
    env = {**os.environ, "XDG_CACHE_HOME": str(tmp_path)}
    run = dict(env=env, capture_output=True, text=True, cwd=tmp_path)
    done = subprocess.run([sys.executable, "-c", script], **run)
    assert done.returncode == 0, done.stderr
    assert any((tmp_path / "fenics").glob("libffcx_forms_*.c"))  # it compiled
    assert done.stdout == "built\n" and "build_ext" not in done.stderr and "gcc" not in done.stderr
