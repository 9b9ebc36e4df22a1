"""The job specification (reference: the exported JSON Schema, schemas/json/job.schema.json): the models of a job, parsing and error formatting.

The conventions every model follows (unknown keys, finite floats, SI units, vectors coupled to
``JobSpec.dimension``, tagged unions) are stated in :mod:`schemas.base`; regions live in
:mod:`schemas.regions`.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from typing import Annotated, Any, Literal, Union

import numpy as np
from pydantic import (
    AfterValidator,
    ConfigDict,
    Field,
    ModelWrapValidatorHandler,
    TypeAdapter,
    ValidationError,
    field_validator,
    model_validator,
)

from .base import (
    INTEGER,
    REAL,
    TAGGED,
    Flag,
    Integer,
    Real,
    SpecModel,
    Text,
    Vector,
    check_length,
    current_dimension,
    custom_error,
    dimension_scope,
    integer_choice,
    not_null,
    quoted,
    raise_at,
    tag_dispatch,
)
from .regions import Facing, Region

ROTATION_TOLERANCE = 1e-6
"""Largest entry of |R^T R - I| accepted for the linear part of ``geometry.transform``."""


# --- geometry and grid -------------------------------------------------------------------------


class GeometrySpec(SpecModel):
    """The solid: a surface mesh file, or (2D only) a polygon with holes.

    Exactly one of ``mesh`` / ``polygon``. Points are mapped by ``x -> R (scale x) + t`` where
    ``transform = [[R, t], [0, 1]]`` (scale first, then the rigid transform).
    """

    model_config = ConfigDict(json_schema_extra={"oneOf": [{"required": ["mesh"]}, {"required": ["polygon"]}]})

    mesh: Text | None = Field(
        None,
        json_schema_extra=not_null,
        description="Surface mesh file (STL/OBJ/PLY/OFF...; SVG/DXF in 2D). CLI: a path relative to the "
        "spec file or absolute; service: the uploaded file's name.",
    )
    polygon: Annotated[list[Annotated[list[Vector], Field(min_length=3)]], Field(min_length=1)] | None = Field(
        None,
        json_schema_extra=not_null,
        description="2D only: closed loops of [x, y] vertices [m] (last joins first); a point is inside "
        "when an odd number of loops enclose it (outer boundaries and holes, any orientation).",
    )
    scale: Real = Field(1.0, gt=0, description="Factor applied to the coordinates (unit conversion) [-].")
    transform: tuple[tuple[Real, ...], ...] | None = Field(
        None,
        description="Rigid transform as a homogeneous matrix (4x4 in 3D, 3x3 in 2D): linear part a proper "
        f"rotation (orthonormal to {ROTATION_TOLERANCE:g}, det +1), bottom row [0, ..., 0, 1]; translation in m.",
    )

    @field_validator("polygon", mode="before")
    @classmethod
    def _planar(cls, polygon: Any) -> Any:
        # Before the vertices are validated: in 3D each one would otherwise be reported as short.
        d = current_dimension()
        if polygon is not None and d is not None and d != 2:
            raise custom_error("polygon_dimension", f"requires dimension 2, got dimension {d}")
        return polygon

    @field_validator("transform")
    @classmethod
    def _check_rigid(cls, m: tuple[tuple[float, ...], ...] | None) -> tuple[tuple[float, ...], ...] | None:
        if m is None:
            return m
        n = len(m)
        lengths = [len(row) for row in m]
        if n not in (3, 4) or any(k != n for k in lengths):
            shape = f"{n}x{lengths[0]}" if len(set(lengths)) == 1 else f"{n} rows of lengths {lengths}"
            raise custom_error("transform_shape", f"must be a 3x3 (2D) or 4x4 (3D) homogeneous matrix, got {shape}")
        d = current_dimension()
        if d is not None and n != d + 1:
            reason = f"expected a {d + 1}x{d + 1} matrix (dimension {d}), got {n}x{n}"
            raise custom_error("transform_dimension", reason)
        a = np.asarray(m, dtype=float)
        bottom = np.zeros(n)
        bottom[-1] = 1.0
        if np.abs(a[-1] - bottom).max() > ROTATION_TOLERANCE:
            reason = f"bottom row must be {bottom.astype(int).tolist()}, got {list(m[-1])}"
            raise custom_error("transform_rigid", reason)
        r = a[:-1, :-1]
        deviation = float(np.abs(r.T @ r - np.eye(n - 1)).max())
        if deviation > ROTATION_TOLERANCE:
            raise custom_error(
                "transform_rigid",
                f"linear part is not a rotation: max |R^T R - I| = {deviation:.3g} > {ROTATION_TOLERANCE:g} "
                "(only rotation + translation; use geometry.scale for scaling)",
            )
        if np.linalg.det(r) < 0:
            reason = "linear part has determinant -1 (a reflection); a proper rotation has +1"
            raise custom_error("transform_rigid", reason)
        return m

    @model_validator(mode="after")
    def _one_source(self) -> GeometrySpec:
        if (self.mesh is None) == (self.polygon is None):
            got = "both" if self.mesh is not None else "neither"
            raise custom_error("geometry_source", f"exactly one of 'mesh' or 'polygon' is required, got {got}")
        return self


class GridSpec(SpecModel):
    """The background grid: exactly one of ``cell_size`` / ``resolution``, plus empty padding."""

    model_config = ConfigDict(json_schema_extra={"oneOf": [{"required": ["cell_size"]}, {"required": ["resolution"]}]})

    cell_size: Annotated[float | None, REAL] = Field(None, gt=0, json_schema_extra=not_null, description="Cell edge h [m].")
    resolution: Annotated[int | None, INTEGER] = Field(
        None, ge=1, json_schema_extra=not_null, description="Cells along the longest side of the bounding box."
    )
    padding: Integer = Field(1, ge=0, description="Cells of empty space added on every side.")

    @model_validator(mode="after")
    def _one_size(self) -> GridSpec:
        if (self.cell_size is None) == (self.resolution is None):
            got = "both" if self.cell_size is not None else "neither"
            raise custom_error("grid_size", f"exactly one of 'cell_size' or 'resolution' is required, got {got}")
        return self


# --- method -------------------------------------------------------------------------------------


class StaggeredMethod(SpecModel):
    """Volume-fraction staggered-grid finite differences (dolny-2025)."""

    model_config = TAGGED
    kind: Literal["staggered"] = "staggered"
    solver: Literal["auto", "direct", "iterative"] = Field(
        "auto", description="Linear solver: 'direct' sparse Cholesky of the whole problem (its memory grows "
                            "superlinearly), 'iterative' CG preconditioned by a multigrid V-cycle (to solver.rtol), "
                            "'auto' direct when the grid has at most 60,000 displacement samples (the dimension "
                            "times the product of cells + 1 per axis; only those beside material are unknowns).")


class DGMethod(SpecModel):
    """Hex-sliced discontinuous Galerkin (kaufmann-2009)."""

    model_config = TAGGED
    kind: Literal["dg"] = "dg"
    degree: Annotated[Literal[1, 2], integer_choice(1, 2)] = Field(1, description="Total polynomial degree per element.")
    flux: Literal["ip", "bz"] = Field("ip", description="'ip' symmetric interior penalty, 'bz' Babuska-Zlamal.")
    penalty: Annotated[float | None, REAL] = Field(
        None, gt=0, json_schema_extra=not_null,
        description="Penalty factor eta [-]: face weight eta*area*(1/vol- + 1/vol+); doubled until the matrix is "
                    "positive definite (above nu ~0.495 the volumetric terms' penalty is raised alone first, by "
                    "1.25 up to twice eta). Default by degree: 2.5 (k=1), 5 (k=2); a larger eta stiffens both "
                    "(k=2 near curved surfaces).")
    solver: Literal["auto", "direct", "iterative"] = Field(
        "auto", description="Linear solver: 'direct' sparse Cholesky (its memory grows superlinearly), 'iterative' CG "
                            "preconditioned by p-multigrid onto degree k-1 (to solver.rtol), 'auto' iterative above "
                            "100,000 unknowns for k=1 and 50,000 for k=2 (400,000 / 200,000 when lambda/mu > 100, "
                            "nu > 0.495, where CG needs many more iterations).")


Method = Annotated[
    Union[StaggeredMethod, DGMethod],
    Field(discriminator="kind"),
    tag_dispatch("kind", {"staggered": StaggeredMethod, "dg": DGMethod}),
]


# --- material and loads ------------------------------------------------------------------------


# Material scales and time steps outside this range overflow or underflow in the solvers' f64
# arithmetic (E = 1e308 broke the eigen-solve of the rigid modes, 1e-308 let the hold's penalty
# vanish, dt = 1e-300 squared to zero): the range is far wider than any material or step.
SCALE_RANGE = (1e-100, 1e100)


def _in_scale(unit: str) -> AfterValidator:
    def check(value: float) -> float:
        lo, hi = SCALE_RANGE
        if not lo <= value <= hi:
            raise custom_error("scale_range", f"{value:g} {unit} is outside {lo:g} .. {hi:g} {unit}, the range the "
                               "solvers' arithmetic is checked over")
        return value

    return AfterValidator(check)


SCALE_SCHEMA = {"minimum": SCALE_RANGE[0], "maximum": SCALE_RANGE[1]}


class MaterialSpec(SpecModel):
    """Homogeneous isotropic elastic material."""

    youngs_modulus: Annotated[Real, _in_scale("Pa")] = Field(gt=0, json_schema_extra=SCALE_SCHEMA,
                                                          description="Young's modulus E [Pa].")
    poisson_ratio: Real = Field(ge=0, lt=0.5, description="Poisson's ratio nu [-], 0 <= nu < 0.5.")
    density: Annotated[Real, _in_scale("kg/m^3")] = Field(1000.0, gt=0, json_schema_extra=SCALE_SCHEMA,
                                                          description="Mass density rho [kg/m^3].")
    model: Literal["linear", "corotated"] = Field("linear", description="Small-strain or corotated elasticity.")


# Loads and prescribed values beyond this magnitude overflow the solvers' f64 arithmetic: the load
# vector's squared norm passes 1e308 (a traction or gravity of 1e308, a displacement of 1e308 in
# the Nitsche terms) and the job failed in the solve with "the load vector is not finite", after it
# was accepted and queued. The body force density x gravity is bounded alike (JobSpec).
LOAD_LIMIT = 1e100


def _load(unit: str) -> Any:
    """A number of at most LOAD_LIMIT in magnitude [``unit``]: a load or prescribed value."""

    def check(value: float) -> float:
        if abs(value) > LOAD_LIMIT:
            raise custom_error("load_range", f"{value:g} {unit} is beyond +-{LOAD_LIMIT:g} {unit}, the range the "
                               "solvers' arithmetic is checked over")
        return value

    return Annotated[Real, AfterValidator(check), Field(json_schema_extra={"minimum": -LOAD_LIMIT, "maximum": LOAD_LIMIT})]


def _load_vector(unit: str) -> Any:
    """A vector (length dimension, as :data:`Vector`) of loads in ``unit``."""
    return Annotated[tuple[_load(unit), ...], Field(json_schema_extra={"minItems": 2, "maxItems": 3}),
                     AfterValidator(check_length)]


class LoadsSpec(SpecModel):
    """Body loads."""

    gravity: _load_vector("m/s^2") | None = Field(
        None, description="Gravitational acceleration [m/s^2], length dimension; null/absent = zero vector."
    )


# --- boundary conditions ------------------------------------------------------------------------


class _Boundary(SpecModel):
    kind: str  # declared first so that it leads in dumps and the schema; narrowed by each subclass
    name: Text | None = Field(None, description="Label used in messages and results.")
    region: Region
    facing: Facing | None = Field(
        None, description="Optional: keep only the facets of the patch whose outward normal faces this way."
    )


class DisplacementBoundary(_Boundary):
    """Prescribed displacement of the surface patch (the mesh surface inside the region); null
    components stay free."""

    model_config = TAGGED
    kind: Literal["displacement"] = "displacement"
    value: Annotated[tuple[_load("m") | None, ...], AfterValidator(check_length)] = Field(
        description="Displacement [m] per component, null = free (length dimension, at least one number).",
        json_schema_extra={"minItems": 2, "maxItems": 3},
    )

    @field_validator("value")
    @classmethod
    def _constrains_something(cls, value: tuple[float | None, ...]) -> tuple[float | None, ...]:
        if all(v is None for v in value):
            raise custom_error("all_free", "at least one component must be a number (all null constrains nothing)")
        return value


class TractionBoundary(_Boundary):
    """Traction vector on the part of the surface inside the region."""

    model_config = TAGGED
    kind: Literal["traction"] = "traction"
    value: _load_vector("Pa") = Field(description="Traction (force per area) [Pa], length dimension.")


class PressureBoundary(_Boundary):
    """Normal pressure on the part of the surface inside the region."""

    model_config = TAGGED
    kind: Literal["pressure"] = "pressure"
    value: _load("Pa") = Field(description="Pressure [Pa]; positive pushes into the surface.")


Boundary = Annotated[
    Union[DisplacementBoundary, TractionBoundary, PressureBoundary],
    Field(discriminator="kind"),
    tag_dispatch(
        "kind", {"displacement": DisplacementBoundary, "traction": TractionBoundary, "pressure": PressureBoundary}
    ),
]


# --- analysis, solver, output -------------------------------------------------------------------


MAX_STEPS = 10_000
"""Most steps of a quasi-static or dynamic job: the result names each step's group with four digits
(``steps/0000`` .. ``steps/9999``), and a job with more used to run to the end and fail writing."""


def _fits_the_result(steps: int) -> int:
    if steps > MAX_STEPS:
        raise custom_error("too_many_steps", f"{steps} steps; a result holds at most {MAX_STEPS} (each step is a "
                           "numbered group of the file): take fewer, longer steps")
    return steps


Steps = Annotated[Integer, AfterValidator(_fits_the_result)]


class StaticAnalysis(SpecModel):
    """One equilibrium solve with the full loads."""

    model_config = TAGGED
    kind: Literal["static"] = "static"


class QuasistaticAnalysis(SpecModel):
    """A sequence of equilibrium solves with the loads ramped linearly over ``steps``."""

    model_config = TAGGED
    kind: Literal["quasistatic"] = "quasistatic"
    steps: Steps = Field(ge=1, json_schema_extra={"maximum": MAX_STEPS}, description="Number of load steps.")


class DynamicAnalysis(SpecModel):
    """Implicit time stepping from rest."""

    model_config = TAGGED
    kind: Literal["dynamic"] = "dynamic"
    time_step: Annotated[Real, _in_scale("s")] = Field(gt=0, json_schema_extra=SCALE_SCHEMA, description="Time step dt [s].")
    steps: Steps = Field(ge=1, json_schema_extra={"maximum": MAX_STEPS}, description="Number of time steps.")


Analysis = Annotated[
    Union[StaticAnalysis, QuasistaticAnalysis, DynamicAnalysis],
    Field(discriminator="kind"),
    tag_dispatch(
        "kind", {"static": StaticAnalysis, "quasistatic": QuasistaticAnalysis, "dynamic": DynamicAnalysis}
    ),
]


class SolverSpec(SpecModel):
    """Linear solver settings."""

    rtol: Real = Field(1e-8, gt=0, lt=1, description="Relative residual tolerance [-].")
    max_iterations: Integer = Field(5000, ge=1, description="Iteration cap of the iterative solver.")
    precision: Literal["f64", "f32"] = Field("f64", description=(
        "Floating-point precision of the solve. f32 halves the vectors, but the smallest residual it resolves "
        "grows with the operator's conditioning (a held shell at 48^3: 1.6e-4 at poisson_ratio 0.3, 1.9e-2 at "
        "0.499): near 0.5 keep f64."))
    arch: Literal["cpu", "cuda", "auto"] = Field("auto", description="Taichi backend; auto = CUDA if present.")


FieldName = Literal["displacement", "velocity", "strain", "stress", "von_mises", "pressure"]


class OutputSpec(SpecModel):
    """What the result file contains."""

    fields: list[FieldName] = Field(
        default_factory=lambda: ["displacement"],
        description="Cell-centre fields to write (no duplicates).",
        json_schema_extra={"uniqueItems": True},
    )
    probes: list[Vector] = Field(default_factory=list, description="Points [m] where fields are sampled.")
    surface: Flag = Field(True, description="Write the deformed surface mesh.")
    every: Integer = Field(1, ge=1, description="Quasi-static and dynamic runs: keep every n-th step in the "
                           "result (steps n, 2n, ... and always the last); 1 keeps them all.")

    @field_validator("fields")
    @classmethod
    def _unique(cls, fields: list[str]) -> list[str]:
        repeated = sorted({f for f in fields if fields.count(f) > 1})
        if repeated:
            raise custom_error("duplicate_field", f"duplicate entries {quoted(repeated)}")
        return fields


# --- the job ------------------------------------------------------------------------------------

Dimension = Annotated[Literal[2, 3], integer_choice(2, 3)]
_DIMENSION_ADAPTER = TypeAdapter(Dimension)


class JobSpec(SpecModel):
    """A complete simulation job. SI units throughout."""

    model_config = ConfigDict(title="JobSpec")

    dimension: Dimension = Field(3, description="2 (plane strain, planar geometry) or 3.")
    geometry: GeometrySpec
    grid: GridSpec
    method: Method = Field(default_factory=StaggeredMethod)
    material: MaterialSpec
    loads: LoadsSpec = Field(default_factory=LoadsSpec)
    boundaries: list[Boundary] = Field(default_factory=list)
    analysis: Analysis = Field(default_factory=StaticAnalysis)
    solver: SolverSpec = Field(default_factory=SolverSpec)
    output: OutputSpec = Field(default_factory=OutputSpec)

    @model_validator(mode="wrap")
    @classmethod
    def _couple_dimension(cls, data: Any, handler: ModelWrapValidatorHandler[JobSpec]) -> JobSpec:
        # The fields are validated inside a scope holding the declared dimension, so vector lengths,
        # the polygon and the transform are checked at their own fields, alongside every other error.
        # An invalid dimension is reported by its field; nothing is compared with it.
        with dimension_scope(_declared_dimension(cls, data)):
            return handler(data)

    @model_validator(mode="after")
    def _velocity_is_dynamic(self) -> JobSpec:
        if "velocity" in self.output.fields and self.analysis.kind != "dynamic":
            i = self.output.fields.index("velocity")
            raise_at("JobSpec", [(("output", "fields", i), "velocity_static", "'velocity' needs analysis.kind "
                                  f"'dynamic' (a {self.analysis.kind} state has none)", "velocity")])
        return self

    @model_validator(mode="after")
    def _every_is_stepped(self) -> JobSpec:
        if self.output.every != 1 and self.analysis.kind == "static":
            raise_at("JobSpec", [(("output", "every"), "every_static", "keeps every n-th step of a quasi-static or "
                                  "dynamic run; a static run has one state (leave it at 1)", self.output.every)])
        return self

    @property
    def kept_steps(self) -> int:
        """How many steps the result keeps: every ``output.every``-th of a quasi-static or dynamic
        run and its last; 0 for a static run (its result holds the final state alone)."""
        if self.analysis.kind == "static":
            return 0
        return -(-self.analysis.steps // self.output.every)

    @model_validator(mode="after")
    def _body_force_in_range(self) -> JobSpec:
        g = self.loads.gravity
        force = self.material.density * math.hypot(*g) if g is not None else 0.0
        if force > LOAD_LIMIT:
            raise_at("JobSpec", [(("loads", "gravity"), "load_range", f"the body force material.density x |gravity| "
                                  f"= {force:.3g} N/m^3 is beyond {LOAD_LIMIT:g} N/m^3, the range the solvers' "
                                  "arithmetic is checked over", g)])
        return self

    @model_validator(mode="after")
    def _zero_gravity(self) -> JobSpec:
        if self.loads.gravity is None:
            self.loads = self.loads.model_copy(update={"gravity": (0.0,) * self.dimension})
        return self

    def to_json(self, indent: int | None = None) -> str:
        """Canonical JSON of the validated spec: every default filled in, unused optional keys omitted.

        ``parse_job(spec.to_json()) == spec``, and the text validates against the JSON Schema.
        """
        return self.model_dump_json(exclude_none=True, indent=indent)


def _declared_dimension(cls: type[JobSpec], data: Any) -> int | None:
    """The dimension ``data`` declares (or the default), or None if that value is itself invalid."""
    if isinstance(data, cls):
        return data.dimension
    if not isinstance(data, Mapping):
        return None
    try:
        return _DIMENSION_ADAPTER.validate_python(data.get("dimension", cls.model_fields["dimension"].default))
    except ValidationError:
        return None


# --- parsing and errors -------------------------------------------------------------------------


class SpecError(ValueError):
    """An invalid job spec (bad JSON or failed validation); ``errors`` holds one line per problem.

    Each line reads ``path.to.field: reason`` (list indices as numbers); ``__cause__`` keeps the
    underlying ``pydantic.ValidationError`` or ``json.JSONDecodeError``.
    """

    def __init__(self, errors: list[str]) -> None:
        self.errors = list(errors)
        super().__init__("invalid job spec:\n" + "\n".join(f"  {line}" for line in self.errors))


_PREFIXES = ("Value error, ", "Assertion failed, ")


def format_errors(exc: ValidationError | SpecError) -> list[str]:
    """One line per error: ``path.to.field: reason``; ``(root)`` for errors of the whole document."""
    if isinstance(exc, SpecError):
        return list(exc.errors)
    lines = []
    for err in exc.errors():
        path = ".".join(str(part) for part in err["loc"]) or "(root)"
        reason = err["msg"]
        for prefix in _PREFIXES:
            reason = reason.removeprefix(prefix)
        if err["type"] == "finite_number":
            reason = f"must be a finite number, got {err['input']!r}"
        elif err["type"] == "missing":
            reason = "required key is missing"
        elif err["type"] == "extra_forbidden":
            reason = "unknown key"
        lines.append(f"{path}: {reason}")
    return lines


def _json_type(value: Any) -> str:
    names = {dict: "object", list: "array", str: "string", bool: "boolean", int: "number", float: "number"}
    return "null" if value is None else names.get(type(value), type(value).__name__)


class _DuplicateKey(ValueError):
    pass


def _reject_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    # json.loads keeps the last of repeated keys silently; a repeated key is a mistake in a spec.
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise _DuplicateKey(f"(json): duplicate key {key!r} in an object with keys {quoted(k for k, _ in pairs)}")
        out[key] = value
    return out


def parse_job(data: Mapping[str, Any] | str | bytes | bytearray) -> JobSpec:
    """Validate a job spec given as a mapping or as JSON text; raise :class:`SpecError` if invalid."""
    if isinstance(data, (str, bytes, bytearray)):
        try:
            data = json.loads(data, object_pairs_hook=_reject_duplicates)
        except json.JSONDecodeError as exc:
            raise SpecError([f"(json): {exc.msg} at line {exc.lineno}, column {exc.colno}"]) from exc
        except UnicodeDecodeError as exc:
            reason = f"(json): cannot decode the text as {exc.encoding} ({exc.reason} at byte {exc.start})"
            raise SpecError([reason]) from exc
        except _DuplicateKey as exc:
            raise SpecError([str(exc)]) from exc
        except RecursionError as exc:
            raise SpecError(["(json): the spec nests arrays or objects too deeply (nearly 1000 levels); a job spec "
                             "needs fewer than 10"]) from exc
        except ValueError as exc:  # Python's own limit: "Exceeds the limit (4300 digits) for integer string conversion"
            raise SpecError(["(json): the spec holds an integer with more than 4300 digits" if "digits" in str(exc)
                             else f"(json): {exc}"]) from exc
    if not isinstance(data, Mapping):
        raise SpecError([f"(root): expected a JSON object, got {_json_type(data)}"])
    try:
        return JobSpec.model_validate(dict(data))
    except ValidationError as exc:
        raise SpecError(format_errors(exc)) from exc


def job_json_schema() -> dict[str, Any]:
    """JSON Schema (draft 2020-12) of the job spec, as committed in ``schemas/json/job.schema.json``.

    The schema cannot express the dimension coupling (vector lengths, polygon only in 2D) or the
    rotation check of ``geometry.transform``; :func:`parse_job` enforces those.
    """
    schema = JobSpec.model_json_schema()
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", **schema}
