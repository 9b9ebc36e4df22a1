"""output.every: a quasi-static or dynamic run keeps every n-th step (and its last) in its result,
and the memory and disk it is admitted by count those steps alone."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from engine import simulate
from engine.geometry.cache import GeometryCache
from engine.output import estimate_result_bytes, read_result, write_result
from engine.grid import make_grid
from engine.pipeline import held_steps_bytes
from schemas import SpecError, parse_job


def bar_job(analysis: dict, every: int = 1, method: dict | None = None) -> dict:
    return {"geometry": {"mesh": "bar.stl"}, "grid": {"resolution": 10}, "method": method or {"kind": "staggered"},
            "material": {"youngs_modulus": 1e7, "poisson_ratio": 0.3, "density": 1000},
            "boundaries": [{"kind": "displacement", "region": {"halfspace": {"point": [0.001, 0, 0], "normal": [1, 0, 0]}},
                            "value": [0, 0, 0]}],
            "loads": {"gravity": [0, 0, -9.81]}, "analysis": analysis, "solver": {"rtol": 1e-12},
            "output": {"fields": ["displacement", "velocity", "von_mises"] if analysis["kind"] == "dynamic"
                       else ["displacement", "von_mises"], "probes": [[0.9, 0, 0]], "every": every}}


def bar_mesh() -> bytes:
    box = trimesh.creation.box(extents=(1.0, 0.2, 0.2))
    box.apply_translation((0.5, 0.0, 0.0))
    return box.export(file_type="stl")


def test_every_is_checked_and_counts_the_kept_steps():
    assert parse_job(bar_job({"kind": "quasistatic", "steps": 7}, every=3)).kept_steps == 3  # 3, 6, 7
    assert parse_job(bar_job({"kind": "quasistatic", "steps": 6}, every=3)).kept_steps == 2  # 3, 6
    assert parse_job(bar_job({"kind": "dynamic", "time_step": 1e-3, "steps": 5}, every=9)).kept_steps == 1  # 5
    assert parse_job(bar_job({"kind": "dynamic", "time_step": 1e-3, "steps": 5})).kept_steps == 5
    assert parse_job(bar_job({"kind": "static"})).kept_steps == 0
    with pytest.raises(SpecError) as caught:
        parse_job(bar_job({"kind": "static"}, every=2))
    assert caught.value.errors == ["output.every: keeps every n-th step of a quasi-static or dynamic run; a static "
                                   "run has one state (leave it at 1)"]
    with pytest.raises(SpecError) as caught:
        parse_job(bar_job({"kind": "quasistatic", "steps": 4}, every=0))
    assert caught.value.errors[0].startswith("output.every: ")


@pytest.mark.parametrize("analysis", [{"kind": "quasistatic", "steps": 7},
                                      {"kind": "dynamic", "time_step": 2e-3, "steps": 7}], ids=["quasistatic", "dynamic"])
@pytest.mark.parametrize("method", [{"kind": "staggered"}, {"kind": "dg", "degree": 1}], ids=["staggered", "dg1"])
def test_the_kept_steps_are_those_of_the_whole_run(tmp_path, analysis, method):
    """Steps 3, 6 and 7 of seven, each the same state (fields, probes, surface, velocity, time) as
    in the run that keeps all seven; the result file holds those three."""
    mesh = bar_mesh()
    every = simulate(bar_job(analysis, 3, method), mesh, filename="bar.stl", cache=GeometryCache(None))
    whole = simulate(bar_job(analysis, 1, method), mesh, filename="bar.stl", cache=GeometryCache(None))
    assert len(whole.steps) == 7 and len(every.steps) == 3
    for got, want in zip(every.steps, [whole.steps[2], whole.steps[5], whole.steps[6]]):
        assert got.time == pytest.approx(want.time, rel=1e-15)
        for level in ("cells", "probes", "surface"):
            for name, value in getattr(want, level).items():
                np.testing.assert_allclose(getattr(got, level)[name], value, rtol=1e-12, atol=1e-14 * np.nanmax(
                    np.abs(value)), equal_nan=True, err_msg=f"{level}/{name}")
    np.testing.assert_array_equal(every.fields.cells["displacement"], whole.fields.cells["displacement"])
    write_result(every, tmp_path / "r.h5")
    back = read_result(tmp_path / "r.h5")
    assert [s.time for s in back.steps] == [s.time for s in every.steps]
    dt = analysis.get("time_step", 1 / 7)
    np.testing.assert_allclose([s.time for s in back.steps], [3 * dt, 6 * dt, 7 * dt], rtol=1e-14)


def test_memory_and_disk_count_the_kept_steps_alone():
    spec = parse_job(bar_job({"kind": "dynamic", "time_step": 1e-3, "steps": 100}, every=10))
    whole = parse_job(bar_job({"kind": "dynamic", "time_step": 1e-3, "steps": 100}))
    grid = make_grid(np.array([0.0, -0.1, -0.1]), np.array([1.0, 0.1, 0.1]), resolution=10)
    assert held_steps_bytes(spec, grid) * 99 == held_steps_bytes(whole, grid) * 9
    from service.faults import result_estimate
    fields = list(spec.output.fields)
    assert result_estimate(spec.to_json(), grid.shape, 0) == estimate_result_bytes(
        grid.shape, fields, levels=11, surface_vertices=3, probes=1)
