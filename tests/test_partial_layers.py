"""Partial cell layers along flat faces (engine/staggered/flat_layers.py, layers.py).

The bundled cantilever (1 x 0.2 x 0.2 m) at grid.resolution 32 has h = 1/32 m, so its 0.2 m width is
6.4 cells, centred in 7: both outer layers across y and z hold fill 0.7, which stiffens bending by
about 6 * 2 * 0.7 * 0.3 / 6.4^2 = 6.15%. Where the layers' lines along the bar end on a held face and
a loaded one (the example: clamp and tip traction) the method moves the layers' weights to the
solid's first moments; where one end is free (gravity alone) it says so instead."""

import json
import re
from pathlib import Path

import pytest
import trimesh

from engine.geometry.cache import GeometryCache
from engine.pipeline import run

ROOT = Path(__file__).resolve().parents[1]
STL = ROOT / "examples" / "cantilever.stl"


def cantilever(grid: dict, mesh=STL, tip_load: bool = True, load_from: float = 1.0):
    spec = json.loads((ROOT / "examples" / "cantilever.json").read_text())
    spec["grid"] = grid
    spec["boundaries"][1]["region"] = {"box": [[load_from, -1, -1], [2, 1, 1]]}
    if not tip_load:
        spec["boundaries"] = spec["boundaries"][:1]
    spec["output"] = {"fields": ["displacement"], "probes": [[1.0, 0, 0]], "surface": False}
    return run(spec, mesh, cache=GeometryCache(None))


def layer_warnings(result) -> list[str]:
    return [w for w in result.solver.warnings if "cell layers" in w]


def test_layers_ending_on_a_free_face_are_estimated_from_their_fill_and_thickness():
    (warning,) = layer_warnings(cantilever({"resolution": 32, "padding": 1}, tip_load=False))
    fill = 1 - (7 - 0.2 * 32) / 2
    expected = 6 * 2 * fill * (1 - fill) / (0.2 * 32) ** 2
    stated = float(re.search(r"about ([0-9.]+)% too stiff", warning).group(1)) / 100
    assert stated == pytest.approx(expected, abs=0.0005), warning
    assert "fill 0.70" in warning and "6.4 cells thick" in warning
    size = float(re.search(r"grid.cell_size ([0-9.]+) m", warning).group(1))
    assert 0.2 / size == pytest.approx(7, abs=1e-3)  # the next cell size below h that divides the width


def test_the_suggested_cell_size_and_whole_layers_draw_no_warning():
    assert layer_warnings(cantilever({"cell_size": 0.2 / 7, "padding": 1}, tip_load=False)) == []
    assert layer_warnings(cantilever({"resolution": 20, "padding": 1}, tip_load=False)) == []  # 4.0 cells


def test_held_and_loaded_layers_are_corrected_toward_whole_layers():
    # the tip at resolution 32 (partial layers of fill 0.7) against resolution 35 (whole layers, 7 cells
    # across, no cut cell): 3.95% apart with the layers weighed at their cell centres (-0.038640 against
    # -0.040229 m), 0.32% with their weights moved; and no warning, the layers being corrected
    partial = cantilever({"resolution": 32, "padding": 1})
    whole = cantilever({"resolution": 35, "padding": 1})
    assert layer_warnings(partial) == [] and layer_warnings(whole) == []
    tip = lambda r: r.fields.probes["displacement"][0][2]  # noqa: E731
    assert abs(tip(partial) / tip(whole) - 1) < 0.01, (tip(partial), tip(whole))


def test_a_curved_surface_draws_no_layer_warning(tmp_path):
    path = tmp_path / "ball.stl"
    trimesh.creation.icosphere(subdivisions=4, radius=0.1).apply_translation([0.1, 0, 0]).export(path)
    assert layer_warnings(cantilever({"cell_size": 0.01, "padding": 1}, path, load_from=0.15)) == []
