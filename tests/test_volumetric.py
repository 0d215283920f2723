"""The nodal average of the volumetric strain rate (``Solver(volumetric="nodal")``)."""

import numpy as np
import pytest
from conftest import rectangle
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


def test_unknown_volumetric_option_is_named():
    grid = dm.Grid(rectangle((0, 0), (1, 1), (2, 2)))
    mat = dm.LinearElastic(E=1e4, nu=0.3, rho=1000.0)
    with pytest.raises(ValueError, match=r"^volumetric must be 'cell' or 'nodal', got 'fbar'"):
        dm.Solver(grid, dm.seed(grid, mat, ppc=1), mat, volumetric="fbar")
