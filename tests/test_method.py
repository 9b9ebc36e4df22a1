"""The method registry (engine/method.py): every entry resolves, jobs it cannot take are named errors
in the CLI (exit 2) and the service's admission (422), and an unknown kind names the known ones."""

from __future__ import annotations

import json

import pytest

from engine.errors import MethodUnavailableError
from engine.grid import Grid
from engine.method import METHODS, method_entry
from schemas import parse_job
from tests.test_cli_checks import cli, one_error_line

SQUARE = [[[0, 0], [1, 0], [1, 1], [0, 1]]]
SPEC_2D = {"dimension": 2, "geometry": {"polygon": SQUARE}, "grid": {"cell_size": 0.25},
           "material": {"youngs_modulus": 1.0, "poisson_ratio": 0.3}, "method": {"kind": "dg", "degree": 1}}


@pytest.mark.parametrize("kind", sorted(METHODS))
def test_every_entry_resolves_its_builder_and_estimate(kind):
    entry = METHODS[kind]
    assert entry.kind == kind and entry.geometry in ("fractions", "cut_cells")
    spec = parse_job({**SPEC_2D, "dimension": 3, "geometry": {"mesh": "part.stl"}, "method": {"kind": kind}})
    grid = Grid(origin=(0.0,) * 3, spacing=1.0, shape=(8, 8, 8))
    # 512 cells: at least the cell fractions' 8 bytes a cell, and not gigabytes
    assert 512 * 8 <= entry.estimate_memory(grid, spec.method) < 2**30
    from engine.method import _load

    assert callable(_load(entry.builder))


def test_an_unknown_kind_names_the_known_ones():
    with pytest.raises(MethodUnavailableError, match=r"method.kind: 'fem' is not a method of this engine; one of dg, staggered"):
        method_entry("fem")


def test_a_2d_dg_job_is_refused_by_the_cli_with_the_method_that_takes_it(tmp_path):
    path = tmp_path / "job.json"
    path.write_text(json.dumps(SPEC_2D))
    line = one_error_line(cli("run", path, "-o", tmp_path / "r.h5"))
    assert line == "error: method.kind: 'dg' solves dimension 3 only; for dimension 2 use 'staggered'"
    assert not (tmp_path / "r.h5").exists()


def test_a_2d_dg_job_is_a_422_at_admission():
    from service.admission import Rejected, check_submission
    from service.settings import Settings

    with pytest.raises(Rejected) as caught:
        check_submission(json.dumps(SPEC_2D), None, None, Settings())
    assert caught.value.status_code == 422
    (error,) = caught.value.errors
    assert error["loc"] == ["body", "spec", "method", "kind"] and "dimension 3 only" in error["msg"]


@pytest.mark.parametrize("kind", ["staggered", "dg"])
def test_the_setup_reports_its_parts_in_order(kind):
    """The discretization stage names its parts as they start, so a progress bar never sits on one
    line for the whole setup (the service's bundled job stalled 8.9 s there before)."""
    from engine.geometry.cache import GeometryCache
    from engine.pipeline import run
    from tests.test_cli_checks import EXAMPLE, STL

    spec = json.loads(EXAMPLE.read_text())
    spec["grid"] = {"resolution": 12, "padding": 1}
    spec["method"] = {"kind": kind}
    seen = []
    run(spec, STL, cache=GeometryCache(None), progress=lambda stage, fraction, info: seen.append((stage, fraction, info)))
    parts = [(f, i["part"]) for s, f, i in seen if s == "discretization" and "part" in i]
    fractions = [f for s, f, _ in seen]
    assert fractions == sorted(fractions)  # the bar only moves forward
    names = [p for _, p in parts]
    expected = {"staggered": ["surface quadrature", "operator", "boundaries", "sparse factor"],  # 12 cells: solved directly
                "dg": ["elements and basis", "element integrals", "boundaries and loads", "assembly and factorisation"]}[kind]
    assert [n for n in names if n in expected] == expected, names
