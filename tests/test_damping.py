"""Local damping against the nodes' running mean velocity (``damping_mean_time``): a steady
slide is left alone, the oscillations about it are damped as Cundall's damping damps them."""

import numpy as np
import pytest
from conftest import rectangle
from mpi4py import MPI

import dolfin_mpm as dm


def slide(v0: float, damping: float, mean_time: float | None) -> tuple[float, float]:
    """An elastic block dropped on a frictionless floor while sliding along it at ``v0`` [m/s].

    It settles under its weight (vertical waves, period about 0.02 s) and slides 0.2 m, across
    four columns of cells, in 0.4 s. Returns its mean horizontal velocity [m/s] and its
    vertical kinetic energy [J/m] at the end.
    """
    grid = dm.Grid(rectangle((0, 0), (2.0, 0.3), (40, 6)))
    mat = dm.LinearElastic(E=1e6, nu=0.3, rho=1000.0)
    block = lambda x: (x[0] > 0.2 - 1e-9) & (x[0] < 0.7 + 1e-9) & (x[1] < 0.2 + 1e-9)  # noqa: E731
    P = dm.seed(grid, mat, ppc=4, where=block)
    P.v[:, 0] = v0
    floor = dm.SlipBC(grid.nodes_where(lambda x: np.isclose(x[1], 0.0)), normal=(0, -1))
    solver = dm.Solver(
        grid, P, mat, bcs=[floor], gravity=(0, -9.81), damping=damping, damping_mean_time=mean_time
    )
    solver.run(0.4, progress=False)
    P, comm = solver.particles, grid.comm
    sums = (P.mass, P.mass * P.v[:, 0], 0.5 * P.mass * P.v[:, 1] ** 2)
    mass, momentum, kinetic = (comm.allreduce(float(a.sum()), MPI.SUM) for a in sums)
    return momentum / mass, kinetic


def test_a_steady_slide_keeps_its_speed_and_the_waves_are_damped():
    """Cundall's damping drags the slide (its nodes' out-of-balance force is the noise of the
    points crossing cells, and the damping always opposes the velocity); against the running
    mean it takes no more than the noise, while it damps the settling as much."""
    free_speed, free_waves = slide(0.5, 0.0, None)
    cundall_speed, cundall_waves = slide(0.5, 0.3, None)
    mean_speed, mean_waves = slide(0.5, 0.3, 0.1)
    assert free_speed == pytest.approx(0.5, rel=1e-12)  # no horizontal force on the block at all
    assert cundall_speed < 0.4  # a fifth of the speed lost (0.35)
    assert mean_speed == pytest.approx(0.5, rel=0.005)  # 0.4996
    assert cundall_waves < 0.1 * free_waves and mean_waves < 0.1 * free_waves


def test_at_rest_both_dampings_settle_the_block():
    _, free = slide(0.0, 0.0, None)
    _, cundall = slide(0.0, 0.3, None)
    _, mean = slide(0.0, 0.3, 0.1)
    assert cundall < 1e-3 * free and mean < 1e-3 * free  # 6e-6 and 2e-4 of it
