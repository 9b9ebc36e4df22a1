"""How many steps a job may take, and the room its result needs: named by the spec's fields.

A quasi-static job of 1e9 steps passed ``validate`` and ``run`` refused it with "the result ... may
need up to 56991577.4 MiB", naming no field; a job of more than 10,000 steps (the result's step
groups have four digits) solved to the end and then failed writing."""

from __future__ import annotations

import json
import shutil

import pytest
import trimesh

from engine import cli
from engine.output import estimate_result_bytes
from schemas import SpecError, parse_job
from schemas.export import schema_text
from schemas.job import MAX_STEPS


def bar_job(tmp_path, analysis: dict) -> dict:
    box = trimesh.creation.box(extents=(1.0, 0.2, 0.2))
    box.apply_translation((0.5, 0.0, 0.0))
    box.export(tmp_path / "bar.stl")
    return {"geometry": {"mesh": "bar.stl"}, "grid": {"resolution": 12},
            "material": {"youngs_modulus": 1e7, "poisson_ratio": 0.3},
            "boundaries": [{"kind": "displacement", "region": {"halfspace": {"point": [0.001, 0, 0], "normal": [1, 0, 0]}},
                            "value": [0, 0, 0]}],
            "loads": {"gravity": [0, 0, -9.81]}, "analysis": analysis,
            "output": {"fields": ["displacement", "von_mises"]}}


@pytest.mark.parametrize("analysis", [{"kind": "quasistatic"}, {"kind": "dynamic", "time_step": 1e-3}])
def test_more_steps_than_a_result_holds_is_a_spec_error(tmp_path, analysis):
    assert parse_job(bar_job(tmp_path, {**analysis, "steps": MAX_STEPS})).analysis.steps == 10_000
    with pytest.raises(SpecError) as caught:
        parse_job(bar_job(tmp_path, {**analysis, "steps": 10**9}))
    assert caught.value.errors == ["analysis.steps: 1000000000 steps; a result holds at most 10000 (each step is a "
                                   "numbered group of the file): take fewer, longer steps"]
    assert schema_text().count('"maximum": 10000') == 2


def test_validate_and_run_name_analysis_steps_when_the_result_has_no_room(tmp_path, monkeypatch, capsys):
    job = tmp_path / "job.json"
    job.write_text(json.dumps(bar_job(tmp_path, {"kind": "quasistatic", "steps": 40})))
    usage = shutil.disk_usage(tmp_path)
    monkeypatch.setattr(cli.shutil, "disk_usage", lambda path: usage._replace(free=0))
    need = estimate_result_bytes((14, 5, 5), ["displacement", "von_mises"], levels=41)
    expected = (f"error: analysis.steps: the result of 40 steps, each holding output.fields [displacement, von_mises] "
                f"on a 14x5x5 grid, may need up to {need / 2**20:.1f} MiB, and '{tmp_path}' has 0.0 MiB free; keep fewer "
                "steps (output.every), lower analysis.steps or grid.resolution (or raise grid.cell_size), or output "
                "fewer fields")
    assert cli.main(["validate", str(job), "-o", str(tmp_path / "r.h5")]) == 2
    assert capsys.readouterr().err.strip() == expected
    assert cli.main(["run", str(job), "-o", str(tmp_path / "r.h5"), "--no-cache"]) == 2
    assert capsys.readouterr().err.strip().splitlines()[-1] == expected
    assert not (tmp_path / "r.h5").exists()


def test_a_static_result_without_room_names_the_grid(tmp_path, monkeypatch, capsys):
    job = tmp_path / "job.json"
    job.write_text(json.dumps(bar_job(tmp_path, {"kind": "static"})))
    usage = shutil.disk_usage(tmp_path)
    monkeypatch.setattr(cli.shutil, "disk_usage", lambda path: usage._replace(free=0))
    monkeypatch.chdir(tmp_path)
    assert cli.main(["validate", str(job)]) == 2
    assert capsys.readouterr().err.strip().startswith(
        "error: grid: the result of a 14x5x5 grid with output.fields [displacement, von_mises] may need up to ")
