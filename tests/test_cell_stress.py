"""Each particle's stress replaced by its cell's mean (``Solver(stress="cell")``, the default)."""

import numpy as np
import pytest
from conftest import rectangle
from dolfinx import mesh
from mpi4py import MPI

import dolfin_mpm as dm
from dolfin_mpm.core.cell_stress import cell_mean_stress
from dolfin_mpm.core.locate import basis_at, locate
from dolfin_mpm.core.transfer import internal_force


def _noisy(n, rng, gdim):
    """Random symmetric stresses [Pa], plane strain in 2D (no xz, yz shear)."""
    A = rng.normal(scale=1e3, size=(n, 3, 3))
    sigma = A + np.swapaxes(A, 1, 2)
    if gdim == 2:
        sigma[:, 2, :2] = sigma[:, :2, 2] = 0.0
    return sigma


@pytest.mark.parametrize("gdim", [2, 3])
def test_the_cell_mean_leaves_the_nodal_forces_and_each_cells_mean_as_they_were(gdim):
    if gdim == 2:
        msh = rectangle((0, 0), (1, 1), (5, 5))
    else:
        msh = mesh.create_box(MPI.COMM_WORLD, [np.zeros(3), np.ones(3)], [3, 3, 3], mesh.CellType.tetrahedron)
    grid = dm.Grid(msh)
    mat = dm.LinearElastic(E=1e4, nu=0.3, rho=1000.0)
    P = dm.seed(grid, mat, ppc=4)
    rng = np.random.default_rng(1)
    P.volume *= rng.uniform(0.5, 1.5, len(P))  # unequal weights
    cells, N = locate(grid, P.x, P.cell)
    basis = basis_at(grid, cells, N)
    sigma = _noisy(len(P), rng, gdim)
    mean = cell_mean_stress(sigma, P.volume, cells, P.material, grid.num_cells)
    R0, R1 = internal_force(basis, sigma, P.volume), internal_force(basis, mean, P.volume)
    assert np.abs(R1 - R0).max() <= 1e-12 * np.abs(R0).max()  # the forces see nothing of it
    assert np.abs(mean - sigma).max() > 0.1 * np.abs(sigma).max()  # and it did change the stresses
    c = cells[0]
    inside = cells == c
    expected = np.einsum("p,pij->ij", P.volume[inside], sigma[inside]) / P.volume[inside].sum()
    assert np.allclose(mean[inside], expected, rtol=1e-13, atol=1e-9)  # one value per cell


def test_the_means_keep_materials_apart_and_leave_the_kept_points_out():
    grid = dm.Grid(rectangle((0, 0), (1, 1), (2, 2)))
    mat = dm.LinearElastic(E=1e4, nu=0.3, rho=1000.0)
    P = dm.seed(grid, mat, ppc=9)
    cells, _ = locate(grid, P.x, P.cell)
    rng = np.random.default_rng(2)
    sigma = _noisy(len(P), rng, 2)
    material = (np.arange(len(P)) % 2).astype(np.int32)
    kept = np.arange(len(P)) % 3 == 0
    sigma[kept] = 0.0  # e.g. points apart, stress free
    mean = cell_mean_stress(sigma, P.volume, cells, material, grid.num_cells, kept)
    assert np.all(mean[kept] == 0.0)
    for c in np.unique(cells):
        for k in (0, 1):
            group = (cells == c) & (material == k) & ~kept
            if group.any():
                w = P.volume[group]
                assert np.allclose(mean[group], np.einsum("p,pij->ij", w, sigma[group]) / w.sum(), atol=1e-9)


@pytest.mark.parametrize("plane_strain", [False, True])
def test_the_means_in_place_are_the_new_arrays_means_bit_for_bit(plane_strain):
    """In place (the step's use) the kept points keep their stress; the others take the means.

    In plane strain the out-of-plane shears are zero at every point: in place they are left as
    they are, and stay zero.
    """
    from dolfin_mpm.materials.tensor import component_first, particle_first

    rng = np.random.default_rng(5)
    n, num_cells = 300, 40
    sigma = _noisy(n, rng, 3)
    if plane_strain:
        sigma[:, 0, 2] = sigma[:, 2, 0] = sigma[:, 1, 2] = sigma[:, 2, 1] = 0.0
    volume, cells = rng.uniform(0.5, 1.5, n), np.sort(rng.integers(0, num_cells, n))
    material = rng.integers(0, 2, n).astype(np.int32)
    kept = rng.random(n) < 0.2
    expected = cell_mean_stress(sigma, volume, cells, material, num_cells, kept)
    own = particle_first(component_first(sigma).copy())  # component-first memory, as the step's
    out = cell_mean_stress(own, volume, cells, material, num_cells, kept, in_place=True)
    assert np.shares_memory(out, own)
    assert np.array_equal(out, expected)
    assert np.array_equal(out[kept], sigma[kept]) and not np.array_equal(out[~kept], sigma[~kept])


def test_the_mean_of_states_inside_the_cone_is_inside_it():
    rng = np.random.default_rng(3)
    phi = np.radians(30.0)
    m = 18.0 * np.sin(phi) / (9.0 - np.sin(phi) ** 2)
    n = 400
    p = rng.uniform(0.0, 1e4, n)
    s = _noisy(n, rng, 2)
    s -= np.einsum("pii->p", s)[:, None, None] / 3.0 * np.eye(3)
    q = np.sqrt(1.5 * np.einsum("pij,pij->p", s, s))
    s *= (m * p * rng.uniform(0.0, 1.0, n) / q)[:, None, None]  # q <= m p: inside, some at the apex
    sigma = s - p[:, None, None] * np.eye(3)
    cells = rng.integers(0, 20, n)
    mean = cell_mean_stress(sigma, rng.uniform(0.5, 1.5, n), cells, np.zeros(n, np.int32), 20)
    p_m = -np.einsum("pii->p", mean) / 3.0
    s_m = mean + p_m[:, None, None] * np.eye(3)
    q_m = np.sqrt(1.5 * np.einsum("pij,pij->p", s_m, s_m))
    assert np.all(q_m <= m * p_m * (1.0 + 1e-12))


def test_the_step_with_cell_means_moves_the_grid_as_the_step_with_particle_stresses():
    """Both solvers start from the same noisy stresses: their P2G forces, so their grids, agree."""
    velocities = []
    for stress in ("cell", "particle"):
        grid = dm.Grid(rectangle((0, 0), (1, 1), (4, 4)))
        mat = dm.LinearElastic(E=1e4, nu=0.3, rho=1000.0)
        P = dm.seed(grid, mat, ppc=4)
        P.sigma = _noisy(len(P), np.random.default_rng(4 + MPI.COMM_WORLD.rank), 2)
        solver = dm.Solver(grid, P, mat, gravity=(0.0, -9.81), stress=stress)
        solver.step()
        velocities.append(grid.velocity.x.array.copy())
    assert np.abs(velocities[0] - velocities[1]).max() <= 1e-12 * np.abs(velocities[1]).max()


def test_unknown_stress_option_is_named():
    grid = dm.Grid(rectangle((0, 0), (1, 1), (2, 2)))
    mat = dm.LinearElastic(E=1e4, nu=0.3, rho=1000.0)
    with pytest.raises(ValueError, match=r"^stress must be 'cell' or 'particle', got 'node'"):
        dm.Solver(grid, dm.seed(grid, mat, ppc=1), mat, stress="node")
