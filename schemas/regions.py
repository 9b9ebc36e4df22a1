"""Regions of space that boundary conditions act on: box, sphere, half-space or everything [m].

A region is a JSON object with exactly one key naming its shape (``{"box": [[...], [...]]}``);
:data:`Region` validates the branch that key names and no other.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Mapping
from typing import Annotated, Any, Literal, Union

from pydantic import Field, WrapValidator, field_validator

from .base import FLAG, Real, SpecModel, Vector, custom_error, quoted


class BoxRegion(SpecModel):
    """Axis-aligned box: min <= x <= max componentwise [m]."""

    box: tuple[Vector, Vector] = Field(description="[[min...], [max...]] corners [m].")

    @field_validator("box")
    @classmethod
    def _ordered(cls, box: tuple[tuple[float, ...], tuple[float, ...]]) -> tuple:
        lo, hi = box
        # Corners of different lengths are only possible without a dimension (a BoxRegion on its
        # own); inside a JobSpec the corner with the wrong length has already been reported.
        if len(lo) == len(hi):
            for axis, (a, b) in enumerate(zip(lo, hi)):
                if not a < b:
                    reason = f"min must be < max in every component (axis {axis}: {a:g} >= {b:g})"
                    raise custom_error("box_order", reason)
        return box


class Sphere(SpecModel):
    """Ball |x - center| <= radius."""

    center: Vector = Field(description="Centre [m].")
    radius: Real = Field(gt=0, description="Radius [m].")


class SphereRegion(SpecModel):
    sphere: Sphere


def _nonzero(vector: tuple[float, ...], name: str) -> tuple[float, ...]:
    """Validator: a direction must have a length (error type zero_<name>) that double precision can
    normalise (error type <name>_length): the engine divides by sqrt(sum of squares), whose squares
    underflow to 0 below about 1e-154 (a normal [1e-170, 0, 0] made every region test NaN) and
    overflow to inf above about 1e154 (a direction [1e160, 0, 0] became (0, 0, 0))."""
    length = math.hypot(*vector)
    if length == 0:
        raise custom_error(f"zero_{name}", f"{name} must be non-zero")
    if not 0 < math.fsum(v * v for v in vector) < math.inf:
        raise custom_error(f"{name}_length", f"{name} has length {length:.3g}, too {'small' if length < 1 else 'large'} "
                           "to normalise in double precision; only its direction counts: give it a length near 1")
    return vector


class Halfspace(SpecModel):
    """Half-space (x - point) . normal <= 0: the normal points out of the region.

    ``normal`` is kept as given (any non-zero length); consumers normalise it.
    """

    point: Vector = Field(description="A point on the bounding plane [m].")
    normal: Vector = Field(description="Outward normal of the region (non-zero, need not be unit).")

    _nonzero = field_validator("normal")(lambda v: _nonzero(v, "normal"))


class HalfspaceRegion(SpecModel):
    halfspace: Halfspace


class Facing(SpecModel):
    """Keeps only the facets of a patch whose outward normal lies within ``max_angle_deg`` of
    ``direction`` (e.g. a bar's end face out of a half-space that also takes side strips along)."""

    direction: Vector = Field(description="Direction the kept facets face (non-zero, need not be unit).")
    max_angle_deg: Real = Field(
        gt=0, le=180, description="Largest angle [degrees] between a kept facet's outward normal and direction."
    )

    _nonzero = field_validator("direction")(lambda v: _nonzero(v, "direction"))


class AllRegion(SpecModel):
    """Everything: all material (displacement) or the whole surface (traction, pressure)."""

    all: Annotated[Literal[True], FLAG]


_REGIONS: dict[str, type[SpecModel]] = {
    "box": BoxRegion, "sphere": SphereRegion, "halfspace": HalfspaceRegion, "all": AllRegion
}


def _region_dispatch(value: Any, handler: Any) -> Any:
    """A region is an object with exactly one key naming its shape; validate that branch only."""
    if isinstance(value, tuple(_REGIONS.values())):
        return type(value).model_validate(value)
    if not isinstance(value, Mapping):
        raise custom_error("region_type", f"expected an object with one of {quoted(_REGIONS)}, got {value!r}")
    shapes = [k for k in value if k in _REGIONS]
    if len(shapes) != 1:
        got = quoted(map(str, value)) if value else "an empty object"
        hints = [difflib.get_close_matches(str(k), list(_REGIONS), n=1) for k in value if k not in _REGIONS]
        hint = "".join(f"; did you mean {h[0]!r}?" for h in hints if h) if not shapes else ""
        raise custom_error("region_shape", f"must have exactly one of {quoted(_REGIONS)}, got {got}{hint}")
    return _REGIONS[shapes[0]].model_validate(value)


Region = Annotated[Union[BoxRegion, SphereRegion, HalfspaceRegion, AllRegion], WrapValidator(_region_dispatch)]
