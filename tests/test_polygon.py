"""Planar solids from vertex loops and SVG/DXF drawings (engine.geometry.polygon)."""

from __future__ import annotations

import io

import numpy as np
import pytest
import trimesh
from trimesh.path.exchange.dxf import export_dxf

from engine.errors import GeometryError
from engine.geometry.loading import load_surface
from engine.geometry.polygon import polygon_surface
from engine.geometry.winding import winding_number


def _loop_area(vertices: np.ndarray, segments: np.ndarray) -> float:
    p = vertices[segments]
    return float((p[:, 0, 0] * p[:, 1, 1] - p[:, 1, 0] * p[:, 0, 1]).sum() / 2.0)


def test_polygon_with_a_hole_is_oriented():
    outer = [[0, 0], [0, 4], [4, 4], [4, 0]]  # clockwise: must be reversed
    hole = [[1, 1], [3, 1], [3, 3], [1, 3]]  # counter-clockwise: must be reversed
    island = [[1.5, 1.5], [2.5, 1.5], [2.5, 2.5], [1.5, 2.5], [1.5, 1.5]]  # closing point repeated
    surface = polygon_surface([outer, hole, island])
    assert surface.warnings == []  # nesting decides each loop's role: reversing is bookkeeping
    assert surface.enclosed_volume() == 16.0 - 4.0 + 1.0
    # Vertex order kept; the island's repeated closing point dropped.
    np.testing.assert_array_equal(surface.vertices[:8], np.array(outer + hole, dtype=float))
    assert len(surface.vertices) == 12
    assert _loop_area(surface.vertices, surface.faces[:4]) == 16.0
    assert _loop_area(surface.vertices, surface.faces[4:8]) == -4.0
    assert _loop_area(surface.vertices, surface.faces[8:]) == 1.0
    probes = np.array([[0.5, 0.5], [1.2, 2.0], [2.0, 2.0], [5.0, 0.0]])
    w = winding_number(surface.vertices, surface.faces, probes)
    np.testing.assert_allclose(w, [1, 0, 1, 0], atol=1e-14)


def test_polygon_placement_and_errors():
    square = [[0, 0], [1, 0], [1, 1], [0, 1]]
    turn = np.array([[0.0, -1.0, 3.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    surface = polygon_surface([square], scale=2.0, transform=turn)
    assert surface.warnings == [] and surface.enclosed_volume() == 4.0
    np.testing.assert_array_equal(surface.bounds[0], [1.0, 0.0])
    with pytest.raises(GeometryError, match="loops 0 and 1 cross each other"):
        polygon_surface([square, [[0.5, 0.5], [2, 0.5], [2, 2], [0.5, 2]]])
    with pytest.raises(GeometryError, match="loop 0 is not a simple closed curve"):
        polygon_surface([[[0, 0], [2, 2], [2, 0], [0, 1]]])
    with pytest.raises(GeometryError, match=r"loop 0 encloses no area \(3 distinct points\)"):
        polygon_surface([[[0, 0], [1, 1], [2, 2]]])
    with pytest.raises(GeometryError, match=r"loop 1 encloses no area \(1 distinct points\)"):
        polygon_surface([square, [[0.5, 0.5]] * 5])
    # shapely's reason in words ('Self-intersection[0.5 0.5]' before), at the point where the loop was
    # drawn: placed 10x larger and turned, the crossing below is still named at (0.666667, 0.666667)
    bowtie = r"loop 0 is not a simple closed curve: it crosses itself at \(0\.5, 0\.5\)$"
    with pytest.raises(GeometryError, match=bowtie):
        polygon_surface([[[0, 0], [1, 1], [1, 0], [0, 1]]])  # a bowtie: its lobes' areas cancel
    crossing = r"^polygon 'polygon': loop 0 is not a simple closed curve: it crosses itself at \(0\.666667, 0\.666667\)"
    with pytest.raises(GeometryError, match=crossing):
        polygon_surface([[[0, 0], [2, 2], [2, 0], [0, 1]]], scale=10.0, transform=turn)
    with pytest.raises(GeometryError, match=r"loop 0 is not a simple closed curve: it touches itself at \(1, 2\)"):
        polygon_surface([[[0, 0], [2, 0], [2, 2], [1, 2], [1, 1], [1, 2], [0, 2]]])  # a slit down to (1, 1)
    with pytest.raises(GeometryError, match="loop 1 has 1 points with non-finite"):
        polygon_surface([square, [[0.2, 0.2], [0.4, np.nan], [0.3, 0.4]]])


# The hole is a subpath of the plate's path, drawn in the same direction: evenodd makes it a hole.
_SVG = """<svg xmlns="http://www.w3.org/2000/svg" width="10" height="10">
<path fill-rule="evenodd" d="M 0 0 L 4 0 L 4 3 L 0 3 Z M 1 1.5 A 1 1 0 1 0 3 1.5 A 1 1 0 1 0 1 1.5 Z"/>
<path d="M 6 6 L 7 7"/>
</svg>"""


@pytest.mark.parametrize("file_type", ["svg", "dxf"])
def test_drawing_with_rectangle_and_circular_hole(tmp_path, file_type):
    data = _SVG.encode()
    if file_type == "dxf":
        data = export_dxf(trimesh.load_path(io.BytesIO(data), file_type="svg")).encode()
    path = tmp_path / f"plate.{file_type}"
    path.write_bytes(data)
    surface = load_surface(path, dimension=2)
    circle = surface.faces[4:]
    n = len(circle)
    # The circle is a regular polygon inscribed in radius 1: its area is n/2 sin(2 pi / n).
    assert _loop_area(surface.vertices, circle) == pytest.approx(-n / 2 * np.sin(2 * np.pi / n), rel=1e-12)
    assert surface.enclosed_volume() == pytest.approx(12.0 - n / 2 * np.sin(2 * np.pi / n), rel=1e-13)
    assert 12.0 - np.pi < surface.enclosed_volume() < 12.0 - np.pi + np.pi * (2 * np.pi / n) ** 2 / 6
    assert surface.warnings == ["ignored 1 open curves of the drawing"]


# --- SVG fill rules (engine.geometry.svg) ---------------------------------------------------------


def _svg(body: str) -> bytes:
    return f'<svg xmlns="http://www.w3.org/2000/svg">{body}</svg>'.encode()


def test_a_hole_drawn_as_a_subpath_needs_no_warning():
    surface = load_surface(_svg('<path fill-rule="evenodd" d="M0 0 H100 V20 H0 Z M40 5 H60 V15 H40 Z"/>'),
                           filename="hole.svg", dimension=2, scale=0.01)
    assert surface.warnings == []
    assert surface.enclosed_volume() == pytest.approx(0.18, rel=1e-12)


def test_the_nonzero_rule_fills_a_same_direction_subpath_and_holes_one_drawn_the_other_way():
    same = load_surface(_svg('<path d="M0 0 H100 V20 H0 Z M40 5 H60 V15 H40 Z"/>'), filename="a.svg", dimension=2)
    opposite = load_surface(_svg('<path d="M0 0 H100 V20 H0 Z M40 5 V15 H60 V5 Z"/>'), filename="b.svg", dimension=2)
    assert same.enclosed_volume() == pytest.approx(2000.0, rel=1e-12) and same.warnings == []
    assert opposite.enclosed_volume() == pytest.approx(1800.0, rel=1e-12) and opposite.warnings == []


def test_a_circle_drawn_over_a_rectangle_is_filled_and_the_union_is_named():
    surface = load_surface(_svg('<rect x="0" y="0" width="100" height="20"/><circle cx="50" cy="10" r="5"/>'),
                           filename="circle.svg", dimension=2, scale=0.01)
    assert surface.enclosed_volume() == pytest.approx(0.2, rel=1e-12)
    (warning,) = surface.warnings
    assert warning.startswith("united 2 overlapping filled shapes of the drawing (overlap area 0.00784")
    assert warning.endswith("-> 0.2 m^2); a hole must be a subpath of its outline's path (fill-rule evenodd, or drawn"
                            " in the opposite direction)")


def test_overlapping_filled_shapes_are_united():
    surface = load_surface(_svg('<rect x="0" y="0" width="100" height="20"/><rect x="40" y="-20" width="20" height="60"/>'),
                           filename="cross.svg", dimension=2, scale=0.01)
    assert surface.enclosed_volume() == pytest.approx(0.28, rel=1e-12)
    assert surface.warnings == ["united 2 overlapping filled shapes of the drawing (overlap area 0.04 m^2; area 0.32 ->"
                                " 0.28 m^2); a hole must be a subpath of its outline's path (fill-rule evenodd, or"
                                " drawn in the opposite direction)"]
    probes = np.array([[0.5, 0.3], [0.1, 0.1], [0.5, 0.1], [0.1, 0.3]])
    np.testing.assert_allclose(winding_number(surface.vertices, surface.faces, probes), [1, 1, 1, 0], atol=1e-12)


def test_unfilled_outlines_nest_as_in_a_dxf():
    surface = load_surface(_svg('<g fill="none" stroke="black"><rect x="0" y="0" width="100" height="20"/>'
                                '<rect x="40" y="5" width="20" height="10"/></g>'), filename="o.svg", dimension=2)
    assert surface.enclosed_volume() == pytest.approx(1800.0, rel=1e-12) and surface.warnings == []


def test_text_is_ignored_with_one_note():
    surface = load_surface(_svg('<rect x="0" y="0" width="100" height="20"/><text x="10" y="50">A</text>'
                                '<text x="10" y="80">B</text>'), filename="t.svg", dimension=2)
    assert surface.warnings == ["ignored 2 text elements of the drawing: convert text to paths in the drawing program"
                                " to include it"]
