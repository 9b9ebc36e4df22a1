"""benchmarks/random_jobs.py draws valid job specs: a draw the schema refuses would test the schema
alone, never the engine."""

import numpy as np
import pytest
import trimesh

from benchmarks.random_jobs import ORACLES, draw, oracle_errors
from engine.geometry.cache import GeometryCache
from engine.pipeline import run
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


@pytest.mark.parametrize("oracle", sorted(ORACLES))
def test_an_oracle_passes_an_exact_state_and_catches_a_wrong_one(tmp_path, oracle):
    """The oracles' jobs are valid: held or loaded on their surface alone, or falling free, with the IP
    flux; a solved one is exact to its solve's accuracy, and the same result read against other values
    is not."""
    made = 0
    for seed in range(20):
        kind, drawn = draw(seed, 3, "f64", tmp_path)
        oracle_job = ORACLES[oracle](drawn, np.random.default_rng(seed), kind)
        if oracle_job is None:
            continue
        made += 1
        spec = oracle_job[0]
        parse_job(spec)
        assert spec["method"].get("flux", "ip") == "ip"
        if oracle == "freefall":
            assert not spec["boundaries"] and spec["loads"]["gravity"] and spec["analysis"]["kind"] == "dynamic"
        elif oracle == "uniform":  # one traction per facet direction, all sigma n of one symmetric sigma
            n = np.array([b["facing"]["direction"] for b in spec["boundaries"]])
            t = np.array([b["value"] for b in spec["boundaries"]])
            assert len(n) >= 6 and all(b["kind"] == "traction" for b in spec["boundaries"])
            sigma = np.linalg.lstsq(n, t, rcond=None)[0]
            assert np.allclose(n @ sigma, t) and np.allclose(sigma, sigma.T)
        else:
            assert len(spec["boundaries"]) == 1 and spec["analysis"]["kind"] in ("static", "quasistatic")
            assert not spec["loads"]
    assert made >= 10
    box = tmp_path / "box.stl"
    trimesh.creation.box(extents=[1.0, 0.6, 0.4]).export(box)
    clamp = {"kind": "displacement", "name": "clamp", "region": {"box": [[-1, -1, -1], [-0.4, 1, 1]]}, "value": [0, 0, 0]}
    base = {"dimension": 3, "geometry": {"mesh": str(box)}, "grid": {"resolution": 8},
            "method": {"kind": "staggered"}, "material": {"youngs_modulus": 1e6, "poisson_ratio": 0.3},
            "boundaries": [clamp], "analysis": {"kind": "quasistatic", "steps": 2},
            "solver": {"rtol": 1e-8, "precision": "f64"}, "output": {"fields": ["displacement"], "probes": [[0, 0, 0]]}}
    spec, wanted = ORACLES[oracle](base, np.random.default_rng(0), "box")
    r = run(spec, cache=GeometryCache(None))
    worst = oracle_errors(r, wanted)
    assert {"cells", "probes", "surface"} <= set(worst) and max(worst.values()) < 1e-8, worst
    off = {name: (lambda t, v=value, c=scale: 1.01 * (v(t) if callable(v) else t * v) + 0.01 * c, scale)
           for name, (value, scale) in wanted.items()}
    assert min(oracle_errors(r, off).values()) > 5e-3
