"""Renders the damage map of a run with ParaView: the material points at one output time, warped by their
displacement, coloured by damage, with the time in a corner; saves a PNG.

Usage: pvpython render_damage.py RUN_DIR/fields.xdmf OUT.png [--time T] [--warp FACTOR] [--size W H]

  --time T       time to show (s; default: the last output step; the nearest output step is shown)
  --warp FACTOR  displacement magnification (default 10)
  --size W H     image size in pixels (default 1000 800)

Needs an X display; on a headless machine:
  xvfb-run -a -s "-noreset -screen 0 1280x1024x24" pvpython tools/paraview/render_damage.py ...
The steps are those of ParaView's GUI (docs/paraview.md), so the script doubles as a recipe.
"""

import argparse
import math

from paraview.simple import (
    AnnotateTimeFilter,
    ColorBy,
    CreateView,
    GetColorTransferFunction,
    GetScalarBar,
    OpenDataFile,
    Render,
    ResetCamera,
    SaveScreenshot,
    Show,
    WarpByVector,
)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("xdmf")
    parser.add_argument("png")
    parser.add_argument("--time", type=float, help="time to show (s); default the last output step")
    parser.add_argument("--warp", type=float, default=10.0, help="displacement magnification")
    parser.add_argument("--size", type=int, nargs=2, default=[1000, 800], metavar=("W", "H"))
    args = parser.parse_args()

    fields = OpenDataFile(args.xdmf)
    fields.UpdatePipelineInformation()
    times = fields.TimestepValues  # a list, or a bare number for a single time step
    times = list(times) if hasattr(times, "__len__") else [times]
    time = times[-1] if args.time is None else min(times, key=lambda t: abs(t - args.time))
    fields.UpdatePipeline(time)

    # Material points drawn as discs whose radius matches the point spacing (mm): the spacing from the
    # bounding box and the number of points (the notch and the plates make it slightly too large).
    info = fields.GetDataInformation()
    x0, x1, y0, y1, _, _ = info.GetBounds()
    spacing = math.sqrt((x1 - x0) * (y1 - y0) / info.GetNumberOfPoints())

    warped = WarpByVector(Input=fields)
    warped.Vectors = ["POINTS", "displacement"]
    warped.ScaleFactor = args.warp

    view = CreateView("RenderView")
    view.ViewSize = args.size
    view.ViewTime = time
    view.OrientationAxesVisibility = 0
    if hasattr(view, "UseColorPaletteForBackground"):
        view.UseColorPaletteForBackground = 0
    view.Background = [1.0, 1.0, 1.0]

    points = Show(warped, view)
    points.SetRepresentationType("Point Gaussian")
    points.ShaderPreset = "Plain circle"
    points.GaussianRadius = 0.7 * spacing
    ColorBy(points, ("POINTS", "damage"))
    damage = GetColorTransferFunction("damage")
    damage.ApplyPreset("Viridis (matplotlib)", True)
    damage.RescaleTransferFunction(0.0, 1.0)
    damage.AutomaticRescaleRangeMode = "Never"
    points.SetScalarBarVisibility(view, True)
    bar = GetScalarBar(damage, view)
    bar.Title = "damage (-)"
    bar.RangeLabelFormat = "%.1f"
    bar.ComponentTitle = ""
    bar.TitleColor = [0.0, 0.0, 0.0]
    bar.LabelColor = [0.0, 0.0, 0.0]
    bar.TitleFontSize = 20
    bar.LabelFontSize = 18

    label = AnnotateTimeFilter(Input=fields)
    label.Format = "t = {time:.1f} us, displacements x " + f"{args.warp:g}"
    label.Scale = 1.0e6
    text = Show(label, view)
    text.WindowLocation = "Upper Left Corner"
    text.FontSize = 22
    text.Color = [0.0, 0.0, 0.0]

    view.InteractionMode = "2D"
    ResetCamera(view)
    Render(view)
    SaveScreenshot(args.png, view, ImageResolution=args.size, TransparentBackground=0)
    print(f"render_damage: {args.png}: t = {time:g} s, {info.GetNumberOfPoints()} points")


if __name__ == "__main__":
    main()
