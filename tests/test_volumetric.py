"""The nodal average of the volumetric strain rate (``Solver(volumetric="nodal")``)."""

import numpy as np
import pytest
from conftest import rectangle
from dolfinx import mesh
from mpi4py import MPI

import dolfin_mpm as dm
from dolfin_mpm.core.locate import basis_at, locate
from dolfin_mpm.core.volumetric import nodal_volumetric


def test_nodal_volumetric_average_keeps_affine_fields_and_the_total_volume_change():
    grid = dm.Grid(rectangle((0, 0), (1, 1), (6, 6)))
    mat = dm.LinearElastic(E=1e4, nu=0.3, rho=1000.0)
    P = dm.seed(grid, mat, ppc=4, where=lambda x: x[1] < 0.7)
    cells, N = locate(grid, P.x, P.cell)
    basis = basis_at(grid, cells, N)
    A = np.array([[0.3, -0.2], [0.5, 0.1]])
    L = nodal_volumetric(grid, basis, np.tile(A, (len(P), 1, 1)), P.volume)
    assert np.allclose(L, A, rtol=0, atol=1e-14)  # a uniform rate is its own average

    L0 = np.random.default_rng(0).normal(size=(len(P), 2, 2))
    tr0 = np.einsum("pii->p", L0)
    L1 = nodal_volumetric(grid, basis, L0.copy(), P.volume)
    tr1 = np.einsum("pii->p", L1)
    total = lambda tr: MPI.COMM_WORLD.allreduce(float(P.volume @ tr))  # noqa: E731
    assert total(tr1) == pytest.approx(total(tr0), rel=1e-12)  # the volume change, redistributed
    assert np.std(tr1) < 0.5 * np.std(tr0)  # and smoothed
    deviatoric = lambda L: L - np.einsum("pii->p", L)[:, None, None] / 2 * np.eye(2)  # noqa: E731
    assert np.allclose(deviatoric(L1), deviatoric(L0), rtol=0, atol=1e-12)  # the rest kept


def average_one_term_at_a_time(grid, basis, L, volume):
    """The average as numpy writes it, one nodal term at a time in the particles' order."""
    g, n = L.shape[1], len(volume)
    tr = np.einsum("pii->p", L)
    sums = [np.zeros(basis.num_nodes), np.zeros(basis.num_nodes)]
    for out, values in zip(sums, (volume, volume * tr)):  # particle by particle, node by node
        np.add.at(out, basis.dofs.T.ravel(), (basis.N * values).T.ravel())
    weight = grid.assemble(grid.scratch, sums[0]).copy()
    total = grid.assemble(grid.scratch, sums[1])
    with np.errstate(divide="ignore", invalid="ignore"):
        tr_node = np.where(weight > 0.0, total / weight, 0.0)
    interpolated = np.zeros(n)
    for a in range(g + 1):
        interpolated += basis.N[a] * tr_node[basis.dofs[a]]
    out = L.copy()
    for i in range(g):
        out[:, i, i] += (interpolated - tr) / g
    return out


@pytest.mark.parametrize("gdim", [2, 3])
def test_the_compiled_average_takes_numpys_terms_in_numpys_order(gdim):
    """Bit for bit, for a gradient's particle-first view of component-first memory and for a
    particle-first array, with the step's weights given or not."""
    from dolfin_mpm.core.transfer import gradient
    from dolfin_mpm.core.volumetric import nodal_volume

    if gdim == 2:
        grid = dm.Grid(rectangle((0, 0), (1, 1), (6, 6), "crossed"))
    else:
        grid = dm.Grid(mesh.create_box(MPI.COMM_WORLD, [np.zeros(3), np.ones(3)], [3, 3, 3]))
    mat = dm.LinearElastic(E=1e4, nu=0.3, rho=1000.0)
    P = dm.seed(grid, mat, ppc=4 if gdim == 2 else 8, where=lambda x: x[1] < 0.7)
    P.volume = P.volume * np.random.default_rng(1).uniform(0.5, 1.5, len(P))
    cells, N = locate(grid, P.x, P.cell)
    basis = basis_at(grid, cells, N)
    v_node = np.random.default_rng(2).normal(size=(basis.num_nodes, gdim))
    L = gradient(basis, v_node)  # the layout the step gives
    expected = average_one_term_at_a_time(grid, basis, np.array(L), P.volume)
    weight = nodal_volume(grid, basis, P.volume)
    for given in (None, weight):
        for L_in in (gradient(basis, v_node), np.ascontiguousarray(L)):  # component- and particle-first
            out = nodal_volumetric(grid, basis, L_in, P.volume, given)
            assert out is L_in and np.array_equal(out, expected)


def test_unknown_volumetric_option_is_named():
    grid = dm.Grid(rectangle((0, 0), (1, 1), (2, 2)))
    mat = dm.LinearElastic(E=1e4, nu=0.3, rho=1000.0)
    with pytest.raises(ValueError, match=r"^volumetric must be 'cell' or 'nodal', got 'fbar'"):
        dm.Solver(grid, dm.seed(grid, mat, ppc=1), mat, volumetric="fbar")
