"""Pipeline stages: geometry from a spec, limits checked before work, cache by content hash."""

import json
from pathlib import Path

import h5py
import numpy as np
import pytest

from engine.errors import GeometryError, GridError, MethodUnavailableError
from engine.geometry.cache import GeometryCache
from engine.grid import make_grid
from engine.output import write_result
from engine.pipeline import Limits, prepare_geometry, run
from schemas import SpecError, parse_job

ROOT = Path(__file__).resolve().parents[1]


def cantilever_spec(**grid):
    spec = json.loads((ROOT / "examples" / "cantilever.json").read_text())
    if grid:
        spec["grid"] = grid
    return parse_job(spec)


def test_geometry_stages_from_bytes_and_cache_hit(tmp_path):
    spec = cantilever_spec(resolution=16)
    data = (ROOT / "examples" / "cantilever.stl").read_bytes()
    cache = GeometryCache(tmp_path / "cache")
    first = prepare_geometry(spec, data, filename="cantilever.stl", cache=cache)
    assert not first.cache_hit
    assert abs(first.fractions.solid_volume() - 0.04) < 1e-14
    second = prepare_geometry(spec, data, filename="cantilever.stl", cache=cache)
    assert second.cache_hit
    np.testing.assert_array_equal(second.fractions.dense(), first.fractions.dense())
    # a different grid is a different key
    third = prepare_geometry(cantilever_spec(resolution=12), data, filename="cantilever.stl", cache=cache)
    assert not third.cache_hit


def test_limits_are_checked_before_any_work(tmp_path):
    spec = cantilever_spec(resolution=64)
    data = (ROOT / "examples" / "cantilever.stl").read_bytes()
    with pytest.raises(GridError, match=r"exceeds the limit of 1000"):
        prepare_geometry(spec, data, filename="c.stl", cache=GeometryCache(None), limits=Limits(max_cells=1000))
    with pytest.raises(GridError, match=r"GiB for method 'staggered', over the limit"):
        prepare_geometry(spec, data, filename="c.stl", cache=GeometryCache(None), limits=Limits(max_memory_bytes=10**6))
    with pytest.raises(GeometryError, match=r"12 facets exceed the limit of 10"):
        prepare_geometry(spec, data, filename="c.stl", cache=GeometryCache(None), limits=Limits(max_triangles=10))
    # a 401-digit resolution is a grid error, not an OverflowError from the float division
    with pytest.raises(GridError, match=r"grid.resolution: 401 digits"):
        prepare_geometry(cantilever_spec(resolution=10**400), data, filename="c.stl", cache=GeometryCache(None))
    with pytest.raises(GridError, match=r"= 9e\+899 cells exceeds the limit"):  # the count is beyond a float
        make_grid((0, 0, 0), (1, 1, 1), cell_size=1e-300)


def test_polygon_spec_in_2d():
    spec = parse_job(
        {
            "dimension": 2,
            "geometry": {"polygon": [[[0, 0], [2, 0], [2, 1], [0, 1]], [[0.5, 0.25], [1.5, 0.25], [1.5, 0.75], [0.5, 0.75]]]},
            "grid": {"cell_size": 0.1},
            "material": {"youngs_modulus": 1.0, "poisson_ratio": 0.3},
        }
    )
    geo = prepare_geometry(spec, cache=GeometryCache(None))
    assert abs(geo.fractions.solid_volume() - 1.5) < 1e-13


def test_run_staggered_and_dg_end_to_end():
    # 6 cells across the 0.2 m section: at 3 the cut cells' bending stiffness is off by up to 30%
    # (each partial layer's strain is weighed at its cell centre)
    spec = cantilever_spec(resolution=32)
    result = run(spec, ROOT / "examples" / "cantilever.stl", cache=GeometryCache(None))
    tip = result.fields.probes["displacement"][0]
    # Euler-Bernoulli: gravity q L^4 / 8EI + tip load P L^3 / 3EI = 0.0368 + 0.0100 m (span 1 m),
    # 0.0384 m for the 0.95 m the clamp leaves (it holds the end face and 0.05 m of the sides)
    assert -0.05 < tip[2] < -0.035 and abs(tip[0]) < 1e-3 * abs(tip[2])
    assert result.solver.iterations > 0 and result.solver.residual <= 1e-8
    assert set(result.fields.cells) == {"displacement", "von_mises"}
    job = {**spec.model_dump(mode="json"), "method": {"kind": "dg", "degree": 2, "penalty": 10},
           "grid": {"resolution": 16, "padding": 1}}
    dg = run(parse_job(job), ROOT / "examples" / "cantilever.stl", cache=GeometryCache(None))
    tip_dg = dg.fields.probes["displacement"][0]
    # the same beam and clamp with k = 2 on a 16-cell grid: within 10% of the staggered 32-cell answer
    # (measured 3.5%)
    assert abs(tip_dg[2] - tip[2]) < 0.1 * abs(tip[2])
    assert dg.method == "dg" and dg.solver.residual < 1e-9  # direct solve, measured 4.1e-10 on this grid
    assert dg.fields.surface["displacement"].shape == (len(dg.surface_vertices), 3)
    assert np.all(np.isfinite(dg.fields.surface["displacement"]))


def test_the_engine_docstring_example_runs():
    """engine/__init__.py's tiny job (its expected values are plane-strain elasticity's, by hand)."""
    import doctest

    import engine

    failed, tried = doctest.testmod(engine, verbose=False)
    assert tried >= 3 and failed == 0


def test_dg_memory_is_checked_again_with_the_pieces_after_slicing():
    """Two plates closer than a cell: every cell of their layer holds two pieces (two elements), which
    the bound from the surface counts once; the check after slicing refuses what the bound let by."""
    import trimesh

    from engine.dg.problem import estimate_memory
    from engine.geometry.loading import load_surface
    from engine.geometry.occupancy import occupied_cells_bound
    from engine.grid import make_grid

    plates = [trimesh.creation.box(extents=(2.0, 2.0, 0.08)) for _ in range(2)]
    plates[0].apply_translation((0, 0, 0.11))
    plates[1].apply_translation((0, 0, -0.07))
    data = trimesh.util.concatenate(plates).export(file_type="stl")
    spec = parse_job({"dimension": 3, "geometry": {"mesh": "plates.stl"}, "grid": {"cell_size": 0.5, "padding": 1},
                      "material": {"youngs_modulus": 1.0, "poisson_ratio": 0.3}, "method": {"kind": "dg", "degree": 2}})
    surface = load_surface(data, filename="plates.stl", dimension=3)
    grid = make_grid(*surface.bounds, cell_size=0.5, padding=1)
    geo = prepare_geometry(spec, data, filename="plates.stl", cache=GeometryCache(None))
    bound, pieces = occupied_cells_bound(surface, grid), geo.cut_cells.num_pieces
    assert pieces > bound, (pieces, bound)
    low, high = estimate_memory(grid, spec.method, occupied=bound), estimate_memory(grid, spec.method, occupied=pieces)
    with pytest.raises(GridError, match=r"GiB for method 'dg', over the limit"):
        prepare_geometry(spec, data, filename="plates.stl", cache=GeometryCache(None),
                         limits=Limits(max_memory_bytes=(low + high) // 2))


@pytest.mark.parametrize("method", [{"kind": "staggered"}, {"kind": "dg", "degree": 1}])
def test_velocity_is_a_field_of_dynamic_runs_only(method, tmp_path):
    """The result format lists `velocity` (m/s); the spec refused to ask for it. It is the backward-Euler
    velocity (u_n - u_{n-1}) / dt of every step, and a static job asking for it is refused."""
    spec = json.loads((ROOT / "examples" / "cantilever.json").read_text())
    spec.update(grid={"resolution": 8, "padding": 1}, method=method, analysis={"kind": "dynamic", "time_step": 0.01, "steps": 3})
    spec["output"] = {"fields": ["displacement", "velocity"], "probes": [[1.0, 0.0, 0.0]], "surface": True}
    r = run(spec, (ROOT / "examples" / "cantilever.stl").read_bytes(), filename="cantilever.stl",
            cache=GeometryCache(None))
    u = [s.probes["displacement"] for s in r.steps]
    v = [s.probes["velocity"] for s in r.steps]
    np.testing.assert_allclose(v[0], u[0] / 0.01, rtol=1e-12)
    np.testing.assert_allclose(v[2], (u[2] - u[1]) / 0.01, rtol=1e-9, atol=1e-12)
    assert r.fields.cells["velocity"].shape == r.fields.cells["displacement"].shape and abs(v[2][0, 2]) > 0
    # the viewer files carry it at the corners and on the surface, as docs/result-format.md says
    with h5py.File(write_result(r, tmp_path / "v.h5"), "r") as f:
        for part in ("nodes", "surface"):
            assert f[f"xdmf/levels/0002/{part}/velocity"].attrs["units"] == "m/s"
    spec.update(analysis={"kind": "static"})
    with pytest.raises(SpecError, match=r"output.fields.1: 'velocity' needs analysis.kind 'dynamic'"):
        parse_job(spec)


def test_dg_on_an_open_surface_names_the_mesh_and_the_way_out():
    """The slicer's own error ("slice_cells: the surface is not closed; hex slicing needs a watertight
    mesh") named no field and no fix, while the staggered method runs the same mesh."""
    import trimesh

    from engine import simulate
    from engine.errors import GeometryError
    from engine.geometry.cache import GeometryCache

    sphere = trimesh.creation.icosphere(subdivisions=3)
    sphere.update_faces(sphere.triangles_center[:, 2] < 0.8)  # a hole over the top
    spec = {"dimension": 3, "geometry": {"mesh": "s.stl"}, "grid": {"resolution": 6}, "method": {"kind": "dg", "degree": 1},
            "material": {"youngs_modulus": 1e7, "poisson_ratio": 0.3},
            "boundaries": [{"kind": "displacement", "name": "c", "region": {"all": True}, "value": [0, 0, 0]}]}
    with pytest.raises(GeometryError, match=r"^geometry.mesh: the surface is not closed \(\d+ edges without a matching "
                                            r"opposite edge .*use method.kind 'staggered'"):
        simulate(spec, sphere.export(file_type="stl"), filename="s.stl", cache=GeometryCache(None))
