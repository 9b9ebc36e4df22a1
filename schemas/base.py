"""What every job-spec model shares: the base model, error helpers, tagged unions and dimension-bound vectors.

Conventions shared by every model:

- unknown keys are errors (``extra="forbid"``; the message suggests the closest known key);
- every float must be finite (NaN/inf rejected: JSON has none, but Python callers can pass them);
- SI units throughout: metres, pascals, kg/m^3, seconds, m/s^2;
- vectors (:data:`Vector`) must have ``JobSpec.dimension`` components. :class:`JobSpec` reads its
  dimension from the raw input and opens a :func:`dimension_scope` around the validation of its
  fields, so each coupled check runs at its own field, next to that field's other checks, and every
  problem of a document is reported at once (``loads.gravity: expected 3 components (dimension 3),
  got 2`` beside ``material.poisson_ratio: ...``). A sub-model validated on its own has no
  dimension and accepts 2 or 3 components; passed into a :class:`JobSpec` it is revalidated
  (``revalidate_instances="always"``), so the coupling holds for Python callers too;
- tagged unions (``method``, ``boundaries``, ``analysis``, regions) dispatch on their tag before
  validating, so a mistake is reported by the chosen branch alone, at a path without union tags.
"""

from __future__ import annotations

import difflib
import re
from collections.abc import Iterable, Iterator, Mapping
from contextlib import contextmanager
from contextvars import ContextVar
from typing import Annotated, Any, Union

from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    ValidationError,
    WrapValidator,
    model_validator,
)
from pydantic_core import PydanticCustomError

Loc = tuple[Union[str, int], ...]


def custom_error(kind: str, reason: str) -> PydanticCustomError:
    """A validation error of type ``kind`` whose message is exactly ``reason``."""
    # The reason goes through ctx, not the template, so braces in user input are never expanded.
    return PydanticCustomError(kind, "{reason}", {"reason": reason})


def raise_at(title: str, issues: list[tuple[Loc, str, str, Any]]) -> None:
    """Raise one ValidationError for (relative location, type, reason, input) issues, if any.

    Raised inside a validator, pydantic prefixes each location with the validator's own path.
    """
    if issues:
        raise ValidationError.from_exception_data(
            title,
            [{"type": custom_error(kind, reason), "loc": loc, "input": value} for loc, kind, reason, value in issues],
        )


def quoted(names: Iterable[str]) -> str:
    """``'a', 'b', 'c'``: names as they appear in messages."""
    return ", ".join(repr(n) for n in names)


# --- the dimension a document declares ----------------------------------------------------------

_DIMENSION: ContextVar[int | None] = ContextVar("voxelastic_spec_dimension", default=None)


@contextmanager
def dimension_scope(dimension: int | None) -> Iterator[None]:
    """Within the block, validated vectors must have ``dimension`` components (None: 2 or 3, unchecked)."""
    token = _DIMENSION.set(dimension)
    try:
        yield
    finally:
        _DIMENSION.reset(token)


def current_dimension() -> int | None:
    """The dimension of the job spec being validated, or None outside one (or if its own value is invalid)."""
    return _DIMENSION.get()


def check_length(vector: tuple) -> tuple:
    """Validator: ``vector`` has :func:`current_dimension` components, when there is one."""
    d = current_dimension()
    if d is not None and len(vector) != d:
        raise custom_error("vector_length", f"expected {d} components (dimension {d}), got {len(vector)}")
    return vector


# --- scalars of their JSON type ------------------------------------------------------------------
# pydantic's lax mode turns true into 1.0, "1e7" into 1e7 and 2.0 into 2: a spec that says
# "youngs_modulus": true would run with E = 1 Pa. Values must have the JSON type the schema states;
# numpy scalars (Python callers) count as the Python scalars they hold.


def _plain(value: Any) -> Any:
    item = getattr(value, "item", None)
    return item() if callable(item) and getattr(value, "shape", None) == () else value


def _json_name(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float, str)):
        text = repr(value)
        return text if len(text) <= 40 else f"{text[:30]}... ({len(text)} characters)"
    return {list: "an array", tuple: "an array", dict: "an object"}.get(type(value), type(value).__name__)


def _is_integer(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def of_type(expected: str, accepts: Any) -> BeforeValidator:
    """Validator: the value (numpy scalars unwrapped) passes ``accepts``, else "expected ``expected``"."""

    def check(value: Any) -> Any:
        value = _plain(value)
        if value is not None and not accepts(value):  # None: for the optional fields' own check
            raise custom_error("json_type", f"expected {expected}, got {_json_name(value)}")
        return value

    return BeforeValidator(check)


# (an optional field puts the check around its union, ``Annotated[float | None, REAL]``, where the
# field's own constraints still reach the JSON Schema)
REAL = of_type("a number", lambda v: isinstance(v, (int, float)) and not isinstance(v, bool))
INTEGER = of_type("an integer", _is_integer)
FLAG = of_type("true or false", lambda v: isinstance(v, bool))
Real = Annotated[float, REAL]


def integer_choice(*choices: int) -> BeforeValidator:
    """Validator of an integer ``Literal``: 2.0 or true is not 2 or 1."""
    return of_type(" or ".join(map(str, choices)), _is_integer)


Integer = Annotated[int, INTEGER]
Flag = Annotated[bool, FLAG]

# Text the engine puts into its messages (a boundary's name, the mesh file's name) must not break
# the line it is printed on or drive the terminal that shows it: no C0/C1 control characters
# (newline, tab, ESC, NUL), DEL, or Unicode line and paragraph separators. A name holding "\n\x1b[31m"
# split a one-line CLI error in two and coloured the rest red.
_CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f\u2028\u2029]")


def _one_line(text: str) -> str:
    found = _CONTROL.search(text)
    if found:
        raise custom_error("control_character", f"holds the control character U+{ord(found.group()):04X} at "
                           f"position {found.start()}; it is shown in messages, as one line of plain text")
    return text


# One line of plain text, not empty (the JSON Schema states the same as a pattern, in ECMA-262 escapes)
Text = Annotated[str, Field(min_length=1, json_schema_extra={"pattern": r"^[^\u0000-\u001f\u007f-\u009f\u2028\u2029]*$"}),
                 AfterValidator(_one_line)]

# A vector in R^dimension. The schema states 2..3 items; the exact length needs the document's dimension.
Vector = Annotated[
    tuple[Real, ...], Field(json_schema_extra={"minItems": 2, "maxItems": 3}), AfterValidator(check_length)
]


# --- models -------------------------------------------------------------------------------------


class SpecModel(BaseModel):
    """Base of every spec model: strict about keys, finite floats, nothing else implicit."""

    # Instances handed to a parent are revalidated so that the parent's dimension applies to them.
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, revalidate_instances="always")

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
                hint = f"did you mean {close[0]!r}?" if close else f"allowed keys: {quoted(known)}"
                issues.append(((str(key),), "unknown_key", f"unknown key; {hint}", data[key]))
            raise_at(cls.__name__, issues)
        return data


def tag_dispatch(tag: str, choices: dict[str, type[SpecModel]]) -> WrapValidator:
    """Validate a tagged union by its ``tag`` key only, so errors come from the chosen branch."""
    types = tuple(choices.values())
    expected = quoted(choices)

    def validate(value: Any, handler: Any) -> Any:
        if isinstance(value, types):
            return type(value).model_validate(value)
        if not isinstance(value, Mapping):
            raise custom_error("object_type", f"expected an object with a {tag!r} key ({expected}), got {value!r}")
        if tag not in value:
            raise_at(tag, [((tag,), "missing_tag", f"missing; expected one of {expected}", None)])
        model = choices.get(value[tag]) if isinstance(value[tag], str) else None
        if model is None:
            reason = f"unknown {tag} {value[tag]!r}; expected one of {expected}"
            raise_at(tag, [((tag,), "unknown_tag", reason, value[tag])])
        return model.model_validate(value)

    return WrapValidator(validate)


def _require_kind(schema: dict[str, Any]) -> None:
    # The models default ``kind`` for Python callers, but a JSON document must name it.
    schema["properties"]["kind"].pop("default", None)
    schema["required"] = ["kind", *schema.get("required", [])]


TAGGED = ConfigDict(json_schema_extra=_require_kind)
"""Config of a tagged-union branch: ``kind`` is required in the JSON Schema."""


def not_null(schema: dict[str, Any]) -> None:
    """``json_schema_extra`` of one key of an exactly-one-of pair: absent rather than null in JSON."""
    # The schema's oneOf-of-required can then tell the two cases apart.
    schema.update(next(b for b in schema.pop("anyOf") if b != {"type": "null"}))
    schema.pop("default", None)
