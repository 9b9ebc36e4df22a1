"""The job spec: the committed JSON Schema, the design sketch's example, defaults and the error messages."""

from __future__ import annotations

import copy
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from pydantic import ValidationError

from schemas import (
    AllRegion,
    BoxRegion,
    DGMethod,
    DisplacementBoundary,
    GeometrySpec,
    GridSpec,
    HalfspaceRegion,
    JobSpec,
    LoadsSpec,
    MaterialSpec,
    OutputSpec,
    PressureBoundary,
    SpecError,
    SphereRegion,
    StaggeredMethod,
    StaticAnalysis,
    TractionBoundary,
    format_errors,
    job_json_schema,
    parse_job,
)
from schemas.export import SCHEMA_PATH, main as export_main, schema_text

ROOT = Path(__file__).resolve().parents[1]

# The example job of the project's design sketch, verbatim apart from the comments.
DESIGN_EXAMPLE = {
    "geometry": {"mesh": "part.stl", "scale": 1.0},
    "grid": {"cell_size": 0.02},
    "method": {"kind": "staggered"},
    "material": {"youngs_modulus": 1e6, "poisson_ratio": 0.3, "density": 1000, "model": "linear"},
    "loads": {"gravity": [0, 0, -9.81]},
    "boundaries": [
        {"kind": "displacement", "region": {"box": [[-1, -1, -1], [1, 1, -0.9]]}, "value": [0, 0, 0]},
        {
            "kind": "displacement",
            "region": {"halfspace": {"point": [0.1, 0, 0], "normal": [1, 0, 0]}},
            "value": [0, 0, 0],
        },
        {"kind": "displacement", "region": {"box": [[-1, -0.01, -1], [1, 0.01, 1]]}, "value": [None, 0, None]},
        {"kind": "traction", "region": {"sphere": {"center": [0, 0, 0], "radius": 0.6}}, "value": [0, 0, -100]},
        {"kind": "pressure", "region": {"sphere": {"center": [0, 0, 0], "radius": 0.6}}, "value": 1000},
    ],
    "analysis": {"kind": "static"},
    "solver": {"rtol": 1e-8, "max_iterations": 5000, "precision": "f64", "arch": "auto"},
    "output": {"fields": ["displacement", "stress", "von_mises"], "probes": [[0.7, 0, 0]], "surface": True},
}

MINIMAL = {
    "geometry": {"mesh": "part.stl"},
    "grid": {"resolution": 16},
    "material": {"youngs_modulus": 2e6, "poisson_ratio": 0.25},
}

SQUARE_WITH_HOLE = [
    [[0, 0], [1, 0], [1, 1], [0, 1]],
    [[0.25, 0.25], [0.25, 0.75], [0.75, 0.75], [0.75, 0.25]],
]

DELETE = object()


def _edit(spec: dict, path: str, value: object) -> dict:
    """Copy of ``spec`` with the dotted ``path`` (list indices as numbers) set to ``value`` or deleted."""
    out = copy.deepcopy(spec)
    *parents, last = [int(k) if k.isdigit() else k for k in path.split(".")]
    node = out
    for key in parents:
        node = node[key]
    if value is DELETE:
        del node[last]
    else:
        node[last] = value
    return out


def _errors(data: object) -> list[str]:
    with pytest.raises(SpecError) as info:
        parse_job(data)
    return info.value.errors


def _rotation_z(angle: float, translation: tuple[float, float, float]) -> list[list[float]]:
    c, s = math.cos(angle), math.sin(angle)
    return [[c, -s, 0, translation[0]], [s, c, 0, translation[1]], [0, 0, 1, translation[2]], [0, 0, 0, 1]]


# --- the committed JSON Schema ------------------------------------------------------------------


def test_committed_schema_equals_generated() -> None:
    # Fails whenever a model changes without `python -m schemas.export`.
    assert SCHEMA_PATH.read_text(encoding="utf-8") == schema_text()


def test_schema_text_format() -> None:
    text = schema_text()
    assert text.endswith("}\n") and not text.endswith("\n\n")
    assert text == json.dumps(json.loads(text), sort_keys=True, indent=2, ensure_ascii=False) + "\n"
    schema = json.loads(text)
    assert schema["$schema"] == "https://json-schema.org/draft/2020-12/schema"
    assert schema["title"] == "JobSpec"
    assert schema["required"] == ["geometry", "grid", "material"]
    assert schema["additionalProperties"] is False
    assert schema == job_json_schema()


def test_export_check_detects_drift(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    target = tmp_path / "json" / "job.schema.json"
    assert export_main(["--check", "--path", str(target)]) == 1  # missing
    assert "is missing" in capsys.readouterr().err
    assert export_main(["--path", str(target)]) == 0
    assert target.read_text(encoding="utf-8") == schema_text()
    assert export_main(["--check", "--path", str(target)]) == 0
    target.write_text(schema_text().replace('"exclusiveMinimum": 0', '"minimum": 0', 1), encoding="utf-8")
    assert export_main(["--check", "--path", str(target)]) == 1
    assert "is out of date; run `python -m schemas.export`" in capsys.readouterr().err


def test_module_check_and_leaf_package() -> None:
    # `python -m schemas.export --check` on the committed file, in a fresh interpreter that also
    # proves the package imports neither engine nor service.
    check = subprocess.run(
        [sys.executable, "-m", "schemas.export", "--check"], cwd=ROOT, capture_output=True, text=True
    )
    assert check.returncode == 0, check.stderr
    leaf = subprocess.run(
        [sys.executable, "-c", "import sys, schemas; print(sorted({m.split('.')[0] for m in sys.modules}))"],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    assert leaf.returncode == 0, leaf.stderr
    loaded = set(json.loads(leaf.stdout.replace("'", '"')))
    assert "schemas" in loaded and not loaded & {"engine", "service", "gstaichi"}


# --- valid specs --------------------------------------------------------------------------------


def test_design_example_parses() -> None:
    spec = parse_job(DESIGN_EXAMPLE)
    assert spec.dimension == 3
    assert spec.geometry.mesh == "part.stl" and spec.geometry.polygon is None
    assert spec.grid.cell_size == 0.02 and spec.grid.resolution is None and spec.grid.padding == 1
    assert isinstance(spec.method, StaggeredMethod)
    assert spec.material.youngs_modulus == 1e6 and spec.material.poisson_ratio == 0.3
    assert spec.loads.gravity == (0.0, 0.0, -9.81)
    kinds = [type(b) for b in spec.boundaries]
    assert kinds == [DisplacementBoundary] * 3 + [TractionBoundary, PressureBoundary]
    assert isinstance(spec.boundaries[0].region, BoxRegion)
    assert spec.boundaries[0].region.box == ((-1.0, -1.0, -1.0), (1.0, 1.0, -0.9))
    assert isinstance(spec.boundaries[1].region, HalfspaceRegion)
    assert spec.boundaries[1].region.halfspace.normal == (1.0, 0.0, 0.0)
    assert spec.boundaries[2].value == (None, 0.0, None)
    assert isinstance(spec.boundaries[3].region, SphereRegion)
    assert spec.boundaries[3].region.sphere.radius == 0.6
    assert spec.boundaries[4].value == 1000.0
    assert isinstance(spec.analysis, StaticAnalysis)
    assert spec.output.fields == ["displacement", "stress", "von_mises"]
    assert spec.output.probes == [(0.7, 0.0, 0.0)]


def test_json_text_and_bytes_give_the_same_spec() -> None:
    text = json.dumps(DESIGN_EXAMPLE)
    assert parse_job(text) == parse_job(text.encode()) == parse_job(DESIGN_EXAMPLE)


def test_defaults() -> None:
    spec = parse_job(MINIMAL)
    assert spec.dimension == 3
    assert (spec.geometry.scale, spec.geometry.transform) == (1.0, None)
    assert (spec.grid.resolution, spec.grid.cell_size, spec.grid.padding) == (16, None, 1)
    assert spec.method == StaggeredMethod()
    assert (spec.material.density, spec.material.model) == (1000.0, "linear")
    assert spec.loads.gravity == (0.0, 0.0, 0.0)  # zero vector of length dimension
    assert spec.boundaries == []
    assert spec.analysis == StaticAnalysis()
    assert (spec.solver.rtol, spec.solver.max_iterations) == (1e-8, 5000)
    assert (spec.solver.precision, spec.solver.arch) == ("f64", "auto")
    assert (spec.output.fields, spec.output.probes, spec.output.surface) == (["displacement"], [], True)
    dg = parse_job({**MINIMAL, "method": {"kind": "dg"}}).method
    assert (dg.degree, dg.flux, dg.penalty) == (1, "ip", None)  # None: the degree's default (engine.dg.elasticity.DEFAULT_PENALTY)
    assert parse_job({**MINIMAL, "dimension": 2}).loads.gravity == (0.0, 0.0)


def test_analysis_kinds() -> None:
    quasi = parse_job({**MINIMAL, "analysis": {"kind": "quasistatic", "steps": 4}}).analysis
    assert (quasi.kind, quasi.steps) == ("quasistatic", 4)
    dyn = parse_job({**MINIMAL, "analysis": {"kind": "dynamic", "time_step": 1e-3, "steps": 10}}).analysis
    assert (dyn.kind, dyn.time_step, dyn.steps) == ("dynamic", 1e-3, 10)


def test_2d_polygon_spec() -> None:
    spec = parse_job(
        {
            "dimension": 2,
            "geometry": {
                "polygon": SQUARE_WITH_HOLE,
                "scale": 0.5,
                "transform": [[0, -1, 0.1], [1, 0, 0.2], [0, 0, 1]],
            },
            "grid": {"cell_size": 0.05, "padding": 2},
            "material": {"youngs_modulus": 1e6, "poisson_ratio": 0.3},
            "loads": {"gravity": [0, -9.81]},
            "boundaries": [
                {"kind": "displacement", "region": {"box": [[-1, -1], [1, 0.01]]}, "value": [None, 0]},
                {"kind": "traction", "region": {"halfspace": {"point": [1, 0], "normal": [-2, 0]}}, "value": [1, 0]},
            ],
            "output": {"probes": [[0.5, 0.9]]},
        }
    )
    assert spec.dimension == 2
    assert spec.geometry.mesh is None
    assert spec.geometry.polygon == [[tuple(map(float, v)) for v in loop] for loop in SQUARE_WITH_HOLE]
    assert spec.geometry.transform == ((0.0, -1.0, 0.1), (1.0, 0.0, 0.2), (0.0, 0.0, 1.0))
    assert spec.loads.gravity == (0.0, -9.81)
    assert spec.boundaries[0].value == (None, 0.0)
    assert spec.boundaries[1].region.halfspace.normal == (-2.0, 0.0)  # kept as given, not normalised
    assert spec.output.probes == [(0.5, 0.9)]


def test_2d_with_mesh_file() -> None:
    spec = parse_job({**MINIMAL, "dimension": 2, "geometry": {"mesh": "outline.svg"}})
    assert (spec.dimension, spec.geometry.mesh) == (2, "outline.svg")


def test_rotation_round_off_accepted_within_tolerance() -> None:
    rotation = _rotation_z(0.3, (1.0, -2.0, 0.5))
    spec = parse_job(_edit(MINIMAL, "geometry.transform", rotation))
    assert np.allclose(spec.geometry.transform, rotation, rtol=0, atol=0)
    nearly = copy.deepcopy(rotation)
    nearly[0][0] += 1e-7
    parse_job(_edit(MINIMAL, "geometry.transform", nearly))
    nearly[0][0] += 1e-5
    (line,) = _errors(_edit(MINIMAL, "geometry.transform", nearly))
    assert line.startswith("geometry.transform: linear part is not a rotation: max |R^T R - I| = 1.9")


def test_canonical_json_round_trip() -> None:
    spec = parse_job(DESIGN_EXAMPLE)
    text = spec.to_json()
    assert parse_job(text) == spec
    dumped = json.loads(text)
    assert dumped["boundaries"][2]["value"] == [None, 0.0, None]  # free components survive
    assert "polygon" not in dumped["geometry"] and "resolution" not in dumped["grid"]


def test_python_objects_and_numpy_inputs() -> None:
    spec = JobSpec(
        geometry=GeometrySpec(mesh="part.stl"),
        grid=GridSpec(cell_size=0.1),
        method=DGMethod(degree=2, flux="bz"),
        material=MaterialSpec(youngs_modulus=1e6, poisson_ratio=0.2),
        loads=LoadsSpec(gravity=np.array([0.0, 0.0, -9.81])),
        boundaries=[
            DisplacementBoundary(region=AllRegion(all=True), value=(0, None, 0)),
            {"kind": "pressure", "region": {"all": True}, "value": np.float64(5.0)},
        ],
        output=OutputSpec(probes=[np.zeros(3)]),
    )
    assert spec.loads.gravity == (0.0, 0.0, -9.81)
    assert (spec.method.degree, spec.method.flux) == (2, "bz")
    assert spec.boundaries[1] == PressureBoundary(region=AllRegion(all=True), value=5.0)
    with pytest.raises(ValidationError) as info:
        JobSpec(
            geometry=GeometrySpec(mesh="part.stl"),
            grid=GridSpec(cell_size=0.1),
            material=MaterialSpec(youngs_modulus=1e6, poisson_ratio=0.2),
            output=OutputSpec(probes=[(0.0, 0.0)]),
        )
    assert format_errors(info.value) == ["output.probes.0: expected 3 components (dimension 3), got 2"]


def test_json_schema_accepts_what_the_models_accept() -> None:
    jsonschema = pytest.importorskip("jsonschema")
    validator = jsonschema.Draft202012Validator(json.loads(SCHEMA_PATH.read_text(encoding="utf-8")))
    example = json.loads((ROOT / "examples" / "cantilever.json").read_text(encoding="utf-8"))
    for document in (DESIGN_EXAMPLE, MINIMAL, example, json.loads(parse_job(DESIGN_EXAMPLE).to_json())):
        assert list(validator.iter_errors(document)) == []
    rejected = [
        _edit(MINIMAL, "grid", {"cell_size": 0.1, "resolution": 8}),
        _edit(MINIMAL, "geometry", {"mesh": "a.stl", "polygon": SQUARE_WITH_HOLE}),
        _edit(MINIMAL, "method", {"degree": 2}),  # JSON documents must name the kind
        _edit(MINIMAL, "material.youngs_modulu", 1.0),
        _edit(MINIMAL, "boundaries", [{"kind": "pressure", "region": {"all": True, "sphere": {}}, "value": 1}]),
    ]
    for document in rejected:
        assert list(validator.iter_errors(document)) != [], document
        with pytest.raises(SpecError):
            parse_job(document)


def test_cantilever_example() -> None:
    spec = parse_job((ROOT / "examples" / "cantilever.json").read_bytes())
    assert (spec.dimension, spec.geometry.mesh, spec.grid.resolution) == (3, "cantilever.stl", 32)
    assert isinstance(spec.method, StaggeredMethod)
    assert (spec.material.youngs_modulus, spec.material.poisson_ratio, spec.material.density) == (1e7, 0.3, 1000.0)
    assert spec.loads.gravity == (0.0, 0.0, -9.81)
    clamp, tip = spec.boundaries
    assert isinstance(clamp, DisplacementBoundary) and clamp.value == (0.0, 0.0, 0.0)
    assert clamp.region.box == ((-0.1, -0.2, -0.2), (0.05, 0.2, 0.2))
    assert isinstance(tip, TractionBoundary) and tip.region.box[0][0] > 0.99 and tip.value == (0.0, 0.0, -1000.0)
    assert spec.output.fields == ["displacement", "von_mises"]
    assert (spec.output.probes, spec.output.surface) == ([(1.0, 0.0, 0.0)], True)


# --- invalid specs: exact path, key phrase of the reason ------------------------------------------

BAD = [
    ("E zero", "material.youngs_modulus", 0, "material.youngs_modulus", "greater than 0"),
    ("E negative", "material.youngs_modulus", -1e6, "material.youngs_modulus", "greater than 0"),
    ("nu half", "material.poisson_ratio", 0.5, "material.poisson_ratio", "less than 0.5"),
    ("nu negative", "material.poisson_ratio", -0.1, "material.poisson_ratio", "greater than or equal to 0"),
    ("density zero", "material.density", 0, "material.density", "greater than 0"),
    ("material model", "material.model", "neo-hookean", "material.model", "'linear' or 'corotated'"),
    ("NaN gravity", "loads.gravity", [0, 0, math.nan], "loads.gravity.2", "must be a finite number, got nan"),
    ("inf scale", "geometry.scale", math.inf, "geometry.scale", "must be a finite number, got inf"),
    ("scale zero", "geometry.scale", 0, "geometry.scale", "greater than 0"),
    ("gravity 2 of 3", "loads.gravity", [0, -9.81], "loads.gravity", "expected 3 components (dimension 3), got 2"),
    ("box reversed", "boundaries.0.region.box", [[0, 0, 0.5], [1, 1, 0.1]], "boundaries.0.region.box",
     "min must be < max in every component (axis 2: 0.5 >= 0.1)"),
    ("box flat", "boundaries.0.region.box", [[1, 0, 0], [1, 1, 1]], "boundaries.0.region.box", "(axis 0: 1 >= 1)"),
    ("box corner short", "boundaries.0.region.box", [[0, 0], [1, 1, 1]], "boundaries.0.region.box.0",
     "expected 3 components (dimension 3), got 2"),
    ("zero normal", "boundaries.1.region.halfspace.normal", [0, 0, 0], "boundaries.1.region.halfspace.normal",
     "normal must be non-zero"),
    ("radius zero", "boundaries.3.region.sphere.radius", 0, "boundaries.3.region.sphere.radius", "greater than 0"),
    ("radius negative", "boundaries.3.region.sphere.radius", -0.6, "boundaries.3.region.sphere.radius",
     "greater than 0"),
    ("centre short", "boundaries.3.region.sphere.center", [0, 0], "boundaries.3.region.sphere.center",
     "expected 3 components"),
    ("both sizes", "grid", {"cell_size": 0.02, "resolution": 64}, "grid",
     "exactly one of 'cell_size' or 'resolution' is required, got both"),
    ("no size", "grid", {"padding": 2}, "grid", "exactly one of 'cell_size' or 'resolution' is required, got neither"),
    ("padding negative", "grid.padding", -1, "grid.padding", "greater than or equal to 0"),
    ("unknown key", "material.youngs_modulu", 1e6, "material.youngs_modulu",
     "unknown key; did you mean 'youngs_modulus'?"),
    ("unknown top key", "outputs", {}, "outputs", "unknown key; did you mean 'output'?"),
    ("unknown method", "method", {"kind": "fem"}, "method.kind",
     "unknown kind 'fem'; expected one of 'staggered', 'dg'"),
    ("method no kind", "method", {"degree": 2}, "method.kind", "missing; expected one of 'staggered', 'dg'"),
    ("method string", "method", "dg", "method", "expected an object with a 'kind' key"),
    ("dg degree 3", "method", {"kind": "dg", "degree": 3}, "method.degree", "1 or 2"),
    ("dg penalty", "method", {"kind": "dg", "penalty": 0}, "method.penalty", "greater than 0"),
    ("scaling transform", "geometry.transform", [[2, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]],
     "geometry.transform", "linear part is not a rotation"),
    ("shear transform", "geometry.transform", [[1, 0.5, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]],
     "geometry.transform", "linear part is not a rotation"),
    ("reflection", "geometry.transform", [[-1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]],
     "geometry.transform", "determinant -1 (a reflection)"),
    ("bottom row", "geometry.transform", [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1, 1]],
     "geometry.transform", "bottom row must be [0, 0, 0, 1]"),
    ("2D transform in 3D", "geometry.transform", [[0, -1, 0], [1, 0, 0], [0, 0, 1]], "geometry.transform",
     "expected a 4x4 matrix (dimension 3), got 3x3"),
    ("ragged transform", "geometry.transform", [[1, 0, 0], [0, 1, 0]], "geometry.transform",
     "must be a 3x3 (2D) or 4x4 (3D) homogeneous matrix, got 2x3"),
    ("NaN probe", "output.probes", [[0.7, math.nan, 0]], "output.probes.0.1", "must be a finite number, got nan"),
    ("short probe", "output.probes", [[0.7, 0, 0], [1, 2]], "output.probes.1", "expected 3 components"),
    ("duplicate field", "output.fields", ["stress", "von_mises", "stress"], "output.fields",
     "duplicate entries 'stress'"),
    ("unknown field", "output.fields", ["temperature"], "output.fields.0", "'displacement', 'velocity', 'strain', 'stress'"),
    ("polygon in 3D", "geometry", {"polygon": SQUARE_WITH_HOLE}, "geometry.polygon",
     "requires dimension 2, got dimension 3"),
    # In 3D the polygon is wrong whatever else the geometry says; "got both" is tested in 2D.
    ("mesh and polygon", "geometry", {"mesh": "a.stl", "polygon": SQUARE_WITH_HOLE}, "geometry.polygon",
     "requires dimension 2, got dimension 3"),
    ("no geometry source", "geometry", {"scale": 2}, "geometry", "got neither"),
    ("empty mesh name", "geometry.mesh", "", "geometry.mesh", "at least 1 character"),
    ("displacement all null", "boundaries.2.value", [None, None, None], "boundaries.2.value",
     "at least one component must be a number"),
    ("displacement NaN", "boundaries.2.value", [None, math.nan, None], "boundaries.2.value.1", "finite"),
    ("traction short", "boundaries.3.value", [0, -100], "boundaries.3.value", "expected 3 components"),
    ("pressure vector", "boundaries.4.value", [1, 2, 3], "boundaries.4.value", "expected a number, got an array"),
    # loads of 1e308 were accepted and failed in the solve ("the load vector is not finite")
    ("gravity 1e308", "loads.gravity", [0, 0, -1e308], "loads.gravity.2",
     "-1e+308 m/s^2 is beyond +-1e+100 m/s^2, the range the solvers' arithmetic is checked over"),
    ("traction 1e101", "boundaries.3.value", [0, 1e101, 0], "boundaries.3.value.1", "1e+101 Pa is beyond +-1e+100 Pa"),
    ("pressure -1e200", "boundaries.4.value", -1e200, "boundaries.4.value", "-1e+200 Pa is beyond +-1e+100 Pa"),
    ("displacement 1e308", "boundaries.2.value", [None, 1e308, None], "boundaries.2.value.1", "1e+308 m is beyond"),
    ("body force", "material.density", 1e100, "loads.gravity",
     "the body force material.density x |gravity| = 9.81e+100 N/m^3 is beyond 1e+100 N/m^3"),
    # JSON types are not coerced: true would have run with E = 1 Pa
    ("E true", "material.youngs_modulus", True, "material.youngs_modulus", "expected a number, got true"),
    ("E string", "material.youngs_modulus", "1e7", "material.youngs_modulus", "expected a number, got '1e7'"),
    ("traction bool", "boundaries.3.value", [0, True, 0], "boundaries.3.value.1", "expected a number, got true"),
    ("surface string", "output.surface", "yes", "output.surface", "expected true or false, got 'yes'"),
    ("resolution float", "grid", {"resolution": 8.0}, "grid.resolution", "expected an integer, got 8.0"),
    ("degree bool", "method", {"kind": "dg", "degree": True}, "method.degree", "expected 1 or 2, got true"),
    ("all one", "boundaries.0.region", {"all": 1}, "boundaries.0.region.all", "expected true or false, got 1"),
    ("boundary kind", "boundaries.0.kind", "force", "boundaries.0.kind", "unknown kind 'force'"),
    ("boundary no kind", "boundaries.0.kind", DELETE, "boundaries.0.kind", "missing"),
    ("region two shapes", "boundaries.0.region", {"box": [[0, 0, 0], [1, 1, 1]], "all": True}, "boundaries.0.region",
     "must have exactly one of 'box', 'sphere', 'halfspace', 'all', got 'box', 'all'"),
    ("region typo", "boundaries.0.region", {"boxes": [[0, 0, 0], [1, 1, 1]]}, "boundaries.0.region",
     "did you mean 'box'?"),
    ("region extra key", "boundaries.3.region.radius", 1, "boundaries.3.region.radius", "unknown key"),
    ("region all false", "boundaries.0.region", {"all": False}, "boundaries.0.region.all", "Input should be True"),
    ("empty name", "boundaries.0.name", "", "boundaries.0.name", "at least 1 character"),
    # directions are normalised by sqrt(sum of squares): squares that underflow or overflow made them NaN or 0
    ("tiny normal", "boundaries.0.region", {"halfspace": {"point": [0, 0, 0], "normal": [1e-170, 0, 0]}},
     "boundaries.0.region.halfspace.normal", "normal has length 1e-170, too small to normalise in double precision"),
    ("huge facing", "boundaries.0.facing", {"direction": [0, -1e160, 1e160], "max_angle_deg": 30},
     "boundaries.0.facing.direction", "direction has length 1.41e+160, too large to normalise in double precision; "
     "only its direction counts: give it a length near 1"),
    # names are printed in one-line messages: a newline split them, ESC drove the terminal
    ("name with a newline", "boundaries.0.name", "clamp\n\x1b[31m", "boundaries.0.name",
     "holds the control character U+000A at position 5; it is shown in messages, as one line of plain text"),
    ("mesh name with NUL", "geometry.mesh", "part\x00.stl", "geometry.mesh", "holds the control character U+0000 at position 4"),
    ("mesh name with a line separator", "geometry.mesh", "a\u2028b.stl", "geometry.mesh", "control character U+2028"),
    ("quasistatic steps", "analysis", {"kind": "quasistatic", "steps": 0}, "analysis.steps",
     "greater than or equal to 1"),
    ("dynamic dt", "analysis", {"kind": "dynamic", "time_step": 0, "steps": 5}, "analysis.time_step",
     "greater than 0"),
    ("dynamic missing steps", "analysis", {"kind": "dynamic", "time_step": 0.01}, "analysis.steps",
     "required key is missing"),
    ("rtol one", "solver.rtol", 1, "solver.rtol", "less than 1"),
    ("iterations zero", "solver.max_iterations", 0, "solver.max_iterations", "greater than or equal to 1"),
    ("arch gpu", "solver.arch", "gpu", "solver.arch", "'cpu', 'cuda' or 'auto'"),
    ("staggered solver", "method.solver", "cholmod", "method.solver", "'auto', 'direct' or 'iterative'"),
    ("dimension 4", "dimension", 4, "dimension", "2 or 3"),
    ("no material", "material", DELETE, "material", "required key is missing"),
]


@pytest.mark.parametrize(("path", "value", "where", "phrase"), [case[1:] for case in BAD], ids=[c[0] for c in BAD])
def test_bad_input_names_field_and_reason(path: str, value: object, where: str, phrase: str) -> None:
    (line,) = _errors(_edit(DESIGN_EXAMPLE, path, value))
    location, _, reason = line.partition(": ")
    assert location == where
    assert phrase in reason
    assert "Value error" not in reason and "[type=" not in reason


def test_several_errors_reported_together() -> None:
    data = _edit(_edit(DESIGN_EXAMPLE, "material.poisson_ratio", 0.7), "solver.precision", "f16")
    assert _errors(data) == [
        "material.poisson_ratio: Input should be less than 0.5",
        "solver.precision: Input should be 'f64' or 'f32'",
    ]
    data = _edit(_edit(DESIGN_EXAMPLE, "loads.gravity", [0, 1]), "boundaries.1.region.halfspace.point", [0, 0])
    assert _errors(data) == [
        "loads.gravity: expected 3 components (dimension 3), got 2",
        "boundaries.1.region.halfspace.point: expected 3 components (dimension 3), got 2",
    ]


def test_2d_dimension_errors() -> None:
    base = {**MINIMAL, "dimension": 2, "geometry": {"polygon": SQUARE_WITH_HOLE}}
    assert _errors(_edit(base, "geometry.polygon.1.2", [0.75, 0.75, 0])) == [
        "geometry.polygon.1.2: expected 2 components (dimension 2), got 3"
    ]
    assert _errors({**base, "loads": {"gravity": [0, 0, -9.81]}}) == [
        "loads.gravity: expected 2 components (dimension 2), got 3"
    ]
    assert _errors(_edit(base, "geometry.transform", _rotation_z(0.1, (0, 0, 0)))) == [
        "geometry.transform: expected a 3x3 matrix (dimension 2), got 4x4"
    ]
    assert _errors(_edit(base, "geometry.polygon.0", [[0, 0], [1, 0]])) == [
        "geometry.polygon.0: List should have at least 3 items after validation, not 2"
    ]
    assert _errors(_edit(base, "geometry.mesh", "outline.svg")) == [
        "geometry: exactly one of 'mesh' or 'polygon' is required, got both"
    ]


def test_field_and_cross_field_errors_reported_together() -> None:
    # A field error does not hide a dimension error elsewhere (nor the other way round).
    data = _edit(_edit(DESIGN_EXAMPLE, "material.poisson_ratio", 0.5), "loads.gravity", [0, 0])
    assert _errors(data) == [
        "material.poisson_ratio: Input should be less than 0.5",
        "loads.gravity: expected 3 components (dimension 3), got 2",
    ]
    edits = {
        "geometry.transform": [[0, -1, 0], [1, 0, 0], [0, 0, 1]],
        "grid.padding": -1,
        "material.poisson_ratio": 0.5,
        "boundaries.0.region.box": [[0, 0], [1, 1, 1]],
        "boundaries.2.value": [None, None],
        "boundaries.3.region.sphere": {"center": [0, 0], "radius": -1},
        "output.probes": [[0, 0], [1, 1, 1, 1]],
    }
    data = DESIGN_EXAMPLE
    for path, value in edits.items():
        data = _edit(data, path, value)
    assert _errors(data) == [  # document order
        "geometry.transform: expected a 4x4 matrix (dimension 3), got 3x3",
        "grid.padding: Input should be greater than or equal to 0",
        "material.poisson_ratio: Input should be less than 0.5",
        "boundaries.0.region.box.0: expected 3 components (dimension 3), got 2",
        "boundaries.2.value: expected 3 components (dimension 3), got 2",
        "boundaries.3.region.sphere.center: expected 3 components (dimension 3), got 2",
        "boundaries.3.region.sphere.radius: Input should be greater than 0",
        "output.probes.0: expected 3 components (dimension 3), got 2",
        "output.probes.1: expected 3 components (dimension 3), got 4",
    ]
    polygon_in_3d = _edit(_edit(MINIMAL, "geometry", {"polygon": SQUARE_WITH_HOLE, "scale": 0}), "loads", {})
    assert _errors(_edit(polygon_in_3d, "loads.gravity", [1])) == [
        "geometry.polygon: requires dimension 2, got dimension 3",  # not one line per 2-component vertex
        "geometry.scale: Input should be greater than 0",
        "loads.gravity: expected 3 components (dimension 3), got 1",
    ]


@pytest.mark.parametrize("dimension", [4, "3", None, [3]])
def test_invalid_dimension_is_the_only_dimension_error(dimension: object) -> None:
    # Nothing can be compared with an invalid dimension: no length, polygon or transform errors.
    data = _edit(DESIGN_EXAMPLE, "dimension", dimension)
    data = _edit(_edit(data, "loads.gravity", [0, -9.81]), "geometry.transform", [[0, -1, 0], [1, 0, 0], [0, 0, 1]])
    data = _edit(data, "material.youngs_modulus", -1)
    (dimension_line, youngs_line) = _errors(data)
    assert dimension_line.startswith("dimension: Input should be 2 or 3") or dimension_line.startswith(
        "dimension: expected 2 or 3")
    assert youngs_line == "material.youngs_modulus: Input should be greater than 0"
    polygon = _edit(_edit(MINIMAL, "dimension", dimension), "geometry", {"polygon": SQUARE_WITH_HOLE})
    (line,) = _errors(polygon)
    assert line.startswith("dimension: ")


def test_sub_models_alone_have_no_dimension() -> None:
    # The dimension applies only while a JobSpec is validated, also after one failed.
    with pytest.raises(SpecError):
        parse_job(_edit(MINIMAL, "loads", {"gravity": [0, 0]}))
    assert LoadsSpec(gravity=(0, -9.81)).gravity == (0.0, -9.81)
    assert LoadsSpec(gravity=(0, 0, -9.81)).gravity == (0.0, 0.0, -9.81)
    assert GeometrySpec(polygon=SQUARE_WITH_HOLE).polygon[0][2] == (1.0, 1.0)
    # ... and an instance handed to a JobSpec is revalidated against its dimension.
    with pytest.raises(ValidationError) as info:
        JobSpec(
            geometry=GeometrySpec(polygon=SQUARE_WITH_HOLE),
            grid=GridSpec(resolution=8),
            material=MaterialSpec(youngs_modulus=1e6, poisson_ratio=0.2),
            loads=LoadsSpec(gravity=(0, -9.81)),
        )
    assert format_errors(info.value) == [
        "geometry.polygon: requires dimension 2, got dimension 3",
        "loads.gravity: expected 3 components (dimension 3), got 2",
    ]


def test_format_errors_matches_spec_error_lines() -> None:
    bad = _edit(DESIGN_EXAMPLE, "method", {"kind": "dg", "degree": 3, "flux": "xx"})
    with pytest.raises(ValidationError) as info:
        JobSpec.model_validate(bad)
    lines = format_errors(info.value)
    assert lines == ["method.degree: Input should be 1 or 2", "method.flux: Input should be 'ip' or 'bz'"]
    assert _errors(bad) == lines


# --- JSON text ----------------------------------------------------------------------------------


def test_json_syntax_error_is_clear() -> None:
    text = '{\n  "geometry": {"mesh": "part.stl"}\n  "grid": {"resolution": 8}\n}'
    with pytest.raises(SpecError) as info:
        parse_job(text)
    assert info.value.errors == ["(json): Expecting ',' delimiter at line 3, column 3"]
    assert str(info.value) == "invalid job spec:\n  (json): Expecting ',' delimiter at line 3, column 3"
    assert isinstance(info.value.__cause__, json.JSONDecodeError)
    assert isinstance(info.value, ValueError)


def test_json_document_errors() -> None:
    assert _errors("[1, 2]") == ["(root): expected a JSON object, got array"]
    assert _errors('{"grid": {"cell_size": 1, "cell_size": 2}}') == [
        "(json): duplicate key 'cell_size' in an object with keys 'cell_size', 'cell_size'"
    ]
    # Python's json module reads the non-standard NaN literal; validation then names the field.
    text = json.dumps(MINIMAL).replace('"youngs_modulus": 2000000.0', '"youngs_modulus": NaN')
    assert _errors(text) == ["material.youngs_modulus: must be a finite number, got nan"]
    assert _errors(b"\x80{}")[0].startswith("(json): cannot decode the text as utf-8")


def test_facing_on_any_boundary_round_trips_and_names_bad_values() -> None:
    facing = {"direction": [1, 0, 0], "max_angle_deg": 30}
    spec = _edit(DESIGN_EXAMPLE, "boundaries.3.facing", facing)
    job = parse_job(spec)
    assert job.boundaries[3].facing.direction == (1.0, 0.0, 0.0) and job.boundaries[3].facing.max_angle_deg == 30
    assert parse_job(job.to_json()) == job
    import jsonschema

    jsonschema.validate(json.loads(job.to_json()), json.loads(SCHEMA_PATH.read_text()))
    assert _errors(_edit(spec, "boundaries.3.facing.max_angle_deg", 0)) == [
        "boundaries.3.facing.max_angle_deg: Input should be greater than 0"]
    assert _errors(_edit(spec, "boundaries.3.facing.direction", [0, 0, 0])) == [
        "boundaries.3.facing.direction: direction must be non-zero"]
    assert _errors(_edit(spec, "boundaries.3.facing.direction", [1, 0])) == [
        "boundaries.3.facing.direction: expected 3 components (dimension 3), got 2"]


def test_json_that_python_refuses_to_read_is_a_spec_error() -> None:
    # json.loads raises ValueError / RecursionError here; the CLI printed a traceback
    with pytest.raises(SpecError) as info:
        parse_job('{"dimension": 1' + "0" * 5000 + "}")
    assert info.value.errors == ["(json): the spec holds an integer with more than 4300 digits"]
    with pytest.raises(SpecError) as info:
        parse_job("[" * 100_000 + "]" * 100_000)
    assert info.value.errors[0].startswith("(json): the spec nests arrays or objects too deeply")
    with pytest.raises(SpecError) as info:  # a long wrong value is shortened in the message
        parse_job(_edit(MINIMAL, "grid", {"resolution": "1" * 5000}))
    assert info.value.errors == ["grid.resolution: expected an integer, got '11111111111111111111111111111... "
                                 "(5002 characters)"]
