import numpy as np
import pytest
from conftest import rectangle
from dolfinx import mesh
from mpi4py import MPI

import dolfin_mpm as dm
from dolfin_mpm.core.seeding import reference_points


@pytest.mark.parametrize(
    "tdim, ppc", [(2, 1), (2, 4), (2, 9), (2, 16), (3, 1), (3, 4), (3, 8), (3, 32), (3, 64)]
)
def test_reference_points_integrate_linears(tdim, ppc):
    pts = reference_points(tdim, ppc)
    assert pts.shape == (ppc, tdim)
    assert np.all(pts > 0) and np.all(pts.sum(axis=1) < 1)  # strictly inside
    # Equal weights integrate 1, x_i exactly: mean = centroid of the reference simplex.
    assert np.allclose(pts.mean(axis=0), 1.0 / (tdim + 1))
    assert len(np.unique(pts.round(12), axis=0)) == ppc


@pytest.mark.parametrize("tdim, ppc", [(2, 0), (2, 3), (2, 8), (3, 2), (3, 27)])
def test_bad_ppc(tdim, ppc):
    with pytest.raises(ValueError, match="ppc must be"):
        reference_points(tdim, ppc)


def test_seed_from_separate_body_mesh():
    grid = dm.Grid(rectangle((0, 0), (1, 1), (6, 6)))
    body = mesh.create_rectangle(
        MPI.COMM_WORLD, [np.array([0.2, 0.1]), np.array([0.5, 0.4])], [3, 3], mesh.CellType.triangle
    )
    mat = dm.LinearElastic(1e3, 0.3, 2.0)
    P = dm.seed(grid, mat, ppc=9, body=body)
    assert len(P) == 9 * 18
    assert np.isclose(P.volume.sum(), 0.09) and np.isclose(P.mass.sum(), 0.18)
    assert np.all(P.cell >= 0)
    outside = mesh.create_rectangle(
        MPI.COMM_WORLD, [np.array([0.8, 0.8]), np.array([1.3, 1.2])], [2, 2], mesh.CellType.triangle
    )
    with pytest.raises(ValueError, match="seeded outside the grid"):
        dm.seed(grid, mat, body=outside)
    with pytest.raises(ValueError, match="ppc must be an integer"):
        dm.seed(grid, mat, ppc=0)


def test_seeding_a_mask_of_cells_with_and_without_where():
    grid = dm.Grid(rectangle((0, 0), (1, 1), (4, 4)))
    mat = dm.LinearElastic(E=1e4, nu=0.3, rho=1000.0)
    cells = np.zeros(grid.num_owned_cells, dtype=bool)
    cells[::3] = True
    P = dm.seed(grid, mat, ppc=4, cells=cells)
    assert len(P) == 4 * cells.sum() and np.all(cells[P.cell])  # in those cells and all of them
    Q = dm.seed(grid, mat, ppc=4, cells=cells, where=lambda x: x[0] < 0.5)
    assert 0 < len(Q) < len(P) and np.all(Q.x[:, 0] < 0.5) and np.all(cells[Q.cell])
    with pytest.raises(ValueError, match="cells: a mask of the 32 owned cells, got shape"):
        dm.seed(grid, mat, ppc=4, cells=cells[1:])
