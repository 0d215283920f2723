"""ParaView's own XDMF readers open what we write (skipped where ParaView is not installed)."""

import shutil
import subprocess

import pytest
from mpi4py import MPI
from test_io import small_run

SCRIPT = """
import sys
from paraview.simple import XDMFReader, Xdmf3ReaderS
for name in ("particles.xdmf", "grid.xdmf"):
    path = sys.argv[1] + "/" + name
    for reader in (XDMFReader(FileNames=[path]), Xdmf3ReaderS(FileName=[path])):
        times = reader.TimestepValues
        reader.UpdatePipeline(max(times))
        info = reader.GetDataInformation()
        assert info.GetNumberOfPoints() > 0, path
        assert "velocity" in reader.PointData.keys(), path
        print(name, len(times), info.GetNumberOfPoints())
"""


@pytest.mark.skipif(shutil.which("pvpython") is None, reason="ParaView (pvpython) not installed")
@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="serial check")
def test_paraview_reads_particle_and_grid_series(tmp_path):
    small_run(tmp_path, 0.03)
    script = tmp_path / "check.py"
    script.write_text(SCRIPT)
    r = subprocess.run(["pvpython", str(script), str(tmp_path)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    assert r.stdout.count("particles.xdmf 4") == 2 and r.stdout.count("grid.xdmf 4") == 2, r.stdout
