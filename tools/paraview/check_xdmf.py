"""Checks that ParaView shows a run's point fields the way a user opens them.

Usage: pvpython check_xdmf.py RUN_DIR/fields.xdmf [SCREENSHOT.png]

Opens the file with OpenDataFile (the reader ParaView picks for File > Open), then at the last time step
checks that there is one cell per point (a point cloud without cells draws nothing in the default Surface
representation), that the `damage` array is there, that displacement and velocity have 3 components and
that a screenshot with the default representation, coloured by damage, is not blank. Exits 1 with a
message when a check fails. SCREENSHOT.png keeps the screenshot.

Needs an X display; on a headless machine (as .ci/run does):
  xvfb-run -a -s "-noreset -screen 0 1280x1024x24" pvpython tools/paraview/check_xdmf.py ...
"""

import os
import sys
import tempfile

from paraview.simple import (
    ColorBy,
    CreateView,
    OpenDataFile,
    Render,
    ResetCamera,
    SaveScreenshot,
    Show,
)
from vtkmodules.util.numpy_support import vtk_to_numpy
from vtkmodules.vtkIOImage import vtkPNGReader

# Background colour of the check's render view (RGB in 0..1) and the share of the image (-) that must differ
# from it.
BACKGROUND = [0.0, 0.0, 0.0]
MIN_DRAWN_SHARE = 0.01


def fail(message):
    print(f"check_xdmf: FAILED: {message}", file=sys.stderr)
    sys.exit(1)


def main():
    if len(sys.argv) not in (2, 3):
        fail("usage: pvpython check_xdmf.py FIELDS.xdmf [SCREENSHOT.png]")
    path = sys.argv[1]
    if not os.path.isfile(path):
        fail(f"{path}: no such file")
    reader = OpenDataFile(path)
    if reader is None:
        fail(f"{path}: ParaView has no reader for it")
    reader.UpdatePipelineInformation()
    # A list, or a bare number for a single time step.
    times = reader.TimestepValues
    times = list(times) if hasattr(times, "__len__") else [times]
    if not times:
        fail(f"{path}: no time steps")
    last = times[-1]
    reader.UpdatePipeline(last)
    info = reader.GetDataInformation()
    points = info.GetNumberOfPoints()
    cells = info.GetNumberOfCells()
    arrays = list(reader.PointData.keys())
    print(
        f"check_xdmf: {path}: reader {reader.GetXMLName()}, {len(times)} time steps, at t = {last:g} s: "
        f"{points} points, {cells} cells, point arrays {arrays}"
    )
    if points == 0:
        fail("no points")
    if cells != points:
        fail(f"{cells} cells for {points} points: the default representation draws nothing without cells")
    if "damage" not in arrays:
        fail("no `damage` point array at the last time step")
    for name in ("displacement", "velocity"):
        if name in arrays and reader.PointData[name].GetNumberOfComponents() != 3:
            fail(f"`{name}` has {reader.PointData[name].GetNumberOfComponents()} components, expected 3")

    if len(sys.argv) == 3:
        check_screenshot(reader, last, sys.argv[2])
    else:
        with tempfile.TemporaryDirectory(prefix="check_xdmf-") as tmp:
            check_screenshot(reader, last, os.path.join(tmp, "screenshot.png"))
    print("check_xdmf: ok")


def check_screenshot(reader, time, png):
    """Renders `reader` at `time` (s) with the default representation, coloured by damage, into `png` and
    fails when the image is all background."""
    view = CreateView("RenderView")
    view.ViewSize = [400, 300]
    view.OrientationAxesVisibility = 0
    if hasattr(view, "UseColorPaletteForBackground"):
        view.UseColorPaletteForBackground = 0
    view.Background = BACKGROUND
    view.ViewTime = time
    display = Show(reader, view)
    ColorBy(display, ("POINTS", "damage"))
    ResetCamera(view)
    Render(view)
    SaveScreenshot(png, view, ImageResolution=[400, 300], TransparentBackground=0)

    image = vtkPNGReader()
    image.SetFileName(png)
    image.Update()
    pixels = vtk_to_numpy(image.GetOutput().GetPointData().GetScalars())[:, :3].astype(int)
    background = [round(255 * c) for c in BACKGROUND]
    drawn = (abs(pixels - background).max(axis=1) > 8).mean()
    print(f"check_xdmf: {display.Representation} representation, {100 * drawn:.1f} % of the pixels drawn")
    if drawn < MIN_DRAWN_SHARE:
        fail(
            f"the screenshot is blank ({100 * drawn:.2f} % of the pixels differ from the background; "
            "pass SCREENSHOT.png to keep it)"
        )


if __name__ == "__main__":
    main()
