"""Open a run's particle and grid XDMF series with ParaView's readers and render one moment.

Run with ParaView's Python (``pvbatch``, which needs an X display: ``xvfb-run`` gives one):

    pvbatch scripts/paraview_render.py RUN_DIR OUT.png [--time 0.25] [--field eps_vp_rate_nonlocal]

Both series are read with both of ParaView's XDMF readers (``XDMFReader``, ``Xdmf3ReaderS``); the
script exits with an error if a file cannot be read, has no points or lacks the field, and
otherwise renders the particles coloured by the field over the grid's wireframe at the output
time nearest ``--time`` [s].
"""

import argparse
import sys
from pathlib import Path

from paraview.simple import (
    ColorBy,
    CreateView,
    GetColorTransferFunction,
    GetScalarBar,
    Render,
    SaveScreenshot,
    Show,
    Xdmf3ReaderS,
    XDMFReader,
)


def read(path: Path, field: str):
    """The series at ``path`` through both readers; checks points and ``field`` on each."""
    if not path.exists():
        sys.exit(f"{path}: no such file")
    readers = (XDMFReader(FileNames=[str(path)]), Xdmf3ReaderS(FileName=[str(path)]))
    for reader in readers:
        times = reader.TimestepValues
        reader.UpdatePipeline(max(times) if times else 0.0)
        points = reader.GetDataInformation().GetNumberOfPoints()
        if points == 0 or field not in reader.PointData.keys():
            name, fields = type(reader).__name__, reader.PointData.keys()
            sys.exit(f"{path}: {name} read {points} points, fields {fields}")
        print(f"{path.name}: {type(reader).__name__}, {len(times)} times, {points} points")
    return readers[0]


def main():
    """Read both series, render the chosen moment."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path, help="folder with particles.xdmf and grid.xdmf")
    parser.add_argument("png", type=Path)
    parser.add_argument("--time", type=float, default=0.25, help="output time to render [s]")
    parser.add_argument("--field", default="eps_vp_rate_nonlocal", help="particle field to colour by")
    parser.add_argument("--label", default="non-local rate [1/s]", help="colour bar title")
    args = parser.parse_args()

    particles = read(args.run / "particles.xdmf", args.field)
    grid = read(args.run / "grid.xdmf", "velocity")
    times = particles.TimestepValues
    time = min(times, key=lambda t: abs(t - args.time))

    view = CreateView("RenderView")
    view.ViewSize = [700, 1000]
    view.OrientationAxesVisibility = 0
    view.UseColorPaletteForBackground = 0
    view.Background = [1.0, 1.0, 1.0]
    view.ViewTime = time
    mesh = Show(grid, view)
    ColorBy(mesh, None)
    mesh.SetRepresentationType("Wireframe")
    mesh.AmbientColor = mesh.DiffuseColor = [0.75, 0.75, 0.75]
    mesh.Position = [0.0, 0.0, -1e-3]  # behind the particles
    points = Show(particles, view)
    points.SetRepresentationType("Points")
    points.PointSize = 4.0
    ColorBy(points, ("POINTS", args.field))
    points.RescaleTransferFunctionToDataRange(False, True)
    lut = GetColorTransferFunction(args.field)
    lut.ApplyPreset("Inferno (matplotlib)", True)
    points.SetScalarBarVisibility(view, True)
    bar = GetScalarBar(lut, view)
    bar.Title, bar.ComponentTitle = args.label, ""
    bar.TitleColor = bar.LabelColor = [0.0, 0.0, 0.0]
    view.InteractionMode = "2D"
    view.ResetCamera()
    view.CameraParallelScale *= 0.62  # the data fill the height, with room for the colour bar
    Render(view)
    args.png.parent.mkdir(parents=True, exist_ok=True)
    SaveScreenshot(str(args.png), view)
    print(f"wrote {args.png} (t = {time:.4f} s, {args.field})")


if __name__ == "__main__":
    main()
