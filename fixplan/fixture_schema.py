"""The fixture file format, declared once: one pydantic model per TOML table.

Each key is declared once, with its type, unit, range, default and description, as a field of
a :class:`Table` model (``mass: Annotated[float, Number(...)] = Field(description=...)``).
The same declaration

* validates a parsed file (:func:`validate_document`): every problem becomes an
  :class:`~fixplan.errors.Issue` with its dotted key path and what was expected, in the words
  of ``docs/fixture-format.md`` (``workpiece.size[0]: got 300 (expected a length [m] in
  [0.0001, 100]; sizes are in metres; did you write millimetres?)``);
* exports the JSON Schema of the format (:func:`json_schema`, ``fixplan schema``) that TOML
  editors (Taplo / Even Better TOML) use for completion and checks;
* renders the key reference of ``docs/fixture-format.md`` (:func:`markdown_reference`).

Checks that need more than one key's value (the shape's faces, the scene's dimension, unique
names) are declared on the table that holds the keys (:meth:`Table.rules`); checks that need
the whole model (a locator inside the workpiece, goal finding, an inertia possible for the
shape and mass) stay in :mod:`fixplan.fixture`.

Adding a table (``[[obstacle]]``): declare ``class Obstacle(Table)`` with its fields, add
``obstacle: Annotated[tuple[Obstacle, ...], TablesOf("obstacle")] = Field((), description=...)``
to :class:`FixtureFile`, build the model object from it in :mod:`fixplan.fixture`, show the
keys in the example of ``docs/fixture-format.md``, and run ``python tools/fixture_docs.py
--write`` (the JSON Schema and the key table; ``tests/test_fixture_schema.py`` says what is stale).
"""

from __future__ import annotations

import math
import os
import re
import sys
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import contextmanager
from typing import Annotated, Any, ClassVar, NoReturn

from pydantic import BaseModel, ConfigDict, Field, ValidationError, ValidationInfo, model_validator
from pydantic_core import InitErrorDetails, PydanticCustomError, core_schema

from fixplan import limits
from fixplan.errors import Issue, quote_number, shorten
from fixplan.limits import Range
from fixplan.model import SimulationSettings
from fixplan.schema import _as_float, _is_number, _kind

SHAPES_3D = ("box", "cylinder", "sphere", "mesh")
SHAPES_2D = ("rectangle", "disk", "polygon")
# the keys each shape reads besides the common ones; a key of another shape is "not used"
SHAPE_KEYS: dict[str, tuple[str, ...]] = {
    "box": ("size",),
    "rectangle": ("size",),
    "sphere": ("radius",),
    "disk": ("radius",),
    "cylinder": ("radius", "length"),
    "polygon": ("vertices",),
    "mesh": ("file",),
}
# the keys a shape may have besides those (each with a default)
SHAPE_OPTIONAL_KEYS: dict[str, tuple[str, ...]] = {"mesh": ("units", "tolerance")}
MESH_UNITS = ("m", "mm", "in")
FACES = {
    "box": ("+x", "-x", "+y", "-y", "+z", "-z"),
    "rectangle": ("+x", "-x", "+y", "-y"),
    "cylinder": ("+z", "-z", "side"),
}
MAX_SCENE_NAME = 200
NAME_CHARS = r"[\w+\-]"
_NAME = re.compile(f"{NAME_CHARS}{{1,{limits.MAX_NAME_LENGTH}}}")
NAME_RULE = f"a name of 1 to {limits.MAX_NAME_LENGTH} letters, digits, '_', '-' or '+' (no spaces, commas, dots or control characters)"
UNITS_HINT = "sizes are in metres; did you write millimetres?"
VERTEX = Range("a vertex coordinate", "m", -limits.LENGTH_MAX_M, limits.LENGTH_MAX_M)
_ERROR = "fixplan"  # the error type of every message written here


def _fail(message: str, **extra: Any) -> NoReturn:
    raise PydanticCustomError(_ERROR, "{message}", {"message": message, **extra})


def _dimension(info: ValidationInfo) -> int | None:
    return (info.context or {}).get("dimension")


def _unit(bounds: Range | None) -> dict[str, Any]:
    return {"x-unit": bounds.unit} if bounds is not None and bounds.unit else {}


# -- one key's value: the types a field is annotated with ------------------------------------------
class Value(ABC):
    """What a key holds: its check (with the message's words) and its JSON Schema.

    ``dimension`` limits the key to 2D or 3D scenes; in the other one it is an unknown key, or
    refused with ``other_dimension`` when that is given.
    """

    dimension: int | None = None
    other_dimension: str | None = None

    @abstractmethod
    def expected(self, dim: int | None) -> str:
        """The words after "missing (expected ...)"."""

    @abstractmethod
    def schema(self) -> dict[str, Any]:
        """The key's JSON Schema."""

    def __get_pydantic_json_schema__(self, schema: Any, handler: Any) -> dict[str, Any]:
        return self.schema()


class PlainValue(Value):
    """A value read by one function of the raw TOML value (:meth:`check`).

    The other values (vectors, vertex lists, inertia) wrap pydantic's own validation in their core schema.
    """

    @abstractmethod
    def check(self, value: Any, info: ValidationInfo) -> Any:
        """The value as read, or a validation error with the message's words."""

    def __get_pydantic_core_schema__(self, source: Any, handler: Any) -> core_schema.CoreSchema:
        return core_schema.with_info_plain_validator_function(self.check)


class Number(PlainValue):
    """A finite number; ``bounds`` its valid range and unit, ``too_large`` a hint when above it."""

    def __init__(
        self,
        what: str,
        bounds: Range | None = None,
        *,
        minimum: float | None = None,
        exclusive_minimum: float | None = None,
        maximum: float | None = None,
        too_large: str | None = None,
        dimension: int | None = None,
        other_dimension: str | None = None,
    ):
        self.what, self.bounds = what, bounds
        self.minimum, self.exclusive_minimum, self.maximum = minimum, exclusive_minimum, maximum
        self.too_large, self.dimension, self.other_dimension = too_large, dimension, other_dimension

    def expected(self, dim: int | None) -> str:
        return self.what

    def check(self, raw: Any, info: ValidationInfo) -> float:
        what, bounds = self.what, self.bounds
        if not _is_number(raw):
            _fail(f"got {_kind(raw)} (expected {what})")
        value = _as_float(raw)
        if value is None:
            _fail(f"got {_kind(raw)}, too large for a float (expected {what if bounds is None else bounds.expected()})")
        given = quote_number(raw)  # as written, never rounded to the limit
        if not math.isfinite(value):
            _fail(f"got {value} (expected a finite number)")
        if self.exclusive_minimum is not None and value <= self.exclusive_minimum:
            _fail(f"got {given} (expected {what} > {self.exclusive_minimum:g})")
        if self.minimum is not None and value < self.minimum:
            _fail(f"got {given} (expected {what} ≥ {self.minimum:g})")
        if self.maximum is not None and value > self.maximum:
            _fail(f"got {given} (expected {what} ≤ {self.maximum:g})")
        if bounds is not None and not bounds.contains(value):
            above = value > bounds.high
            hint = f"; {self.too_large}" if self.too_large and above else ""
            _fail(f"got {given} (expected {bounds.expected()}{hint})", above=above)
        return value

    def schema(self) -> dict[str, Any]:
        out: dict[str, Any] = {"type": "number"}
        low = [x for x in (self.minimum, self.bounds.low if self.bounds else None) if x is not None]
        high = [x for x in (self.maximum, self.bounds.high if self.bounds else None) if x is not None]
        if self.exclusive_minimum is not None and not (low and max(low) > self.exclusive_minimum):
            out["exclusiveMinimum"] = self.exclusive_minimum
        elif low:
            out["minimum"] = max(low)
        if high:
            out["maximum"] = min(high)
        return out | _unit(self.bounds)


class Vector(Value):
    """``length`` numbers (None: the scene's dimension); every bad element is reported.

    ``too_large`` is a hint added once, to the first element above ``bounds``.
    """

    def __init__(
        self,
        what: str = "numbers",
        length: int | None = None,
        bounds: Range | None = None,
        *,
        too_large: str | None = None,
        dimension: int | None = None,
    ):
        self.what, self.length, self.bounds, self.too_large = what, length, bounds, too_large
        self.dimension = dimension
        self.element = Number("a number", bounds)

    def size(self, dim: int | None) -> int | None:
        return self.length if self.length is not None else dim

    def expected(self, dim: int | None) -> str:
        n = self.size(dim)
        return f"{n} {self.what}" if n is not None else f"2 or 3 {self.what}"

    def __get_pydantic_core_schema__(self, source: Any, handler: Any) -> core_schema.CoreSchema:
        items = core_schema.list_schema(core_schema.with_info_plain_validator_function(self.element.check))
        return core_schema.with_info_wrap_validator_function(self.check_list, items)

    def check_list(self, value: Any, handler: Callable[[Any], list[float]], info: ValidationInfo) -> Any:
        n = self.size(_dimension(info))
        if not isinstance(value, list):
            _fail(f"got {_kind(value)} (expected a list of {self.expected(_dimension(info))})")
        if n is not None and len(value) != n:
            _fail(f"got {len(value)} numbers (expected {n} for a {n}D scene)")
        try:
            return self.after(handler(value), info)
        except ValidationError as exc:
            if self.too_large is None:
                raise
            errors, hinted = exc.errors(), False
            for error in errors:  # the units hint once, on the first element above the range
                ctx = error.get("ctx") or {}
                if not hinted and ctx.get("above"):
                    ctx["message"] = ctx["message"][:-1] + f"; {self.too_large})"
                    hinted = True
            raise _errors(type(self).__name__, [(e["loc"], (e.get("ctx") or {})["message"]) for e in errors]) from None

    def after(self, values: list[float], info: ValidationInfo) -> Any:
        return tuple(values)

    def schema(self) -> dict[str, Any]:
        out: dict[str, Any] = {"type": "array", "items": self.element.schema()}
        out["minItems"], out["maxItems"] = (self.length, self.length) if self.length else (2, 3)
        return out | _unit(self.bounds)


class Direction(Vector):
    """A non-zero vector, returned as given (normalised by the loader)."""

    def after(self, values: list[float], info: ValidationInfo) -> Any:
        scale = max(abs(x) for x in values)  # normalised in two steps: [1e300, 1e300] does not overflow
        if scale <= 1e-12 or not math.isfinite(math.hypot(*(x / scale for x in values))):
            _fail("got a zero vector (expected a direction)")
        return tuple(values)

    def schema(self) -> dict[str, Any]:
        finite = {"type": "number", "minimum": -sys.float_info.max, "maximum": sys.float_info.max}
        return super().schema() | {"items": finite, "not": {"items": {"const": 0}}}


class Integer(PlainValue):
    """One of a few integers (``format = 1``, ``dimension = 2 | 3``)."""

    def __init__(self, allowed: tuple[int, ...]):
        self.allowed = allowed

    def expected(self, dim: int | None) -> str:
        return " or ".join(str(a) for a in self.allowed)

    def check(self, value: Any, info: ValidationInfo) -> int:
        if not isinstance(value, int) or isinstance(value, bool) or value not in self.allowed:
            _fail(f"got {_kind(value)} (expected {self.expected(None)})")
        return int(value)

    def schema(self) -> dict[str, Any]:
        return {"type": "integer", "enum": list(self.allowed)}


class Text(PlainValue):
    """A non-empty string, one of ``choices`` when given."""

    def __init__(self, choices: tuple[str, ...] | None = None, *, what: str = "a string"):
        self.choices, self.what = choices, what

    def expected(self, dim: int | None) -> str:
        return f"one of: {', '.join(self.choices)}" if self.choices else self.what

    def check(self, value: Any, info: ValidationInfo) -> str:
        if not isinstance(value, str) or not value.strip():
            _fail(f"got {_kind(value)} (expected a non-empty string)")
        if self.choices is not None and value not in self.choices:
            _fail(f"got {shorten(value)} (expected one of: {', '.join(self.choices)})")
        return value

    def schema(self) -> dict[str, Any]:
        if self.choices:
            return {"type": "string", "enum": list(self.choices)}
        return {"type": "string", "minLength": 1, "pattern": r"\S"}


class SceneName(Text):
    """``scene.name``: printable, at most 200 characters (it is printed in results)."""

    def check(self, value: Any, info: ValidationInfo) -> str:
        value = super().check(value, info)
        if not value.isprintable() or len(value) > MAX_SCENE_NAME:
            _fail(f"expected a printable name of at most {MAX_SCENE_NAME} characters (no newlines or control codes)")
        return value

    def schema(self) -> dict[str, Any]:
        return super().schema() | {"maxLength": MAX_SCENE_NAME}


class Name(PlainValue):
    """A locator's or contact's name: it appears in messages, CSV headers and ``--contacts A,B``."""

    def expected(self, dim: int | None) -> str:
        return "a unique name"

    def check(self, value: Any, info: ValidationInfo) -> str:
        if not isinstance(value, str) or not value.strip():
            _fail("expected a non-empty string")
        if not is_name(value):
            _fail(f"got {shorten(value)} (expected {NAME_RULE})")
        return value

    def schema(self) -> dict[str, Any]:
        return {"type": "string", "pattern": f"^{NAME_CHARS}{{1,{limits.MAX_NAME_LENGTH}}}$"}


def is_name(value: Any) -> bool:
    """A valid locator or contact name (entries are addressed by it in messages)."""
    return isinstance(value, str) and _NAME.fullmatch(value) is not None


class ShapeName(PlainValue):
    """``workpiece.shape``: one of the shapes of the scene's dimension."""

    def expected(self, dim: int | None) -> str:
        return f"one of: {', '.join(SHAPES_2D if dim == 2 else SHAPES_3D)}"

    def check(self, value: Any, info: ValidationInfo) -> str:
        dim = _dimension(info) or 3
        other = SHAPES_2D if dim == 3 else SHAPES_3D
        if isinstance(value, str) and value in other:
            _fail(
                f"got {value!r}, a {5 - dim}D shape (expected one of: "
                f"{', '.join(SHAPES_3D if dim == 3 else SHAPES_2D)} for a {dim}D scene)"
            )
        return Text(SHAPES_3D if dim == 3 else SHAPES_2D).check(value, info)

    def schema(self) -> dict[str, Any]:
        return {"type": "string", "enum": [*SHAPES_3D, *SHAPES_2D]}


class Face(PlainValue):
    """A locator's face hint: a face of the workpiece's shape."""

    def expected(self, dim: int | None) -> str:
        return "a face"

    def check(self, value: Any, info: ValidationInfo) -> str | None:
        kind = (info.context or {}).get("shape")
        if kind is None:  # the shape is not known (it has its own message): a string is all to check
            return Text(what="a face").check(value, info)
        faces = FACES.get(kind, ())
        if not faces:
            _fail(f"shape {kind!r} has no named faces (expected no face hint)")
        return Text(faces).check(value, info)

    def schema(self) -> dict[str, Any]:
        return {"type": "string", "enum": sorted({f for faces in FACES.values() for f in faces})}


class Vertices(Value):
    """A convex polygon's ``[x, y]`` vertices, counter-clockwise, as wide as a valid length."""

    vertex = Vector("numbers", 2, VERTEX)

    def expected(self, dim: int | None) -> str:
        return "a list of [x, y] vertices, counter-clockwise"

    def __get_pydantic_core_schema__(self, source: Any, handler: Any) -> core_schema.CoreSchema:
        items = core_schema.list_schema(self.vertex.__get_pydantic_core_schema__(source, handler))
        return core_schema.with_info_wrap_validator_function(self.check_polygon, items)

    def check_polygon(self, value: Any, handler: Callable[[Any], list], info: ValidationInfo) -> Any:
        import numpy as np

        if not isinstance(value, list) or len(value) < 3:
            _fail("expected at least 3 [x, y] vertices, counter-clockwise")
        V = np.array(handler(value), dtype=float)
        E = np.roll(V, -1, axis=0) - V
        if np.any(np.linalg.norm(E, axis=1) <= 1e-12):
            _fail("two consecutive vertices coincide (expected distinct vertices)")
        cross = E[:, 0] * np.roll(E, -1, axis=0)[:, 1] - E[:, 1] * np.roll(E, -1, axis=0)[:, 0]
        if np.all(cross < 0):
            _fail("vertices are clockwise (expected counter-clockwise)")
        if not np.all(cross > 0):
            _fail("polygon is not strictly convex (expected a convex polygon, counter-clockwise)")
        extent = float(np.min(V.max(axis=0) - V.min(axis=0)))
        if extent < limits.SIZE.low:
            _fail(f"the polygon is {quote_number(extent)} m across (expected a width {limits.SIZE.expected()})")
        return tuple((float(x), float(y)) for x, y in V)

    def schema(self) -> dict[str, Any]:
        return {"type": "array", "minItems": 3, "items": self.vertex.schema(), "x-unit": "m"}


class Inertia(Value):
    """Principal moments ``[Ixx, Iyy, Izz]`` in 3D (positive, triangle inequality), ``Izz`` in 2D."""

    moments = Vector("principal moments [Ixx, Iyy, Izz]", 3)
    izz = Number("Izz [kg·m²]", exclusive_minimum=0.0)

    def expected(self, dim: int | None) -> str:
        return self.izz.what if dim == 2 else self.moments.expected(3)

    def __get_pydantic_core_schema__(self, source: Any, handler: Any) -> core_schema.CoreSchema:
        self._vector = self.moments.__get_pydantic_core_schema__(source, handler)
        return core_schema.with_info_wrap_validator_function(self.check_inertia, self._vector)

    def check_inertia(self, value: Any, handler: Callable[[Any], Any], info: ValidationInfo) -> Any:
        if _dimension(info) == 2:
            return self.izz.check(value, info)
        vals = list(handler(value))
        a, b, c = vals
        if min(vals) <= 0.0:
            _fail(f"got {vals} (expected a positive-definite inertia: every moment > 0)")
        if a + b < c or a + c < b or b + c < a:
            _fail(f"got {vals} (expected moments satisfying the triangle inequality, as any rigid body does)")
        return tuple(vals)

    def schema(self) -> dict[str, Any]:
        three = self.moments.schema() | {"items": {"type": "number", "exclusiveMinimum": 0}}
        return {"anyOf": [three, {"type": "number", "exclusiveMinimum": 0}], "x-unit": "kg·m²"}


class TablesOf:
    """An array of tables ``[[name]]`` (a list of dicts), else one message at its key."""

    def __init__(self, name: str):
        self.name = name

    def __get_pydantic_core_schema__(self, source: Any, handler: Any) -> core_schema.CoreSchema:
        return core_schema.no_info_before_validator_function(self.check, handler(source))

    def check(self, value: Any) -> Any:
        if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
            _fail(f"got {_kind(value)} (expected an array of tables [[{self.name}]])")
        return value


# -- tables ---------------------------------------------------------------------------------------
def _errors(title: str, errors: Iterable[tuple[tuple[int | str, ...], str]]) -> ValidationError:
    details = [
        InitErrorDetails(type=PydanticCustomError(_ERROR, "{message}", {"message": m}), loc=loc, input=None)
        for loc, m in errors
    ]
    return ValidationError.from_exception_data(title, details)


def _message(error: Any) -> str:
    """The message of a pydantic error: ours as written, pydantic's own with what was given."""
    ctx = error.get("ctx") or {}
    if error["type"] == _ERROR:
        return str(ctx["message"])
    return f"got {_kind(error.get('input'))} ({error['msg'].lower()})"  # pragma: no cover - every key has our types


class Table(BaseModel):
    """A TOML table: its keys are the fields; unknown keys, missing keys and every bad value are reported.

    A subclass declares its keys as fields annotated with a :class:`Value`; :meth:`rules` adds
    checks that need several keys or the context (the scene's dimension, the workpiece's shape).
    """

    # built on first use (validate_document, json_schema), not at import: the CLI starts faster
    model_config = ConfigDict(extra="forbid", frozen=True, defer_build=True)
    table_name: ClassVar[str] = "a table"

    @classmethod
    def value_of(cls, key: str) -> Value | None:
        return next((m for m in cls.model_fields[key].metadata if isinstance(m, Value)), None)

    @classmethod
    def keys(cls, dim: int | None) -> list[str]:
        """The keys of this table in a scene of ``dim`` dimensions."""
        out = []
        for key in cls.model_fields:
            value = cls.value_of(key)
            if dim is None or value is None or value.dimension in (None, dim) or value.other_dimension:
                out.append(key)
        return out

    @classmethod
    def rules(cls, data: Mapping[str, Any], context: Mapping[str, Any]) -> tuple[set[str], list[tuple[tuple, str]]]:
        """The keys read here (others are not validated) and problems of several keys at once."""
        return set(cls.model_fields), []

    @model_validator(mode="wrap")
    @classmethod
    def _read(cls, data: Any, handler: Callable[[Any], Any], info: ValidationInfo) -> Any:
        if not isinstance(data, dict):
            _fail(f"got {_kind(data)} (expected a table)")
        context = info.context or {}
        dim = context.get("dimension")
        keys = cls.keys(dim)
        errors: list[tuple[tuple, str]] = [
            ((key,), f"unknown key (expected one of: {', '.join(sorted(keys))})") for key in data if key not in keys
        ]
        read, problems = cls.rules(data, context)
        errors += problems
        for key in keys:
            value, field = cls.value_of(key), cls.model_fields[key]
            if key in read and key not in data and field.is_required():
                errors.append(((key,), f"missing (expected {value.expected(dim) if value else cls.table_name})"))
            elif key in data and value and value.other_dimension and dim is not None and value.dimension != dim:
                errors.append(((key,), value.other_dimension))
                read = read - {key}
        given = {k: v for k, v in data.items() if k in keys and k in read}
        try:
            result = handler(given)
        except ValidationError as exc:
            errors += [(tuple(e["loc"]), _message(e)) for e in exc.errors() if e["type"] != "missing"]
            result = None
        if errors:
            order = {key: i for i, key in enumerate(keys)}  # unknown keys first, then the keys as declared
            errors.sort(key=lambda e: order.get(str(e[0][0]), -1) if e[0] else -1)
            raise _errors(cls.__name__, errors)
        return result


class Scene(Table):
    """``[scene]``: the scene's name, dimension and gravity."""

    name: Annotated[str, SceneName()] = Field(description="The scene's name, printed in results.")
    dimension: Annotated[int, Integer((2, 3))] = Field(
        3, description="3: six locators locate the part; 2: three locators (planar)."
    )
    gravity: Annotated[tuple[float, ...] | None, Vector(bounds=limits.GRAVITY)] = Field(
        None, description="Gravity in the world frame; default [0, 0, -9.81] (3D), [0, -9.81] (2D)."
    )


_ANGLE_2D = Number("an angle [deg]", limits.ANGLE, dimension=2)


class Pose(Table):
    """A world pose of the workpiece's body frame: ``{ position = [...], rpy_deg = [...] }`` (2D: ``angle_deg``)."""

    position: Annotated[tuple[float, ...], Vector(bounds=limits.COORDINATE)] = Field(
        description="World position of the body frame."
    )
    rpy_deg: Annotated[tuple[float, ...], Vector(length=3, bounds=limits.ANGLE, dimension=3)] = Field(
        (0.0, 0.0, 0.0), description="Roll, pitch, yaw: R = Rz(yaw)·Ry(pitch)·Rx(roll) (3D)."
    )
    angle_deg: Annotated[float, _ANGLE_2D] = Field(0.0, description="Counter-clockwise angle (2D).")


_LENGTH = Number("a length", limits.SIZE, exclusive_minimum=0.0, too_large=UNITS_HINT)


_DIAMETER = Number("a diameter [m]", limits.SIZE, exclusive_minimum=0.0, too_large=UNITS_HINT)
_CHAMFER = Number("a 45° chamfer's leg [m]", limits.TIP_RADIUS, minimum=0.0)
_POINT3 = Vector(length=3, bounds=limits.COORDINATE)
PIN_KINDS = ("round", "diamond")


class Hole(Table):
    """``[[workpiece.hole]]``: a cylindrical hole in the part, body frame (exact geometry, also in a mesh part)."""

    name: Annotated[str, Name()] = Field(description="Unique among the part's holes; a pin names it in `hole`.")
    position: Annotated[tuple[float, ...], _POINT3] = Field(description="Centre of the hole's mouth, body frame.")
    axis: Annotated[tuple[float, ...], Direction(length=3)] = Field(
        description="Pointing out of the part through the mouth, body frame (normalised on load)."
    )
    diameter: Annotated[float, _DIAMETER] = Field(description="The hole's diameter D.")
    depth: Annotated[float, _DIAMETER] = Field(
        description="From the mouth to the bottom; a hole as deep as the part is a through hole."
    )
    chamfer: Annotated[float, _CHAMFER] = Field(0.0, description="The mouth's 45° chamfer (its leg length).")


class Workpiece(Table):
    """``[workpiece]``: the part to load; the keys of its shape, its mass, inertia and poses."""

    shape: Annotated[str, ShapeName()] = Field(
        description="3D: box | cylinder | sphere | mesh; 2D: rectangle | disk | polygon."
    )
    size: Annotated[tuple[float, ...] | None, Vector(bounds=limits.SIZE, too_large=UNITS_HINT)] = Field(
        None, description="Box: full edge lengths along body x, y, z; rectangle: [w, h]."
    )
    radius: Annotated[float | None, Number("a radius", limits.SIZE, exclusive_minimum=0.0, too_large=UNITS_HINT)] = (
        Field(None, description="Sphere, disk, cylinder: the radius.")
    )
    length: Annotated[float | None, _LENGTH] = Field(None, description="Cylinder: the length along body z.")
    vertices: Annotated[tuple[tuple[float, float], ...] | None, Vertices()] = Field(
        None, description="Polygon: [[x, y], ...] in the body frame, counter-clockwise, convex."
    )
    file: Annotated[str | None, Text(what="a mesh file path")] = Field(
        None,
        description="Mesh: the file (STL binary or ASCII, OBJ, PLY; STEP with the CAD extra), relative to the "
        "fixture file's folder and inside it; a closed, manifold triangle mesh whose frame is the body frame.",
    )
    units: Annotated[str | None, Text(MESH_UNITS)] = Field(
        None,
        description="Mesh: the unit of the file's coordinates, m | mm | in (default m; not for STEP, whose "
        "file states its unit).",
    )
    tolerance: Annotated[float | None, Number("a chordal tolerance [m]", limits.STEP_TOLERANCE)] = Field(
        None,
        description="Mesh from a STEP file (.step, .stp; the CAD extra, pip install fixplan[cad]): the chordal "
        "tolerance it is tessellated to, the largest distance between a triangle and the surface "
        "(default 1e-4 m).",
    )
    mass: Annotated[float, Number("a mass [kg]", limits.MASS, exclusive_minimum=0.0)] = Field(
        description="The workpiece's mass."
    )
    inertia: Annotated[tuple[float, ...] | float | None, Inertia()] = Field(
        None,
        description="Principal moments [Ixx, Iyy, Izz] about the centre of mass, body axes (2D: Izz); "
        "default: uniform density over the shape.",
    )
    start: Pose | None = Field(None, description="World pose of the body frame at the start; default: the identity.")
    goal: Pose | None = Field(
        None, description="The located pose (every locator touching); computed when absent, checked when given."
    )
    hole: Annotated[tuple[Hole, ...], TablesOf("workpiece.hole")] = Field(
        (), description="A cylindrical hole in the part (body frame) that a [[pin]] enters."
    )

    @classmethod
    def rules(cls, data: Mapping[str, Any], context: Mapping[str, Any]) -> tuple[set[str], list[tuple[tuple, str]]]:
        common = {"shape", "mass", "inertia", "start", "goal", "hole"}
        kind = data.get("shape")
        dim = context.get("dimension") or 3
        if not isinstance(kind, str) or kind not in (SHAPES_3D if dim == 3 else SHAPES_2D):
            return common, []
        used = common | set(SHAPE_KEYS[kind]) | set(SHAPE_OPTIONAL_KEYS.get(kind, ()))
        errors: list[tuple[tuple, str]] = [
            ((key,), f"not used by shape {kind!r} (remove it)")
            for key in data
            if key in cls.model_fields and key not in used
        ]
        for key in SHAPE_KEYS[kind]:
            value = cls.value_of(key)
            if key not in data and value is not None:
                errors.append(((key,), f"missing (expected {value.expected(dim)})"))
        return used, errors


class Locator(Table):
    """``[[locator]]``: a spherical tip fixed in the world that the part must touch when located."""

    name: Annotated[str, Name()] = Field(description="Unique among locators and contacts.")
    position: Annotated[tuple[float, ...], Vector(bounds=limits.COORDINATE)] = Field(
        description="Centre of the spherical tip, world frame."
    )
    radius: Annotated[float, Number("a tip radius [m]", limits.TIP_RADIUS, minimum=0.0)] = Field(
        0.0, description="Tip radius; 0 is a point."
    )
    friction: Annotated[float, Number("a friction coefficient", limits.FRICTION, minimum=0.0)] = Field(
        description="Coulomb coefficient μ."
    )
    torsion: Annotated[float, Number("a torsional radius [m]", limits.TORSION, minimum=0.0, dimension=3,
                                     other_dimension="torsional friction is 3D only (remove it in a 2D scene)")] = Field(
        0.0, description="Soft-finger torsional radius e_r (3D only)."
    )  # fmt: skip
    face: Annotated[str | None, Face()] = Field(
        None, description="Hint: the face of a box (±x ±y ±z), rectangle (±x ±y) or cylinder (+z -z side) it locates."
    )


class Contact(Table):
    """``[[contact]]``: an explicit contact at the start pose (geometry-free analysis)."""

    name: Annotated[str, Name()] = Field(description="Unique among locators and contacts.")
    point: Annotated[tuple[float, ...], Vector(bounds=limits.COORDINATE)] = Field(description="World frame.")
    normal: Annotated[tuple[float, ...], Direction()] = Field(
        description="The direction in which the fixture pushes the workpiece (normalised on load)."
    )
    friction: Annotated[float, Number("a friction coefficient", limits.FRICTION, minimum=0.0)] = Field(
        description="Coulomb coefficient μ."
    )
    torsion: Annotated[float, Number("a torsional radius [m]", limits.TORSION, minimum=0.0, dimension=3,
                                     other_dimension="torsional friction is 3D only (remove it in a 2D scene)")] = Field(
        0.0, description="Soft-finger torsional radius e_r (3D only)."
    )  # fmt: skip


class Manipulator(Table):
    """``[manipulator]``: what the hand/robot can exert on the workpiece."""

    max_force: Annotated[float | None, Number("a force [N]", limits.MAX_FORCE, exclusive_minimum=0.0)] = Field(
        None, description="The largest force the hand/robot exerts on the workpiece; default: unbounded."
    )
    max_torque: Annotated[float | None, Number("a torque [N·m]", limits.MAX_TORQUE, exclusive_minimum=0.0)] = Field(
        None, description="The largest torque the hand/robot exerts on the workpiece; default: unbounded."
    )


_SIMULATION = SimulationSettings()  # the defaults, as the model has them


class Simulation(Table):
    """``[simulation]``: defaults of the simulation, overridable on the command line."""

    timestep: Annotated[float, Number("a time step [s]", limits.TIMESTEP, exclusive_minimum=0.0, maximum=1.0)] = Field(
        _SIMULATION.timestep_s, description="Time step of the simulation."
    )
    restitution: Annotated[float, Number("a restitution coefficient", limits.RESTITUTION, minimum=0.0, maximum=1.0)] = (
        Field(_SIMULATION.restitution, description="Restitution coefficient.")
    )
    tolerance: Annotated[
        float, Number("a solver tolerance", limits.SOLVER_TOLERANCE, exclusive_minimum=0.0, maximum=1.0)
    ] = Field(_SIMULATION.tolerance, description="Contact solver residual.")


OBSTACLE_SHAPES = {3: ("plane", "box"), 2: ("line", "rectangle")}
OBSTACLE_FRICTION = 0.3  # an [[obstacle]] without friction: a steel plate, dry


class ObstacleShape(PlainValue):
    """``obstacle.shape``: a plane or a box (2D: a line or a rectangle); meshes come later."""

    def expected(self, dim: int | None) -> str:
        return f"one of: {', '.join(OBSTACLE_SHAPES[2 if dim == 2 else 3])}"

    def check(self, value: Any, info: ValidationInfo) -> str:
        if value == "mesh":
            _fail("mesh obstacles come later, with CAD meshes (expected plane or box for now)")
        dim = _dimension(info) or 3
        return Text(OBSTACLE_SHAPES[dim]).check(value, info)

    def schema(self) -> dict[str, Any]:
        return {"type": "string", "enum": [*OBSTACLE_SHAPES[3], *OBSTACLE_SHAPES[2]]}


class Obstacle(Table):
    """``[[obstacle]]``: a fixed body for collision only (a floor, a base plate); never a locator."""

    name: Annotated[str, Name()] = Field(description="Unique among locators, contacts and obstacles.")
    shape: Annotated[str, ObstacleShape()] = Field(
        description="plane or box (2D: line or rectangle): a half-space, or a box placed by its pose."
    )
    point: Annotated[tuple[float, ...] | None, Vector(bounds=limits.COORDINATE)] = Field(
        None, description="Plane (line): a point on it, world frame."
    )
    normal: Annotated[tuple[float, ...] | None, Direction()] = Field(
        None, description="Plane (line): the normal pointing to the free side, world frame (normalised)."
    )
    size: Annotated[tuple[float, ...] | None, Vector(bounds=limits.SIZE, too_large=UNITS_HINT)] = Field(
        None, description="Box (rectangle): the edge lengths."
    )
    pose: Pose | None = Field(None, description="Box (rectangle): the world pose of its centre.")
    friction: Annotated[float, Number("a friction coefficient", limits.FRICTION, minimum=0.0)] = Field(
        OBSTACLE_FRICTION, description="Coulomb friction against the part."
    )

    @classmethod
    def rules(cls, data: Mapping[str, Any], context: Mapping[str, Any]) -> tuple[set[str], list[tuple[tuple, str]]]:
        common = {"name", "shape", "friction"}
        kind = data.get("shape")
        dim = context.get("dimension") or 3
        plane, box = OBSTACLE_SHAPES[2 if dim == 2 else 3]
        if kind not in (plane, box):
            return common, []
        own, other = (
            (("point", "normal"), ("size", "pose")) if kind == plane else (("size", "pose"), ("point", "normal"))
        )
        errors: list[tuple[tuple, str]] = [
            ((key,), f"not a key of a {kind} (expected {', '.join(own)})") for key in other if key in data
        ]
        for key in own:
            if key not in data:
                value = cls.value_of(key)
                errors.append(((key,), f"missing (expected {value.expected(dim) if value else 'a table'})"))
        return common | set(own), errors


class Pin(Table):
    """``[[pin]]``: a locating pin fixed in the fixture, world frame; it enters a hole of the part."""

    name: Annotated[str, Name()] = Field(description="Unique among locators, contacts, obstacles, pins and bores.")
    kind: Annotated[str, Text(PIN_KINDS)] = Field(
        description="round (locates 2 directions) or diamond (relieved: locates along land_direction only)."
    )
    hole: Annotated[str, Name()] = Field(description="The name of the [[workpiece.hole]] it enters.")
    position: Annotated[tuple[float, ...], _POINT3] = Field(
        description="Centre of the pin's base, where it leaves the fixture, world frame."
    )
    axis: Annotated[tuple[float, ...], Direction(length=3)] = Field(
        description="From base to tip, world frame (normalised on load)."
    )
    diameter: Annotated[float, _DIAMETER] = Field(description="The pin's diameter d.")
    length: Annotated[float, _DIAMETER] = Field(description="From the base to the tip.")
    friction: Annotated[float, Number("a friction coefficient", limits.FRICTION, minimum=0.0)] = Field(
        description="Coulomb coefficient μ."
    )
    chamfer: Annotated[float, _CHAMFER] = Field(0.0, description="The tip's 45° chamfer (its leg length).")
    land_direction: Annotated[tuple[float, ...] | None, Direction(length=3)] = Field(
        None, description="Diamond only: the direction the lands locate along (normal to the axis), world frame."
    )
    land_width: Annotated[float | None, _DIAMETER] = Field(None, description="Diamond only: the width of each land.")

    @classmethod
    def rules(cls, data: Mapping[str, Any], context: Mapping[str, Any]) -> tuple[set[str], list[tuple[tuple, str]]]:
        errors: list[tuple[tuple, str]] = []
        if data.get("kind") == "diamond":
            errors += [
                ((k,), "missing (a diamond pin needs it)") for k in ("land_direction", "land_width") if k not in data
            ]
        elif data.get("kind") == "round":
            errors += [
                ((k,), "a diamond pin's key (remove it for a round pin)")
                for k in ("land_direction", "land_width")
                if k in data
            ]
        return set(cls.model_fields), errors


class Bore(Table):
    """``[[bore]]``: a cylindrical hole in the fixture, world frame, for a cylindrical workpiece (a peg)."""

    name: Annotated[str, Name()] = Field(description="Unique among locators, contacts, obstacles, pins and bores.")
    position: Annotated[tuple[float, ...], _POINT3] = Field(description="Centre of the bore's mouth, world frame.")
    axis: Annotated[tuple[float, ...], Direction(length=3)] = Field(
        description="Pointing out of the fixture through the mouth, world frame (normalised on load)."
    )
    diameter: Annotated[float, _DIAMETER] = Field(description="The bore's diameter D.")
    depth: Annotated[float, _DIAMETER] = Field(description="From the mouth to the bore's bottom.")
    friction: Annotated[float, Number("a friction coefficient", limits.FRICTION, minimum=0.0)] = Field(
        description="Coulomb coefficient μ."
    )
    chamfer: Annotated[float, _CHAMFER] = Field(0.0, description="The mouth's 45° chamfer (its leg length).")


class Robot(Table):
    """``[robot]``: the arm that carries the part (3D): a URDF, its base, the grasp and the tool frame."""

    urdf: Annotated[str, Text(what="a URDF path or a robot name")] = Field(
        description="A URDF file relative to the fixture file's folder (and inside it), or the name of a robot of "
        "example-robot-data (panda, ur5, ...; the optional extra fixplan[robots])."
    )
    base: Pose = Field(description="World pose of the robot's base (its URDF root frame).")
    grasp: Pose = Field(description="The tool frame's pose in the workpiece body frame (where the hand holds it).")
    tool_frame: Annotated[str | None, Text(what="a frame name of the URDF")] = Field(
        None, description="The URDF frame that holds the part; default: the URDF's last frame."
    )
    repeatability: Annotated[float | None, Number("a repeatability [m]", limits.REPEATABILITY, minimum=0.0)] = Field(
        None, description="The arm's pose repeatability; `robust` samples it as the part's pose noise."
    )

    @classmethod
    def rules(cls, data: Mapping[str, Any], context: Mapping[str, Any]) -> tuple[set[str], list[tuple[tuple, str]]]:
        if context.get("dimension") == 2:
            return set(cls.model_fields), [(("urdf",), "a robot arm is 3D only (remove [robot] in a 2D scene)")]
        return set(cls.model_fields), []


class WrenchValue(Vector):
    """A wrench about the workpiece's body origin, world axes: 6 numbers in 3D, ``Fx, Fy, Mz`` in 2D."""

    def size(self, dim: int | None) -> int | None:
        return None if dim is None else (6 if dim == 3 else 3)

    def expected(self, dim: int | None) -> str:
        n = self.size(dim)
        return f"{n} numbers" if n is not None else "6 numbers (3D) or 3 (2D)"

    def check_list(self, value: Any, handler: Callable[[Any], list[float]], info: ValidationInfo) -> Any:
        n = self.size(_dimension(info))
        if isinstance(value, list) and n is not None and len(value) != n:
            what = "Fx, Fy, Fz, Tx, Ty, Tz" if n == 6 else "Fx, Fy, Mz"
            _fail(f"got {len(value)} numbers (expected {n} for a {3 if n == 6 else 2}D scene: {what})")
        return super().check_list(value, handler, info)

    def after(self, values: list[float], info: ValidationInfo) -> Any:
        for i, (x, bounds) in enumerate(zip(values, limits.wrench_ranges(len(values)), strict=True)):
            if not bounds.contains(x):
                _fail(f"component {i} is {quote_number(x)} (expected {bounds.expected()})")
        return tuple(values)

    def schema(self) -> dict[str, Any]:
        return super().schema() | {"minItems": 3, "maxItems": 6}


_WRENCH = Range(
    "a force [N] or moment [N·m] component",
    "N, N·m",
    -max(limits.FORCE_MAX_N, limits.TORQUE_MAX_NM),
    max(limits.FORCE_MAX_N, limits.TORQUE_MAX_NM),
)
_CLAMP_FORCE = Number("a force [N]", limits.MAX_FORCE, exclusive_minimum=0.0)


class Clamp(Table):
    """``[[clamp]]``: a clamp applied after loading, its spherical tip touching the located part."""

    name: Annotated[str, Name()] = Field(
        description="Unique among locators, contacts, obstacles, pins, bores, clamps and loads."
    )
    position: Annotated[tuple[float, ...], Vector(bounds=limits.COORDINATE)] = Field(
        description="Centre of the clamp's spherical tip when it touches the located part, world frame."
    )
    direction: Annotated[tuple[float, ...], Direction()] = Field(
        description="The direction in which it pushes the part, world frame (normalised on load)."
    )
    radius: Annotated[float, Number("a tip radius [m]", limits.TIP_RADIUS, minimum=0.0)] = Field(
        0.0, description="Tip radius; 0 is a point."
    )
    friction: Annotated[float, Number("a friction coefficient", limits.FRICTION, minimum=0.0)] = Field(
        description="Coulomb coefficient μ of the tip on the part: the direction must lie within its friction cone."
    )
    max_force: Annotated[float, _CLAMP_FORCE] = Field(description="The largest force the clamp exerts.")
    force: Annotated[float | None, _CLAMP_FORCE] = Field(
        None, description="A clamp of fixed force (a toggle clamp): checked, not computed; at most max_force."
    )

    @classmethod
    def rules(cls, data: Mapping[str, Any], context: Mapping[str, Any]) -> tuple[set[str], list[tuple[tuple, str]]]:
        errors: list[tuple[tuple, str]] = []
        force, top = data.get("force"), data.get("max_force")
        if _is_number(force) and _is_number(top):
            f, m = _as_float(force), _as_float(top)  # type: ignore[arg-type]  # numbers, checked just above
            if f is not None and m is not None and math.isfinite(f) and math.isfinite(m) and f > m:
                errors.append(
                    (
                        ("force",),
                        f"got {quote_number(force)} N, above max_force = {quote_number(top)} N (expected a fixed force ≤ max_force)",
                    )
                )
        return set(cls.model_fields), errors


class Load(Table):
    """``[[load]]``: a process load (a cutting force) the clamped part must hold."""

    name: Annotated[str, Name()] = Field(
        description="Unique among locators, contacts, obstacles, pins, bores, clamps and loads."
    )
    wrench: Annotated[tuple[float, ...], WrenchValue(bounds=_WRENCH)] = Field(
        description="Fx, Fy, Fz, Tx, Ty, Tz about the workpiece's body-frame origin, world axes (2D: Fx, Fy, Mz), "
        "in addition to gravity."
    )


class FixtureFile(Table):
    """A fixture file: ``docs/fixture-format.md``."""

    named: ClassVar[tuple[str, ...]] = (
        "locator",
        "contact",
        "obstacle",
        "pin",
        "bore",
        "clamp",
        "load",
    )  # arrays of tables whose names are unique across all

    format: Annotated[int, Integer((1,))] = Field(description="The file format's version.")
    scene: Scene = Field(description="The scene: its name, dimension and gravity.")
    workpiece: Workpiece = Field(description="The part to load: its shape, mass and poses (body frame).")
    locator: Annotated[tuple[Locator, ...], TablesOf("locator")] = Field(
        (), description="A locator: a spherical tip fixed in the world; 6 in 3D, 3 in 2D for a full fixture."
    )
    contact: Annotated[tuple[Contact, ...], TablesOf("contact")] = Field(
        (), description="An explicit contact at the start pose (geometry-free analysis)."
    )
    obstacle: Annotated[tuple[Obstacle, ...], TablesOf("obstacle")] = Field(
        (), description="A collision-only body: a floor, a base plate, the fixture's body (never locates)."
    )
    pin: Annotated[tuple[Pin, ...], TablesOf("pin")] = Field(
        (), description="A locating pin (round or diamond) fixed in the fixture; it enters a hole of the part."
    )
    bore: Annotated[tuple[Bore, ...], TablesOf("bore")] = Field(
        (), description="A cylindrical hole in the fixture for a cylindrical part (a peg)."
    )
    clamp: Annotated[tuple[Clamp, ...], TablesOf("clamp")] = Field(
        (), description="A clamp applied after loading, at the located pose (`fixplan clamp`)."
    )
    load: Annotated[tuple[Load, ...], TablesOf("load")] = Field(
        (), description="A process load the clamped part must hold (`fixplan clamp`)."
    )
    manipulator: Manipulator | None = Field(None, description="What the hand/robot can exert on the workpiece.")
    robot: Robot | None = Field(None, description="The arm that carries the part (3D; checked along the plan).")
    simulation: Simulation | None = Field(None, description="Simulation defaults, overridable on the command line.")

    @classmethod
    def rules(cls, data: Mapping[str, Any], context: Mapping[str, Any]) -> tuple[set[str], list[tuple[tuple, str]]]:
        errors: list[tuple[tuple, str]] = []
        seen: set[str] = set()
        for kind in cls.named:
            entries = data.get(kind)
            if not isinstance(entries, list):
                continue
            for i, entry in enumerate(entries):
                name = entry.get("name") if isinstance(entry, dict) else None
                if not isinstance(name, str) or not is_name(name):
                    continue  # an invalid name has its own message
                if name in seen:
                    errors.append(((kind, i, "name"), f"{name!r} is used twice (expected unique names)"))
                seen.add(name)
        return set(cls.model_fields), errors


# -- reading a document ------------------------------------------------------------------------------
@contextmanager
def _without_plugins() -> Iterator[None]:
    """Build the models without pydantic's validation plugins (observability hooks, none of ours).

    Looking the plugins up scans every installed distribution's entry points, about 30 ms at
    each start of the command line; the format's models have no use for them.
    """
    before = os.environ.get(_NO_PLUGINS)
    os.environ[_NO_PLUGINS] = "__all__"
    try:
        yield
    finally:
        if before is None:
            del os.environ[_NO_PLUGINS]
        else:
            os.environ[_NO_PLUGINS] = before


_NO_PLUGINS = "PYDANTIC_DISABLE_PLUGINS"


def key_path(loc: tuple[int | str, ...], data: Any) -> str:
    """``locator.B1.position[2]``: an entry of an array of tables by its name when it has a valid one."""
    out, node = "", data
    for part in loc:
        if isinstance(part, int):
            entry = node[part] if isinstance(node, list) and part < len(node) else None
            name = entry.get("name") if isinstance(entry, dict) else None
            out += f".{name}" if is_name(name) else f"[{part}]"
            node = entry
        else:
            out = f"{out}.{part}" if out else part
            node = node.get(part) if isinstance(node, dict) else None
    return out


def validate_document(
    data: dict[str, Any], dimension: int | None, shape: str | None
) -> tuple[FixtureFile | None, list[Issue]]:
    """The validated file, or None and every problem of every key (dotted key path, what was expected).

    ``dimension`` is the scene's (None when it is invalid: vector lengths are then not checked),
    ``shape`` the workpiece's when valid (locator faces are checked against it).
    """
    try:
        with _without_plugins():
            return FixtureFile.model_validate(data, context={"dimension": dimension, "shape": shape}), []
    except ValidationError as exc:
        return None, [Issue(key_path(tuple(e["loc"]), data), _message(e)) for e in exc.errors()]


# -- the JSON Schema and the key reference -------------------------------------------------------------
def _tidy(node: Any) -> Any:
    """Drop pydantic's generated titles and null defaults; ``$defs`` as draft-07 ``definitions``."""
    if isinstance(node, dict):
        options = node.get("anyOf")
        if isinstance(options, list) and {"type": "null"} in options:  # an optional table: absent, not null
            rest = [o for o in options if o != {"type": "null"}]
            node = {k: v for k, v in node.items() if k != "anyOf"} | (rest[0] if len(rest) == 1 else {"anyOf": rest})
        out = {}
        for key, value in node.items():
            if key == "title" or (key == "default" and value is None):
                continue
            if key == "$ref" and isinstance(value, str):
                value = value.replace("#/$defs/", "#/definitions/")
            if key == "description" and isinstance(value, str):  # editors render Markdown, not reST
                value = value.replace("``", "`")
            out["definitions" if key == "$defs" else key] = _tidy(value)
        return out
    if isinstance(node, list):
        return [_tidy(v) for v in node]
    return node


def _shape_rules() -> list[dict[str, Any]]:
    """if/then per shape: the keys it needs, the keys of other shapes refused, vector lengths."""
    shape_keys = {k for keys in (*SHAPE_KEYS.values(), *SHAPE_OPTIONAL_KEYS.values()) for k in keys}
    rules = []
    for kind, keys in SHAPE_KEYS.items():
        then: dict[str, Any] = {"required": list(keys)}
        others = sorted(shape_keys - set(keys) - set(SHAPE_OPTIONAL_KEYS.get(kind, ())))
        if others:
            then["not"] = {"anyOf": [{"required": [k]} for k in others]}
        if kind in ("box", "rectangle"):
            n = 3 if kind == "box" else 2
            then["properties"] = {"size": {"minItems": n, "maxItems": n}}
        rules.append({"if": {"properties": {"shape": {"const": kind}}, "required": ["shape"]}, "then": then})
    return rules


def _dimension_rules() -> list[dict[str, Any]]:
    """if/then per dimension: the shapes, the lengths of vectors and the 2D/3D-only keys."""

    def vectors(n: int) -> dict[str, Any]:
        return {"minItems": n, "maxItems": n}

    rules = []
    for dim, shapes in ((2, SHAPES_2D), (3, SHAPES_3D)):
        pose: dict[str, Any] = {
            "properties": {"position": vectors(dim)},
            "not": {"required": ["rpy_deg" if dim == 2 else "angle_deg"]},
        }
        entry: dict[str, Any] = {
            "properties": {"position": vectors(dim), "point": vectors(dim), "normal": vectors(dim)}
        }
        if dim == 2:
            entry["not"] = {"required": ["torsion"]}
        then: dict[str, Any] = {
            "properties": {
                "scene": {"properties": {"gravity": vectors(dim)}},
                "workpiece": {
                    "properties": {
                        "shape": {"enum": list(shapes)},
                        "start": pose,
                        "goal": pose,
                        "inertia": {"type": "number"} if dim == 2 else {"type": "array"},
                    }
                },
                "locator": {"items": entry},
                "clamp": {"items": {"properties": {"position": vectors(dim), "direction": vectors(dim)}}},
                "load": {"items": {"properties": {"wrench": vectors(6 if dim == 3 else 3)}}},
                "contact": {"items": entry},
                "obstacle": {
                    "items": {
                        "properties": {
                            "shape": {"enum": list(OBSTACLE_SHAPES[dim])},
                            "point": vectors(dim),
                            "normal": vectors(dim),
                            "size": vectors(dim),
                            "pose": pose,
                        },
                        "allOf": [
                            {
                                "if": {"properties": {"shape": {"const": kind}}, "required": ["shape"]},
                                "then": {"required": list(own), "not": {"anyOf": [{"required": [k]} for k in other]}},
                            }
                            for kind, own, other in (
                                (OBSTACLE_SHAPES[dim][0], ("point", "normal"), ("size", "pose")),
                                (OBSTACLE_SHAPES[dim][1], ("size", "pose"), ("point", "normal")),
                            )
                        ],
                    }
                },
            }
        }
        if dim == 3:
            then["properties"]["robot"] = {"properties": {"base": pose, "grasp": pose}}
        else:
            then["not"] = {"required": ["robot"]}  # a robot arm is 3D only
        # dimension defaults to 3: a file without it is a 3D one
        cond: dict[str, Any] = {"properties": {"scene": {"properties": {"dimension": {"const": dim}}}}}
        if dim == 2:
            cond["properties"]["scene"]["required"] = ["dimension"]
            cond["required"] = ["scene"]
        rules.append({"if": cond, "then": then})
    return rules


def json_schema() -> dict[str, Any]:
    """The JSON Schema (draft-07) of fixture files, for editors and other tools."""
    with _without_plugins():
        schema = _tidy(FixtureFile.model_json_schema())
    schema["definitions"]["Workpiece"]["allOf"] = _shape_rules()
    schema["allOf"] = _dimension_rules()
    head = {
        "$schema": "http://json-schema.org/draft-07/schema#",
        "title": "fixplan fixture file",
        "description": "A fixture file of fixplan (docs/fixture-format.md). Units are SI; angles in degrees. "
        "Checks of the whole model (a locator inside the part, goal finding) are fixplan validate's.",
    }
    return head | {k: v for k, v in schema.items() if k != "description"}


def schema_text() -> str:
    """The JSON Schema as written to ``docs/fixture.schema.json`` and printed by ``fixplan schema``."""
    import json

    return json.dumps(json_schema(), indent=2, ensure_ascii=False) + "\n"


def _tables() -> list[tuple[str, type[Table]]]:
    """Every table with its dotted prefix, in the order of the file: ``("workpiece.start", Pose)``."""
    out: list[tuple[str, type[Table]]] = []

    def visit(prefix: str, table: type[Table]) -> None:
        out.append((prefix, table))
        for key, field in table.model_fields.items():
            inner = _table_of(field.annotation)
            if inner is not None:
                visit(f"{prefix}.{key}" if prefix else key, inner)

    visit("", FixtureFile)
    return out


def _table_of(annotation: Any) -> type[Table] | None:
    """The table a field holds (``Pose | None``, ``tuple[Locator, ...]``), or None for a value."""
    if isinstance(annotation, type) and issubclass(annotation, Table):
        return annotation
    for arg in getattr(annotation, "__args__", ()):
        found = _table_of(arg)
        if found is not None:
            return found
    return None


def _kind_of(table: type[Table], key: str) -> str:
    field = table.model_fields[key]
    inner = _table_of(field.annotation)
    if inner is not None:
        return "tables `[[…]]`" if "tuple" in str(field.annotation) else "table"
    value = table.value_of(key)
    schema = value.schema() if value is not None else {}
    if not schema:
        return ""
    if "anyOf" in schema:
        return "3 numbers (2D: a number)"
    if schema.get("type") == "array":
        if schema.get("items", {}).get("type") == "array":
            return "list of [x, y]"
        n, m = schema.get("minItems"), schema.get("maxItems")
        return f"{n} numbers" if n == m else f"{n} or {m} numbers (the dimension)"
    return str(schema.get("type", ""))


def _range(value: Value | None) -> str:
    schema = value.schema() if value is not None else {}
    if "enum" in schema:
        return ", ".join(str(v) for v in schema["enum"])
    items = schema.get("items", schema)
    low, high = items.get("minimum", items.get("exclusiveMinimum")), items.get("maximum")
    if high == sys.float_info.max:
        return "any finite, not all 0"
    if low is None and high is None:
        return ""
    left = "(" if "minimum" not in items else "["
    return f"{left}{low:g}, {high:g}]" if high is not None else f"{left}{low:g}, ∞)"


def _default(default: Any) -> str:
    if isinstance(default, tuple):
        return "[" + ", ".join(f"{x:g}" for x in default) + "]" if default else ""
    if isinstance(default, float):
        return f"{default:g}"
    return "" if default is None else str(default)


def markdown_reference() -> str:
    """The key reference table of ``docs/fixture-format.md``: every key with its type, unit, range, default."""
    rows = ["| key | type | unit | range | default | description |", "|---|---|---|---|---|---|"]
    for prefix, table in _tables():
        for key, field in table.model_fields.items():
            value = table.value_of(key)
            path = f"{prefix}.{key}" if prefix else key
            unit = (value.schema() if value else {}).get("x-unit", "")
            default = "required" if field.is_required() else _default(field.default)
            text = (field.description or "").replace("|", "\\|")
            rows.append(f"| `{path}` | {_kind_of(table, key)} | {unit} | {_range(value)} | {default} | {text} |")
    return "\n".join(rows) + "\n"


def schema_keys() -> list[str]:
    """Every dotted key the format declares (``workpiece.start.position``)."""
    return [f"{p}.{k}" if p else k for p, t in _tables() for k in t.model_fields]
