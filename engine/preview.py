"""A picture of a result: the deformed surface coloured by von Mises stress (or displacement
magnitude), with a colour bar and the undeformed outline, rendered off screen to PNG.

Headless: no display and no GPU. VTK renders through EGL (Mesa's software rasteriser, Debian's
libegl1 + libgl1-mesa-dri) when no X display is set, else through whatever it finds.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

# The deformation is drawn magnified when it would be hard to see: at most this fraction of the
# object's size (a magnification is written on the picture).
_VISIBLE = 0.08
_SIZE = (960, 600)  # pixels


def _field(surface, names) -> tuple[str, np.ndarray, str] | None:
    """(array name, values, bar title) to colour by: von Mises, else displacement magnitude."""
    if "von_mises" in names:
        return "von_mises", np.asarray(surface.point_data["von_mises"]), "von Mises stress [Pa]"
    if "displacement" in names:
        u = np.asarray(surface.point_data["displacement"])
        return "|u|", np.linalg.norm(u, axis=1), "displacement [m]"
    return None


def render_preview(result, path: str | os.PathLike, *, step: int | None = None,
                   size: tuple[int, int] = _SIZE) -> Path:
    """Render ``result`` (an ``engine.output.Result`` with a surface) to the PNG file ``path``.

    The final state, or ``steps[step]``. Raises ValueError when the result has no surface (the
    job's ``output.surface`` was false) -- there is nothing to draw then.
    """
    if not os.environ.get("DISPLAY"):  # no X server: go straight to EGL, without X's warnings
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    import pyvista as pv

    blocks = result.to_pyvista(step)
    if "surface" not in blocks.keys():
        raise ValueError("output.surface: the result has no surface to draw (set output.surface to true)")
    surface = blocks["surface"]
    outline = surface.copy()
    colour = _field(surface, surface.point_data.keys())
    u = np.nan_to_num(np.asarray(surface.point_data["displacement"])) if "displacement" in surface.point_data.keys() \
        else np.zeros((surface.n_points, 3))
    size_m = float(np.linalg.norm(np.ptp(np.asarray(outline.points), axis=0))) or 1.0
    largest = float(np.abs(u).max()) if u.size else 0.0
    scale = 1.0 if largest == 0.0 or largest >= _VISIBLE * size_m else _VISIBLE * size_m / largest
    deformed = surface.copy()
    deformed.points = np.asarray(surface.points) + scale * u
    plotter = pv.Plotter(off_screen=True, window_size=list(size))
    plotter.set_background("white")
    two_d = result.dim == 2
    if colour is not None:
        name, values, title = colour
        deformed.point_data[name] = np.nan_to_num(values)
        plotter.add_mesh(deformed, scalars=name, cmap="viridis", line_width=4 if two_d else 1,
                         scalar_bar_args={"title": title, "color": "black", "fmt": "%.3g", "vertical": True,
                                          "position_x": 0.86, "position_y": 0.1, "height": 0.8, "width": 0.06})
    else:
        plotter.add_mesh(deformed, color="steelblue")
    edges = outline if two_d else outline.extract_feature_edges(boundary_edges=True, feature_edges=True,
                                                                 manifold_edges=False, non_manifold_edges=False)
    plotter.add_mesh(edges, color="dimgray", line_width=2, opacity=0.8)
    label = "deformed (displacement x%.3g), undeformed outline in grey" % scale if scale != 1.0 \
        else "deformed, undeformed outline in grey"
    plotter.add_text(label, position="upper_left", font_size=10, color="black")
    if two_d:
        plotter.view_xy()
    else:
        plotter.view_isometric()
    plotter.camera.zoom(0.9)
    path = Path(path)
    plotter.screenshot(str(path))
    plotter.close()
    return path


def main(argv: list[str] | None = None) -> int:
    """``python -m engine.preview RESULT.h5 PICTURE.png``: the picture of a stored result (what the
    service runs in a child process, so that VTK never loads into the API process). Exit 2 with one
    line on stderr when the result cannot be read or has no surface."""
    import sys

    from .errors import ResultFormatError
    from .output import read_result

    args = sys.argv[1:] if argv is None else argv
    if len(args) != 2:
        print("usage: python -m engine.preview RESULT.h5 PICTURE.png", file=sys.stderr)
        return 2
    try:
        render_preview(read_result(args[0]), args[1])
    except (ResultFormatError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
