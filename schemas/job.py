"""The job specification (DESIGN.md "Job spec"): Pydantic v2 models, parsing and error formatting.

Conventions shared by every model:

- unknown keys are errors (``extra="forbid"``; the message suggests the closest known key);
- every float must be finite (NaN/inf rejected: JSON has none, but Python callers can pass them);
- SI units throughout: metres, pascals, kg/m^3, seconds, m/s^2;
- vectors are tuples whose length must equal ``JobSpec.dimension``. Sub-models accept any length
  and :class:`JobSpec` checks them all at once, so the error names the field
  (``loads.gravity: expected 3 components (dimension 3), got 2``);
- tagged unions (``method``, ``boundaries``, ``analysis``, regions) dispatch on their tag before
  validating, so a mistake is reported by the chosen branch alone, at a path without union tags.
"""

from __future__ import annotations

import difflib
import json
import math
from collections.abc import Iterator, Mapping
from typing import Annotated, Any, Literal, Union

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, WrapValidator, field_validator, model_validator
from pydantic_core import PydanticCustomError

Loc = tuple[Union[str, int], ...]

ROTATION_TOLERANCE = 1e-6
"""Largest entry of |R^T R - I| accepted for the linear part of ``geometry.transform``."""


def _error(kind: str, reason: str) -> PydanticCustomError:
    # The reason goes through ctx, not the template, so braces in user input are never expanded.
    return PydanticCustomError(kind, "{reason}", {"reason": reason})


def _raise_at(title: str, issues: list[tuple[Loc, str, str, Any]]) -> None:
    """Raise one ValidationError for (relative location, type, reason, input) issues, if any.

    Raised inside a validator, pydantic prefixes each location with the validator's own path.
    """
    if issues:
        raise ValidationError.from_exception_data(
            title,
            [{"type": _error(kind, reason), "loc": loc, "input": value} for loc, kind, reason, value in issues],
        )


def _quoted(names: Iterator[str] | list[str]) -> str:
    return ", ".join(repr(n) for n in names)


class _SpecModel(BaseModel):
    """Base of every spec model: strict about keys, finite floats, nothing else implicit."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    @model_validator(mode="before")
    @classmethod
    def _reject_unknown_keys(cls, data: Any) -> Any:
        # Reported before field validation so that a misspelt key gives one error with a hint,
        # not "unknown key" plus "field required" for the key that was meant.
        if isinstance(data, Mapping):
            known = list(cls.model_fields)
            issues = []
            for key in data:
                if key in known:
                    continue
                close = difflib.get_close_matches(str(key), known, n=1)
                hint = f"did you mean {close[0]!r}?" if close else f"allowed keys: {_quoted(known)}"
                issues.append(((str(key),), "unknown_key", f"unknown key; {hint}", data[key]))
            _raise_at(cls.__name__, issues)
        return data

    def _vectors(self) -> Iterator[tuple[Loc, tuple]]:
        """(relative location, vector) of every vector whose length must equal the dimension."""
        return iter(())


def _tag_dispatch(tag: str, choices: dict[str, type[_SpecModel]]) -> WrapValidator:
    """Validate a tagged union by its ``tag`` key only, so errors come from the chosen branch."""
    types = tuple(choices.values())
    expected = _quoted(list(choices))

    def validate(value: Any, handler: Any) -> Any:
        if isinstance(value, types):
            return value
        if not isinstance(value, Mapping):
            raise _error("object_type", f"expected an object with a {tag!r} key ({expected}), got {value!r}")
        if tag not in value:
            _raise_at(tag, [((tag,), "missing_tag", f"missing; expected one of {expected}", None)])
        model = choices.get(value[tag]) if isinstance(value[tag], str) else None
        if model is None:
            reason = f"unknown {tag} {value[tag]!r}; expected one of {expected}"
            _raise_at(tag, [((tag,), "unknown_tag", reason, value[tag])])
        return model.model_validate(value)

    return WrapValidator(validate)


def _require_kind(schema: dict[str, Any]) -> None:
    # The models default ``kind`` for Python callers, but a JSON document must name it.
    schema["properties"]["kind"].pop("default", None)
    schema["required"] = ["kind", *schema.get("required", [])]


_TAGGED = ConfigDict(json_schema_extra=_require_kind)


def _not_null(schema: dict[str, Any]) -> None:
    # For exactly-one-of pairs: the JSON document omits the unused key rather than writing null,
    # so the schema's oneOf-of-required can tell the two cases apart.
    schema.update(next(b for b in schema.pop("anyOf") if b != {"type": "null"}))
    schema.pop("default", None)


# A vector in R^dimension. The schema states 2..3 items; the exact length is checked by JobSpec.
Vector = Annotated[tuple[float, ...], Field(json_schema_extra={"minItems": 2, "maxItems": 3})]


# --- geometry and grid -------------------------------------------------------------------------


class GeometrySpec(_SpecModel):
    """The solid: a surface mesh file, or (2D only) a polygon with holes.

    Exactly one of ``mesh`` / ``polygon``. Points are mapped by ``x -> R (scale x) + t`` where
    ``transform = [[R, t], [0, 1]]`` (scale first, then the rigid transform).
    """

    model_config = ConfigDict(json_schema_extra={"oneOf": [{"required": ["mesh"]}, {"required": ["polygon"]}]})

    mesh: Annotated[str, Field(min_length=1)] | None = Field(
        None,
        json_schema_extra=_not_null,
        description="Surface mesh file (STL/OBJ/PLY/OFF...; SVG/DXF in 2D). CLI: a path relative to the "
        "spec file or absolute; service: the uploaded file's name.",
    )
    polygon: Annotated[list[Annotated[list[Vector], Field(min_length=3)]], Field(min_length=1)] | None = Field(
        None,
        json_schema_extra=_not_null,
        description="2D only: closed loops of [x, y] vertices [m] (last joins first); a point is inside "
        "when an odd number of loops enclose it (outer boundaries and holes, any orientation).",
    )
    scale: float = Field(1.0, gt=0, description="Factor applied to the coordinates (unit conversion) [-].")
    transform: tuple[tuple[float, ...], ...] | None = Field(
        None,
        description="Rigid transform as a homogeneous matrix (4x4 in 3D, 3x3 in 2D): linear part a proper "
        f"rotation (orthonormal to {ROTATION_TOLERANCE:g}, det +1), bottom row [0, ..., 0, 1]; translation in m.",
    )

    @field_validator("transform")
    @classmethod
    def _check_rigid(cls, m: tuple[tuple[float, ...], ...] | None) -> tuple[tuple[float, ...], ...] | None:
        if m is None:
            return m
        n = len(m)
        lengths = [len(row) for row in m]
        if n not in (3, 4) or any(k != n for k in lengths):
            shape = f"{n}x{lengths[0]}" if len(set(lengths)) == 1 else f"{n} rows of lengths {lengths}"
            raise _error("transform_shape", f"must be a 3x3 (2D) or 4x4 (3D) homogeneous matrix, got {shape}")
        a = np.asarray(m, dtype=float)
        bottom = np.zeros(n)
        bottom[-1] = 1.0
        if np.abs(a[-1] - bottom).max() > ROTATION_TOLERANCE:
            raise _error("transform_rigid", f"bottom row must be {bottom.astype(int).tolist()}, got {list(m[-1])}")
        r = a[:-1, :-1]
        deviation = float(np.abs(r.T @ r - np.eye(n - 1)).max())
        if deviation > ROTATION_TOLERANCE:
            raise _error(
                "transform_rigid",
                f"linear part is not a rotation: max |R^T R - I| = {deviation:.3g} > {ROTATION_TOLERANCE:g} "
                "(only rotation + translation; use geometry.scale for scaling)",
            )
        if np.linalg.det(r) < 0:
            raise _error("transform_rigid", "linear part has determinant -1 (a reflection); a proper rotation has +1")
        return m

    @model_validator(mode="after")
    def _one_source(self) -> GeometrySpec:
        if (self.mesh is None) == (self.polygon is None):
            got = "both" if self.mesh is not None else "neither"
            raise _error("geometry_source", f"exactly one of 'mesh' or 'polygon' is required, got {got}")
        return self

    def _vectors(self) -> Iterator[tuple[Loc, tuple]]:
        for i, loop in enumerate(self.polygon or ()):
            for j, vertex in enumerate(loop):
                yield ("polygon", i, j), vertex


class GridSpec(_SpecModel):
    """The background grid: exactly one of ``cell_size`` / ``resolution``, plus empty padding."""

    model_config = ConfigDict(json_schema_extra={"oneOf": [{"required": ["cell_size"]}, {"required": ["resolution"]}]})

    cell_size: float | None = Field(None, gt=0, json_schema_extra=_not_null, description="Cell edge h [m].")
    resolution: int | None = Field(
        None, ge=1, json_schema_extra=_not_null, description="Cells along the longest side of the bounding box."
    )
    padding: int = Field(1, ge=0, description="Cells of empty space added on every side.")

    @model_validator(mode="after")
    def _one_size(self) -> GridSpec:
        if (self.cell_size is None) == (self.resolution is None):
            got = "both" if self.cell_size is not None else "neither"
            raise _error("grid_size", f"exactly one of 'cell_size' or 'resolution' is required, got {got}")
        return self


# --- method -------------------------------------------------------------------------------------


class StaggeredMethod(_SpecModel):
    """Volume-fraction staggered-grid finite differences (dolny-2025)."""

    model_config = _TAGGED
    kind: Literal["staggered"] = "staggered"


class DGMethod(_SpecModel):
    """Hex-sliced discontinuous Galerkin (kaufmann-2009)."""

    model_config = _TAGGED
    kind: Literal["dg"] = "dg"
    degree: Literal[1, 2] = Field(1, description="Total polynomial degree per element.")
    flux: Literal["ip", "bz"] = Field("ip", description="'ip' symmetric interior penalty, 'bz' Babuska-Zlamal.")
    penalty: float = Field(20.0, gt=0, description="Penalty factor eta [-]: face weight eta*area*(1/vol- + 1/vol+).")


Method = Annotated[
    Union[StaggeredMethod, DGMethod],
    Field(discriminator="kind"),
    _tag_dispatch("kind", {"staggered": StaggeredMethod, "dg": DGMethod}),
]


# --- material and loads ------------------------------------------------------------------------


class MaterialSpec(_SpecModel):
    """Homogeneous isotropic elastic material."""

    youngs_modulus: float = Field(gt=0, description="Young's modulus E [Pa].")
    poisson_ratio: float = Field(ge=0, lt=0.5, description="Poisson's ratio nu [-], 0 <= nu < 0.5.")
    density: float = Field(1000.0, gt=0, description="Mass density rho [kg/m^3].")
    model: Literal["linear", "corotated"] = Field("linear", description="Small-strain or corotated elasticity.")


class LoadsSpec(_SpecModel):
    """Body loads."""

    gravity: Vector | None = Field(
        None, description="Gravitational acceleration [m/s^2], length dimension; null/absent = zero vector."
    )

    def _vectors(self) -> Iterator[tuple[Loc, tuple]]:
        if self.gravity is not None:
            yield ("gravity",), self.gravity


# --- regions ------------------------------------------------------------------------------------


class BoxRegion(_SpecModel):
    """Axis-aligned box: min <= x <= max componentwise [m]."""

    box: tuple[Vector, Vector] = Field(description="[[min...], [max...]] corners [m].")

    @field_validator("box")
    @classmethod
    def _ordered(cls, box: tuple[tuple[float, ...], tuple[float, ...]]) -> tuple:
        lo, hi = box
        if len(lo) == len(hi):  # otherwise JobSpec reports the corner with the wrong length
            for axis, (a, b) in enumerate(zip(lo, hi)):
                if not a < b:
                    raise _error("box_order", f"min must be < max in every component (axis {axis}: {a:g} >= {b:g})")
        return box

    def _vectors(self) -> Iterator[tuple[Loc, tuple]]:
        yield ("box", 0), self.box[0]
        yield ("box", 1), self.box[1]


class Sphere(_SpecModel):
    """Ball |x - center| <= radius."""

    center: Vector = Field(description="Centre [m].")
    radius: float = Field(gt=0, description="Radius [m].")


class SphereRegion(_SpecModel):
    sphere: Sphere

    def _vectors(self) -> Iterator[tuple[Loc, tuple]]:
        yield ("sphere", "center"), self.sphere.center


class Halfspace(_SpecModel):
    """Half-space (x - point) . normal <= 0: the normal points out of the region.

    ``normal`` is kept as given (any non-zero length); consumers normalise it.
    """

    point: Vector = Field(description="A point on the bounding plane [m].")
    normal: Vector = Field(description="Outward normal of the region (non-zero, need not be unit).")

    @field_validator("normal")
    @classmethod
    def _nonzero(cls, normal: tuple[float, ...]) -> tuple[float, ...]:
        if math.hypot(*normal) == 0:
            raise _error("zero_normal", "normal must be non-zero")
        return normal


class HalfspaceRegion(_SpecModel):
    halfspace: Halfspace

    def _vectors(self) -> Iterator[tuple[Loc, tuple]]:
        yield ("halfspace", "point"), self.halfspace.point
        yield ("halfspace", "normal"), self.halfspace.normal


class AllRegion(_SpecModel):
    """Everything: all material (displacement) or the whole surface (traction, pressure)."""

    all: Literal[True]


_REGIONS: dict[str, type[_SpecModel]] = {
    "box": BoxRegion, "sphere": SphereRegion, "halfspace": HalfspaceRegion, "all": AllRegion
}


def _region_dispatch(value: Any, handler: Any) -> Any:
    """A region is an object with exactly one key naming its shape; validate that branch only."""
    if isinstance(value, tuple(_REGIONS.values())):
        return value
    if not isinstance(value, Mapping):
        raise _error("region_type", f"expected an object with one of {_quoted(list(_REGIONS))}, got {value!r}")
    shapes = [k for k in value if k in _REGIONS]
    if len(shapes) != 1:
        got = _quoted(list(map(str, value))) if value else "an empty object"
        hints = [difflib.get_close_matches(str(k), list(_REGIONS), n=1) for k in value if k not in _REGIONS]
        hint = "".join(f"; did you mean {h[0]!r}?" for h in hints if h) if not shapes else ""
        raise _error("region_shape", f"must have exactly one of {_quoted(list(_REGIONS))}, got {got}{hint}")
    return _REGIONS[shapes[0]].model_validate(value)


Region = Annotated[Union[BoxRegion, SphereRegion, HalfspaceRegion, AllRegion], WrapValidator(_region_dispatch)]


# --- boundary conditions ------------------------------------------------------------------------


class _Boundary(_SpecModel):
    kind: str  # declared first so that it leads in dumps and the schema; narrowed by each subclass
    name: str | None = Field(None, min_length=1, description="Label used in messages and results.")
    region: Region

    def _vectors(self) -> Iterator[tuple[Loc, tuple]]:
        for loc, vector in self.region._vectors():
            yield ("region", *loc), vector


class DisplacementBoundary(_Boundary):
    """Prescribed displacement of the material inside the region; null components stay free."""

    model_config = _TAGGED
    kind: Literal["displacement"] = "displacement"
    value: tuple[float | None, ...] = Field(
        description="Displacement [m] per component, null = free (length dimension, at least one number).",
        json_schema_extra={"minItems": 2, "maxItems": 3},
    )

    @field_validator("value")
    @classmethod
    def _constrains_something(cls, value: tuple[float | None, ...]) -> tuple[float | None, ...]:
        if all(v is None for v in value):
            raise _error("all_free", "at least one component must be a number (all null constrains nothing)")
        return value

    def _vectors(self) -> Iterator[tuple[Loc, tuple]]:
        yield from super()._vectors()
        yield ("value",), self.value


class TractionBoundary(_Boundary):
    """Traction vector on the part of the surface inside the region."""

    model_config = _TAGGED
    kind: Literal["traction"] = "traction"
    value: Vector = Field(description="Traction (force per area) [Pa], length dimension.")

    def _vectors(self) -> Iterator[tuple[Loc, tuple]]:
        yield from super()._vectors()
        yield ("value",), self.value


class PressureBoundary(_Boundary):
    """Normal pressure on the part of the surface inside the region."""

    model_config = _TAGGED
    kind: Literal["pressure"] = "pressure"
    value: float = Field(description="Pressure [Pa]; positive pushes into the surface.")


Boundary = Annotated[
    Union[DisplacementBoundary, TractionBoundary, PressureBoundary],
    Field(discriminator="kind"),
    _tag_dispatch(
        "kind", {"displacement": DisplacementBoundary, "traction": TractionBoundary, "pressure": PressureBoundary}
    ),
]


# --- analysis, solver, output -------------------------------------------------------------------


class StaticAnalysis(_SpecModel):
    """One equilibrium solve with the full loads."""

    model_config = _TAGGED
    kind: Literal["static"] = "static"


class QuasistaticAnalysis(_SpecModel):
    """A sequence of equilibrium solves with the loads ramped linearly over ``steps``."""

    model_config = _TAGGED
    kind: Literal["quasistatic"] = "quasistatic"
    steps: int = Field(ge=1, description="Number of load steps.")


class DynamicAnalysis(_SpecModel):
    """Implicit time stepping from rest."""

    model_config = _TAGGED
    kind: Literal["dynamic"] = "dynamic"
    time_step: float = Field(gt=0, description="Time step dt [s].")
    steps: int = Field(ge=1, description="Number of time steps.")


Analysis = Annotated[
    Union[StaticAnalysis, QuasistaticAnalysis, DynamicAnalysis],
    Field(discriminator="kind"),
    _tag_dispatch(
        "kind", {"static": StaticAnalysis, "quasistatic": QuasistaticAnalysis, "dynamic": DynamicAnalysis}
    ),
]


class SolverSpec(_SpecModel):
    """Linear solver settings."""

    rtol: float = Field(1e-8, gt=0, lt=1, description="Relative residual tolerance [-].")
    max_iterations: int = Field(5000, ge=1, description="Iteration cap of the iterative solver.")
    precision: Literal["f64", "f32"] = Field("f64", description="Floating-point precision of the solve.")
    arch: Literal["cpu", "cuda", "auto"] = Field("auto", description="Taichi backend; auto = CUDA if present.")


FieldName = Literal["displacement", "strain", "stress", "von_mises"]


class OutputSpec(_SpecModel):
    """What the result file contains."""

    fields: list[FieldName] = Field(
        default_factory=lambda: ["displacement"],
        description="Cell-centre fields to write (no duplicates).",
        json_schema_extra={"uniqueItems": True},
    )
    probes: list[Vector] = Field(default_factory=list, description="Points [m] where fields are sampled.")
    surface: bool = Field(True, description="Write the deformed surface mesh.")

    @field_validator("fields")
    @classmethod
    def _unique(cls, fields: list[str]) -> list[str]:
        repeated = sorted({f for f in fields if fields.count(f) > 1})
        if repeated:
            raise _error("duplicate_field", f"duplicate entries {_quoted(repeated)}")
        return fields

    def _vectors(self) -> Iterator[tuple[Loc, tuple]]:
        for i, point in enumerate(self.probes):
            yield ("probes", i), point


# --- the job ------------------------------------------------------------------------------------


class JobSpec(_SpecModel):
    """A complete simulation job (DESIGN.md "Job spec"). SI units throughout."""

    model_config = ConfigDict(title="JobSpec")

    dimension: Literal[2, 3] = Field(3, description="2 (plane strain, planar geometry) or 3.")
    geometry: GeometrySpec
    grid: GridSpec
    method: Method = Field(default_factory=StaggeredMethod)
    material: MaterialSpec
    loads: LoadsSpec = Field(default_factory=LoadsSpec)
    boundaries: list[Boundary] = Field(default_factory=list)
    analysis: Analysis = Field(default_factory=StaticAnalysis)
    solver: SolverSpec = Field(default_factory=SolverSpec)
    output: OutputSpec = Field(default_factory=OutputSpec)

    @model_validator(mode="after")
    def _check_dimension(self) -> JobSpec:
        d = self.dimension
        issues: list[tuple[Loc, str, str, Any]] = []
        geometry = self.geometry
        if geometry.polygon is not None and d != 2:
            issues.append(
                (("geometry", "polygon"), "polygon_dimension", f"requires dimension 2, got dimension {d}", None)
            )
        if geometry.transform is not None and len(geometry.transform) != d + 1:
            n = len(geometry.transform)
            reason = f"expected a {d + 1}x{d + 1} matrix (dimension {d}), got {n}x{n}"
            issues.append((("geometry", "transform"), "transform_dimension", reason, geometry.transform))
        parts: list[tuple[Loc, _SpecModel]] = [(("loads",), self.loads), (("output",), self.output)]
        if geometry.polygon is not None and d == 2:
            parts.append((("geometry",), geometry))
        parts += [(("boundaries", i), b) for i, b in enumerate(self.boundaries)]
        for prefix, part in parts:
            for loc, vector in part._vectors():
                if len(vector) != d:
                    reason = f"expected {d} components (dimension {d}), got {len(vector)}"
                    issues.append(((*prefix, *loc), "vector_length", reason, vector))
        _raise_at(type(self).__name__, issues)
        if self.loads.gravity is None:
            self.loads = self.loads.model_copy(update={"gravity": (0.0,) * d})
        return self

    def to_json(self, indent: int | None = None) -> str:
        """Canonical JSON of the validated spec: every default filled in, unused optional keys omitted.

        ``parse_job(spec.to_json()) == spec``, and the text validates against the JSON Schema.
        """
        return self.model_dump_json(exclude_none=True, indent=indent)


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
            raise _DuplicateKey(f"(json): duplicate key {key!r} in an object with keys {_quoted(k for k, _ in pairs)}")
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
