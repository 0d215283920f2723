import dolfin_mpm

# isort: split
import numpy as np
import pytest
from dolfinx import mesh
from mpi4py import MPI


def rectangle(x0, x1, n, diagonal="right"):
    """A triangle mesh of the box [x0, x1] with n = (nx, ny) cells."""
    diag = getattr(mesh.DiagonalType, diagonal)
    return mesh.create_rectangle(
        MPI.COMM_WORLD,
        [np.array(x0, float), np.array(x1, float)],
        list(n),
        mesh.CellType.triangle,
        diagonal=diag,
    )


@pytest.fixture
def unit_grid():
    return dolfin_mpm.Grid(rectangle((0, 0), (1, 1), (8, 8), "crossed"))
