"""XDMF output read back with an independent reader (meshio) and checked value by value."""

import xml.etree.ElementTree as ET

import h5py
import meshio
import numpy as np
import pytest
from conftest import rectangle
from mpi4py import MPI

import dolfin_mpm as dm
from dolfin_mpm.materials.tensor import invariants


def small_run(tmp_path, t_end, nan_at=None):
    grid = dm.Grid(rectangle((0, 0), (1, 1), (6, 6)))
    mat = dm.LinearElastic(E=1e4, nu=0.3, rho=100.0)
    P = dm.seed(grid, mat, ppc=4, where=lambda x: x[1] < 0.5)
    bottom = dm.FixedBC(grid.nodes_where(lambda x: np.isclose(x[1], 0.0)))
    solver = dm.Solver(grid, P, mat, bcs=[bottom], gravity=(0, -9.81), dt=1e-3)
    with dm.Output(tmp_path, MPI.COMM_WORLD) as out:
        if nan_at is not None:
            solver.run(nan_at, output=out, output_interval=0.01, progress=False)
            P.v[3, 0] = np.inf
        solver.run(t_end, output=out, output_interval=0.01, progress=False)
    return solver


def test_particle_and_grid_series_read_back(tmp_path):
    solver = small_run(tmp_path, 0.05)
    P, grid = solver.particles, solver.grid
    if MPI.COMM_WORLD.rank != 0:
        return
    with meshio.xdmf.TimeSeriesReader(tmp_path / "particles.xdmf") as reader:
        points, cells = reader.read_points_cells()
        assert cells[0].type == "vertex" and len(points) == len(P)
        assert reader.num_steps == 6
        t, data, _ = reader.read_data(reader.num_steps - 1)
    assert t == pytest.approx(solver.time)
    order = np.argsort(data["id"])
    assert np.allclose(data["velocity"][order, :2], P.v[np.argsort(P.id)])
    p, _ = invariants(P.sigma)
    assert np.allclose(data["p"][order], p[np.argsort(P.id)])
    assert np.allclose(data["stress"][order].reshape(-1, 3, 3), P.sigma[np.argsort(P.id)])
    # The moving geometry of the last step (meshio reads only the first, so read it directly).
    root = ET.parse(tmp_path / "particles.xdmf").getroot()
    last = root.findall(".//Grid[@GridType='Uniform']")[-1]
    h5name, path = last.find("Geometry/DataItem").text.split(":")
    with h5py.File(tmp_path / h5name) as f:
        assert np.allclose(f[path][()][order], P.x[np.argsort(P.id)])

    with meshio.xdmf.TimeSeriesReader(tmp_path / "grid.xdmf") as reader:
        points, cells = reader.read_points_cells()
        assert cells[0].type == "triangle" and len(cells[0].data) == grid.num_cells
        t, data, _ = reader.read_data(reader.num_steps - 1)
    assert data["mass"].sum() == pytest.approx(solver.total_mass(), rel=1e-12)
    # Nodal values sit on the right points: compare with the grid's own node coordinates.
    lookup = {tuple(np.round(x[:2], 12)): i for i, x in enumerate(grid.node_x)}
    idx = [lookup[tuple(np.round(x[:2], 12))] for x in points]
    assert np.allclose(data["velocity"][:, :2], grid.velocity.x.array.reshape(-1, 2)[idx])


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
def test_failed_run_leaves_readable_files(tmp_path):
    with pytest.raises(dm.SimulationError, match="non-finite"):
        small_run(tmp_path, 0.05, nan_at=0.02)
    if MPI.COMM_WORLD.rank != 0:
        return
    with meshio.xdmf.TimeSeriesReader(tmp_path / "particles.xdmf") as reader:
        reader.read_points_cells()
        assert reader.num_steps == 3  # t = 0, 0.01, 0.02; the bad step wrote nothing
        for k in range(reader.num_steps):
            _, data, _ = reader.read_data(k)
            assert np.all(np.isfinite(data["velocity"]))


def test_an_extended_series_drops_later_times_and_what_a_stopped_write_left(tmp_path):
    """The times after ``after`` and a group written but never listed (a run killed between the
    HDF5 flush and the XDMF rename) are gone; new times get their own data."""
    from dolfin_mpm.io.xdmf import XDMFSeries

    path, cells = tmp_path / "s.xdmf", np.arange(3, dtype=np.int32).reshape(-1, 1)
    series = XDMFSeries(path)
    for k in range(3):
        series.write(0.1 * k, np.full((3, 3), float(k)), cells, "Polyvertex", {"p": np.full(3, float(k))})
    series.h5.create_dataset("step3/p", data=np.zeros(5))  # orphaned: the XDMF never listed it
    series.close()
    series = XDMFSeries(path, after=0.1)
    assert series.count == 2 and series.last_time == 0.1 and sorted(series.h5) == ["step0", "step1"]
    series.write(0.15, np.full((3, 3), 7.0), cells, "Polyvertex", {"p": np.full(3, 7.0)})
    series.close()
    with meshio.xdmf.TimeSeriesReader(path) as reader:
        reader.read_points_cells()
        times = [reader.read_data(k)[0] for k in range(reader.num_steps)]
        _, data, _ = reader.read_data(2)
    assert times == [0.0, 0.1, 0.15] and np.array_equal(data["p"], np.full(3, 7.0))
    with pytest.raises(ValueError, match="not a time series to extend"):
        path.write_text("<Xdmf><Domain/></Xdmf>")
        XDMFSeries(path, after=0.1)
