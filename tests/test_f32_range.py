"""solver.precision 'f32': a Young's modulus whose numbers single precision cannot hold is an input
error naming the field and the range (validate, run and the service's admission alike), the job
solves across that range, and the DG method says that it solves in f64.

Before, E = 1e-40 or 1e40 in f32 ran into numpy overflow warnings and "the operator lost positive
definiteness (p.Ap = nan)", and a DG job asking for f32 silently ran in f64."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

import engine
from engine.dg.problem import F32_IGNORED
from engine.geometry.loading import load_surface
from engine.grid import make_grid
from engine.output import read_result
from engine.staggered.precision import modulus_range
from schemas import parse_job
from tests.test_cli_checks import cli, one_error_line

TIP = [0.9, 0.0, 0.0]


def bar_job(tmp_path, E: float, **changes) -> dict:
    box = trimesh.creation.box(extents=(1.0, 0.2, 0.2))
    box.apply_translation((0.5, 0.0, 0.0))
    box.export(tmp_path / "bar.stl")
    spec = {"geometry": {"mesh": "bar.stl"}, "grid": {"resolution": 12},
            "material": {"youngs_modulus": E, "poisson_ratio": 0.3},
            "boundaries": [{"kind": "displacement", "region": {"halfspace": {"point": [0.001, 0, 0], "normal": [1, 0, 0]}},
                            "value": [0, 0, 0]}],
            "loads": {"gravity": [0, 0, -9.81]}, "solver": {"precision": "f32", "rtol": 1e-3},
            "output": {"probes": [TIP]}}
    spec.update(changes)
    return spec


def write(tmp_path, spec: dict, name: str = "job.json"):
    path = tmp_path / name
    path.write_text(json.dumps(spec))
    return path


def allowed(tmp_path) -> tuple[float, float]:
    spec = parse_job(bar_job(tmp_path, 1e7))
    surface = load_surface(tmp_path / "bar.stl")
    return modulus_range(spec, make_grid(*surface.bounds, resolution=12, padding=1))


def test_the_range_comes_from_the_stiffness_the_loads_and_rtol(tmp_path):
    lo, hi = allowed(tmp_path)
    # lowest: n^4 f / k within f32's max / 1e4 (n = 14 cells, f = rho g h^3, k = (lam + 2 mu) h);
    # highest: rtol f / k above f32's tiny * 1e4 (the solve broke at 1e-34 and 1e37)
    h, k = 1 / 12, (0.3 / (1.3 * 0.4) + 1 / 1.3) / 12
    f = 1000 * 9.81 * h**3
    assert lo == pytest.approx(f * 14**4 * 1e4 / (np.finfo(np.float32).max * k), rel=1e-12)
    assert hi == pytest.approx(1e-3 * f / (np.finfo(np.float32).tiny * 1e4 * k), rel=1e-12)
    assert (f"{lo:.2g}", f"{hi:.2g}") == ("5.7e-29", "4.3e+32")


@pytest.mark.parametrize("E", [1e-40, 1e40])
def test_a_modulus_f32_cannot_hold_is_named_by_validate_and_run(tmp_path, E):
    job = write(tmp_path, bar_job(tmp_path, E))
    expected = (f"error: material.youngs_modulus: {E:g} Pa is outside 5.7e-29 .. 4.3e+32 Pa, the range "
                "solver.precision 'f32' holds for this job's loads on its 14x5x5 grid of 0.08333 m cells (the "
                "solver's stiffness, loads and displacements must stay within single precision's 1.2e-38 .. "
                "3.4e+38); use solver.precision 'f64'")
    assert one_error_line(cli("validate", job)) == expected
    run = cli("run", job, "-o", tmp_path / "r.h5")
    assert one_error_line(run) == expected and "Warning" not in run.stderr
    assert not (tmp_path / "r.h5").exists()


def test_f32_solves_at_both_ends_of_the_range_it_allows(tmp_path):
    lo, hi = allowed(tmp_path)
    # linear elasticity: u E is the same for every E (f64 in this process)
    reference = engine.simulate({**bar_job(tmp_path, 1e7), "solver": {"precision": "f64"}}, tmp_path / "bar.stl")
    uE = reference.fields.probes["displacement"][0][2] * 1e7
    for E in (lo * 1.01, hi / 1.01):
        job = write(tmp_path, bar_job(tmp_path, E))
        out = cli("run", job, "-o", tmp_path / "r.h5")
        assert out.returncode == 0, out.stderr[-2000:]
        assert "Warning" not in out.stderr
        tip = read_result(tmp_path / "r.h5").fields.probes["displacement"][0]
        assert tip[2] * E == pytest.approx(uE, rel=2e-3)
    line = one_error_line(cli("validate", write(tmp_path, bar_job(tmp_path, lo / 1.01))))
    assert line.startswith(f"error: material.youngs_modulus: {lo / 1.01:g} Pa is outside 5.7e-29 .. 4.3e+32 Pa")


def test_the_service_refuses_it_at_admission_with_a_422_at_the_field(tmp_path):
    from service.admission import Rejected, check_submission
    from service.settings import Settings

    spec = bar_job(tmp_path, 1e40)
    with pytest.raises(Rejected) as caught:
        check_submission(json.dumps(spec), (tmp_path / "bar.stl").read_bytes(), "bar.stl", Settings())
    assert caught.value.status_code == 422
    (error,) = caught.value.errors
    assert error["loc"] == ["body", "spec", "material", "youngs_modulus"]
    assert error["msg"].startswith("1e+40 Pa is outside 5.7e-29 .. 4.3e+32 Pa, the range solver.precision 'f32' holds")


def test_f64_jobs_have_no_such_limit(tmp_path):
    job = write(tmp_path, bar_job(tmp_path, 1e40, solver={"precision": "f64"}))
    out = cli("validate", job)
    assert out.returncode == 0, out.stderr


def test_a_dg_job_asking_for_f32_says_it_solves_in_f64(tmp_path):
    job = write(tmp_path, bar_job(tmp_path, 1e7, grid={"resolution": 6}, method={"kind": "dg", "degree": 1}))
    out = cli("run", job, "-o", tmp_path / "r.h5")
    assert out.returncode == 0, out.stderr[-2000:]
    assert F32_IGNORED in read_result(tmp_path / "r.h5").solver.warnings
    assert F32_IGNORED == ("solver.precision: 'f32' applies to the staggered method; the DG method solves in f64 "
                           "(its memory and its result are double precision's)")
