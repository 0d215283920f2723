"""Cells the material fills integrated over their area (``Solver(quadrature="cell")``)."""

import numpy as np
import pytest
from conftest import rectangle
from mpi4py import MPI

import dolfin_mpm as dm
from dolfin_mpm.core.locate import basis_at, locate
from dolfin_mpm.core.quadrature import cell_weights
from dolfin_mpm.core.transfer import internal_force
from dolfin_mpm.explicit.options import Options

UNIFORM = np.diag([-3e3, -1e3, -2e3])  # Pa


def _setup(depleted: bool):
    grid = dm.Grid(rectangle((0, 0), (2, 2), (8, 8)))
    mat = dm.LinearElastic(E=1e4, nu=0.3, rho=1000.0)
    P = dm.seed(grid, mat, ppc=4, where=lambda x: (x[0] < 1.0) & (x[1] < 1.0))
    cells, N = locate(grid, P.x, P.cell)
    volume = P.volume.copy()
    keep = np.ones(len(P), dtype=bool)
    if depleted:  # a triangle in the middle of the block keeps one of its 4 points
        centre = np.argmin(np.hypot(P.x[:, 0] - 0.5, P.x[:, 1] - 0.5))
        (inside,) = np.nonzero(cells == cells[centre])
        keep[inside[1:]] = False
    cells, N = cells[keep], N[:, keep]
    return grid, cells, basis_at(grid, cells, N), volume[keep]


def test_a_filled_block_is_integrated_as_the_points_integrate_it():
    """Every cell holds its area's volume: the weights are 1 and R is the points' R."""
    grid, cells, basis, volume = _setup(depleted=False)
    w = cell_weights(grid, basis, cells, volume)
    assert np.allclose(w, 1.0, rtol=1e-12)


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="interior nodes of one rank's mesh")
def test_a_depleted_cell_inside_the_block_carries_its_area():
    """A uniform stress has no resultant at interior nodes. The points' quadrature of a
    triangle left with one of its 4 points gives its nodes 3/4 of the stress's pull unbalanced;
    the cell quadrature integrates the triangle over its area and leaves none."""
    grid, cells, basis, volume = _setup(depleted=True)
    sigma = np.broadcast_to(UNIFORM, (len(volume), 3, 3)).copy()
    w = cell_weights(grid, basis, cells, volume)
    assert np.count_nonzero(np.abs(w - 1.0) > 1e-12) == 1 and w.max() == pytest.approx(4.0)
    x = grid.node_x[:, :2]
    interior = np.all((x > 1e-9) & (x < 1.0 - 1e-9), axis=1)  # nodes of the mesh to round-off
    scale = np.abs(internal_force(basis, sigma, volume)).max()
    by_points = np.abs(internal_force(basis, sigma, volume)[interior]).max()
    by_cells = np.abs(internal_force(basis, sigma, volume * w)[interior]).max()
    assert by_points > 0.1 * scale and by_cells < 1e-12 * scale


def test_cells_at_the_free_surface_keep_the_points_quadrature():
    """A block whose top edge cuts cells in half: those cells are filled in part, not depleted."""
    grid = dm.Grid(rectangle((0, 0), (2, 2), (8, 8)))
    mat = dm.LinearElastic(E=1e4, nu=0.3, rho=1000.0)
    P = dm.seed(grid, mat, ppc=16, where=lambda x: (x[0] < 1.0) & (x[1] < 0.875))  # half a cell
    cells, N = locate(grid, P.x, P.cell)
    w = cell_weights(grid, basis_at(grid, cells, N), cells, P.volume)
    top = P.x[:, 1] > 0.75
    assert np.all(w[top] == 1.0) and np.allclose(w, 1.0)


def test_the_solver_takes_the_option_and_refuses_an_unknown_one_by_name():
    """In a step the weights follow the volumes (a compressed cell that stays full counts its
    area, ``A / sum V > 1``), so the steps differ from the points' quadrature at O(J - 1)."""
    grid = dm.Grid(rectangle((0, 0), (2, 2), (8, 8)))
    mat = dm.LinearElastic(E=1e7, nu=0.3, rho=1000.0)
    ends = []
    for quadrature in ("particle", "cell"):
        P = dm.seed(grid, mat, ppc=4, where=lambda x: (x[0] < 1.0) & (x[1] < 1.0))
        P.sigma[:] = UNIFORM
        x0 = P.x.copy()
        solver = dm.Solver(grid, P, mat, gravity=(0.0, -9.81), quadrature=quadrature)
        for _ in range(3):
            solver.step()
        ends.append(solver.particles.x - x0)
    moved = np.abs(ends[0]).max()
    assert 1e-6 * moved < np.abs(ends[1] - ends[0]).max() < 1e-3 * moved
    with pytest.raises(ValueError, match="quadrature must be 'particle' or 'cell', got 'cells'"):
        Options(quadrature="cells")
