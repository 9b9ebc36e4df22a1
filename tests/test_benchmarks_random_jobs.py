"""benchmarks/random_jobs.py draws valid job specs: a draw the schema refuses would test the schema
alone, never the engine."""

import pytest

from benchmarks.random_jobs import draw
from schemas import parse_job


@pytest.mark.parametrize("dimension", [2, 3])
def test_every_drawn_job_is_a_valid_spec_and_the_draws_differ(tmp_path, dimension):
    specs = [draw(seed, dimension, "f64", tmp_path)[1] for seed in range(40)]
    for spec in specs:
        parse_job(spec)
    assert len({str(spec) for spec in specs}) == len(specs)
    assert {spec["analysis"]["kind"] for spec in specs} == {"static", "quasistatic", "dynamic"}
    if dimension == 3:
        assert {spec["method"]["kind"] for spec in specs} == {"staggered", "dg"}
