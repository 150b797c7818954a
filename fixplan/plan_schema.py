"""The plan file and the haptic recording, declared once: one pydantic model per JSON object.

``fixplan solve --out`` (and ``--json``) writes a *plan file* (:class:`PlanFile`);
``fixplan haptic --record`` writes a *recording* (:class:`RecordingFile`, ``"source": "haptic
session"``). ``fixplan verify`` and ``fixplan view --plan`` read both. Before anything of a file
is used, :func:`validate_plan_document` checks every key against these models, the way
:mod:`fixplan.fixture_schema` checks a fixture: every problem is one
:class:`~fixplan.errors.Issue` with its dotted key path and what was expected
(``transitions[2].pushes.wrench[0][1]: got 1e+308 (expected a force component [N] in [-1e+06,
1e+06])``); unknown keys and missing ones are named too.

What the models check is the file on its own: types, finite numbers within the ranges of
:mod:`fixplan.limits` (poses within 1 km, wrenches within 10⁶ N), locator names of the valid
form, arrays of the lengths their neighbours imply (one pose per sample time). What needs the
fixture (the names are its locators, the sequence starts where the part starts and ends with
every locator pressed, pushes within the hand's limits) is checked by
:func:`fixplan.planner.plan.check_plan_claims`.

The format is described in ``docs/plan-format.md``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping
from typing import Annotated, Any, ClassVar, NoReturn

from pydantic import BaseModel, ConfigDict, Field, ValidationError, ValidationInfo, model_validator
from pydantic_core import InitErrorDetails, PydanticCustomError

from fixplan import limits
from fixplan.errors import Issue, shorten
from fixplan.fixture_schema import PlainValue, _without_plugins, is_name, key_path
from fixplan.limits import Range
from fixplan.schema import _as_float
from fixplan.schema import _kind as _toml_kind
from fixplan.settings import DEFAULT

_ERROR = "fixplan"
RECORDING_SOURCE = "haptic session"
PLAN_STATUSES = ("planned", "unverified", "infeasible")
SESSION_STATUSES = ("reached", "jammed", "short", "diverged", "error")
MOTIONS = ("free", "slide", "roll")
MAX_ERRORS_PER_ARRAY = 5  # bad elements of one array reported (then "... more")
MAX_TEXT = 100_000  # characters of a free-text value (a reason, an event's message)
# any other non-negative quantity a file reports (a duration, a tick time, a count of solves)
QUANTITY = Range("a non-negative number", "", 0.0, 1e12)
SIGNED = Range("a number", "", -1e12, 1e12)


def _fail(message: str) -> NoReturn:
    raise PydanticCustomError(_ERROR, "{message}", {"message": message})


def _kind(value: Any) -> str:
    """What a JSON value is, in words: ``null``, ``an object``, ``the number 3``, ``a list of 2``."""
    if value is None:
        return "null"
    if isinstance(value, dict):
        return "an object"
    return _toml_kind(value)


def _errors(title: str, errors: Iterable[tuple[tuple[int | str, ...], str]]) -> ValidationError:
    details = [
        InitErrorDetails(type=PydanticCustomError(_ERROR, "{message}", {"message": m}), loc=loc, input=None)
        for loc, m in errors
    ]
    return ValidationError.from_exception_data(title, details)


def _context(info: ValidationInfo) -> Mapping[str, Any]:
    return info.context or {}


def _dimension(info: ValidationInfo) -> int | None:
    return _context(info).get("dimension")


def _number(raw: Any, bounds: Range) -> tuple[float | None, str | None]:
    """A finite number within ``bounds``, or None and the message."""
    if not isinstance(raw, int | float) or isinstance(raw, bool):
        return None, f"got {_kind(raw)} (expected {bounds.expected()})"
    value = _as_float(raw)
    if value is None:
        return None, f"got {_kind(raw)}, too large for a float (expected {bounds.expected()})"
    if not math.isfinite(value):
        return None, f"got {value} (expected a finite number)"
    if not bounds.contains(value):
        return None, f"got {value:g} (expected {bounds.expected()})"
    return value, None


# -- values -------------------------------------------------------------------------------------
class Real(PlainValue):
    """A finite number within ``bounds``; ``nullable``: JSON null reads as None."""

    def __init__(self, bounds: Range = SIGNED, *, nullable: bool = False):
        self.bounds, self.nullable = bounds, nullable

    def expected(self, dim: int | None) -> str:
        return self.bounds.expected() + (" or null" if self.nullable else "")

    def check(self, value: Any, info: ValidationInfo) -> float | None:
        if value is None and self.nullable:
            return None
        x, message = _number(value, self.bounds)
        if message is not None:
            _fail(message)
        return x

    def schema(self) -> dict[str, Any]:
        out = {"type": "number", "minimum": self.bounds.low, "maximum": self.bounds.high}
        return {"anyOf": [out, {"type": "null"}]} if self.nullable else out


class Count(PlainValue):
    """A non-negative integer (a count of ticks or solves)."""

    def __init__(self, *, nullable: bool = False):
        self.nullable = nullable

    def expected(self, dim: int | None) -> str:
        return "a non-negative integer" + (" or null" if self.nullable else "")

    def check(self, value: Any, info: ValidationInfo) -> int | None:
        if value is None and self.nullable:
            return None
        ok = isinstance(value, int) and not isinstance(value, bool) and 0 <= value <= QUANTITY.high
        if isinstance(value, float) and value.is_integer() and 0 <= value <= QUANTITY.high:
            ok = True
        if not ok:
            _fail(f"got {_kind(value)} (expected {self.expected(None)})")
        return int(value)

    def schema(self) -> dict[str, Any]:
        out = {"type": "integer", "minimum": 0}
        return {"anyOf": [out, {"type": "null"}]} if self.nullable else out


class Flag(PlainValue):
    """true or false (``nullable``: or null)."""

    def __init__(self, *, nullable: bool = False):
        self.nullable = nullable

    def expected(self, dim: int | None) -> str:
        return "true or false" + (" or null" if self.nullable else "")

    def check(self, value: Any, info: ValidationInfo) -> bool | None:
        if value is None and self.nullable:
            return None
        if not isinstance(value, bool):
            _fail(f"got {_kind(value)} (expected {self.expected(None)})")
        return value

    def schema(self) -> dict[str, Any]:
        return {"type": ["boolean", "null"]} if self.nullable else {"type": "boolean"}


class Str(PlainValue):
    """A string (``choices``: one of them); ``nullable``: or null."""

    def __init__(self, choices: tuple[str, ...] | None = None, *, nullable: bool = False, what: str = "a string"):
        self.choices, self.nullable, self.what = choices, nullable, what

    def expected(self, dim: int | None) -> str:
        words = f"one of: {', '.join(self.choices)}" if self.choices else self.what
        return words + (" or null" if self.nullable else "")

    def check(self, value: Any, info: ValidationInfo) -> str | None:
        if value is None and self.nullable:
            return None
        if not isinstance(value, str) or len(value) > MAX_TEXT:
            _fail(f"got {_kind(value)} (expected {self.expected(None)})")
        if self.choices is not None and value not in self.choices:
            _fail(f"got {shorten(value)} (expected {self.expected(None)})")
        return value

    def schema(self) -> dict[str, Any]:
        out: dict[str, Any] = {"type": "string"} | ({"enum": list(self.choices)} if self.choices else {})
        return {"anyOf": [out, {"type": "null"}]} if self.nullable else out


# the elements of a contact state besides names: a bore's bottom reached ("B1.bottom"); a
# verification's final gaps also hold each pin's or bore's axis offset ("P1.axis_offset"). Names
# have no dots (fixture_schema.NAME_RULE), so these never collide with a locator's.
STATE_SUFFIXES = (".bottom",)
GAP_SUFFIXES = (".bottom", ".axis_offset")


def is_state_name(value: Any, suffixes: tuple[str, ...] = STATE_SUFFIXES) -> bool:
    """A contact state's element: a locator's (pin's, bore's) name, or a name with one of ``suffixes``."""
    if is_name(value):
        return True
    return isinstance(value, str) and any(value.endswith(s) and is_name(value[: -len(s)]) for s in suffixes)


class Locator(PlainValue):
    """A locator's name (which fixture's is checked against the fixture, not here)."""

    def expected(self, dim: int | None) -> str:
        return "a locator name"

    def check(self, value: Any, info: ValidationInfo) -> str:
        if not is_state_name(value):
            _fail(f"got {_kind(value)} (expected a locator name)")
        return str(value)

    def schema(self) -> dict[str, Any]:
        return {"type": "string"}


class Locators(PlainValue):
    """A contact state: a list of distinct locator names."""

    def __init__(self, *, nullable: bool = False, nonempty: bool = False):
        self.nullable, self.nonempty = nullable, nonempty

    def expected(self, dim: int | None) -> str:
        return ("a non-empty " if self.nonempty else "a ") + "list of distinct locator names"

    def check(self, value: Any, info: ValidationInfo) -> tuple[str, ...] | None:
        if value is None and self.nullable:
            return None
        if not isinstance(value, list):
            _fail(f"got {_kind(value)} (expected {self.expected(None)})")
        bad = [(i, x) for i, x in enumerate(value) if not is_state_name(x)]
        if bad:
            raise _errors("Locators", [((i,), f"got {_kind(x)} (expected a locator name)") for i, x in bad[:5]])
        if len(set(value)) != len(value):
            _fail(f"got {shorten(', '.join(value))}, a name twice (expected {self.expected(None)})")
        if self.nonempty and not value:
            _fail(f"got [] (expected {self.expected(None)})")
        return tuple(value)

    def schema(self) -> dict[str, Any]:
        return {"type": "array", "items": {"type": "string"}, "uniqueItems": True}


class Added(PlainValue):
    """The locator a transition closes: a name, or a non-empty list of names closing together."""

    def expected(self, dim: int | None) -> str:
        return "a locator name or a non-empty list of them"

    def check(self, value: Any, info: ValidationInfo) -> str | tuple[str, ...]:
        if isinstance(value, list):
            return Locators(nonempty=True).check(value, info) or ()
        if not is_state_name(value):
            _fail(f"got {_kind(value)} (expected {self.expected(None)})")
        return str(value)

    def schema(self) -> dict[str, Any]:
        return {"anyOf": [{"type": "string"}, {"type": "array", "items": {"type": "string"}, "minItems": 1}]}


def _row_errors(row: Any, ranges: list[Range], loc: tuple[int | str, ...]) -> list[tuple[tuple, str]]:
    if not isinstance(row, list):
        return [(loc, f"got {_kind(row)} (expected a list of {len(ranges)} numbers)")]
    if len(row) != len(ranges):
        return [(loc, f"got {len(row)} numbers (expected {len(ranges)})")]
    out = []
    for j, (x, bounds) in enumerate(zip(row, ranges, strict=True)):
        _, message = _number(x, bounds)
        if message is not None:
            out.append(((*loc, j), message))
    return out


def _raise_some(title: str, errors: list[tuple[tuple, str]]) -> None:
    if errors:
        shown = errors[:MAX_ERRORS_PER_ARRAY]
        if len(errors) > len(shown):
            last_loc, last = shown[-1]
            shown[-1] = (last_loc, f"{last} (and {len(errors) - len(shown)} more bad numbers not shown)")
        raise _errors(title, shown)


def _ndof(info: ValidationInfo, n: int | None = None) -> int | None:
    dim = _dimension(info)
    return {2: 3, 3: 6}.get(dim) if dim is not None else n


class Wrench(PlainValue):
    """A wrench (force, moment about the body origin; world axes): 6 numbers in 3D, 3 in 2D."""

    def __init__(self, *, nullable: bool = False):
        self.nullable = nullable

    def expected(self, dim: int | None) -> str:
        n = {2: 3, 3: 6}.get(dim or 0)
        return (f"{n} numbers" if n else "3 (2D) or 6 (3D) numbers") + " [N, N·m]"

    def check(self, value: Any, info: ValidationInfo) -> tuple[float, ...] | None:
        if value is None and self.nullable:
            return None
        n = _ndof(info, len(value) if isinstance(value, list) and len(value) in (3, 6) else None)
        if not isinstance(value, list) or n is None:
            _fail(
                f"got {_kind(value)} (expected {self.expected(_dimension(info))}{' or null' if self.nullable else ''})"
            )
        _raise_some("Wrench", _row_errors(value, limits.wrench_ranges(n), ()))
        return tuple(float(x) for x in value)

    def schema(self) -> dict[str, Any]:
        out = {"type": "array", "items": {"type": "number"}, "minItems": 3, "maxItems": 6}
        return {"anyOf": [out, {"type": "null"}]} if self.nullable else out


class Wrenches(PlainValue):
    """One wrench per sample: a list of rows (their number is checked by the object holding them)."""

    def __init__(self, *, nullable: bool = False):
        self.nullable = nullable

    def expected(self, dim: int | None) -> str:
        return "a list of wrenches, " + Wrench().expected(dim)

    def check(self, value: Any, info: ValidationInfo) -> list[list[float]] | None:
        if value is None and self.nullable:
            return None
        if not isinstance(value, list):
            _fail(f"got {_kind(value)} (expected {self.expected(_dimension(info))})")
        first = value[0] if value else None
        n = _ndof(info, len(first) if isinstance(first, list) and len(first) in (3, 6) else 6)
        ranges = limits.wrench_ranges(n or 6)
        errors: list[tuple[tuple, str]] = []
        for i, row in enumerate(value):
            errors += _row_errors(row, ranges, (i,))
            if len(errors) > MAX_ERRORS_PER_ARRAY:
                break
        _raise_some("Wrenches", errors)
        return [[float(x) for x in row] for row in value]

    def schema(self) -> dict[str, Any]:
        out = {"type": "array", "items": Wrench().schema()}
        return {"anyOf": [out, {"type": "null"}]} if self.nullable else out


class Series(PlainValue):
    """A list of finite numbers within ``bounds``; ``increasing``: non-decreasing (sample times)."""

    def __init__(self, bounds: Range = SIGNED, *, increasing: bool = False, nonempty: bool = False):
        self.bounds, self.increasing, self.nonempty = bounds, increasing, nonempty

    def expected(self, dim: int | None) -> str:
        order = ", non-decreasing" if self.increasing else ""
        return f"a {'non-empty ' if self.nonempty else ''}list of numbers{order}, each {self.bounds.expected()}"

    def check(self, value: Any, info: ValidationInfo) -> list[float]:
        if not isinstance(value, list) or (self.nonempty and not value):
            _fail(f"got {_kind(value)} (expected {self.expected(None)})")
        errors: list[tuple[tuple, str]] = []
        out: list[float] = []
        for i, raw in enumerate(value):
            x, message = _number(raw, self.bounds)
            if message is not None:
                errors.append(((i,), message))
            elif x is not None:
                if self.increasing and out and x < out[-1]:
                    errors.append(((i,), f"got {x:g} after {out[-1]:g} (expected non-decreasing times)"))
                out.append(x)
            if len(errors) > MAX_ERRORS_PER_ARRAY:
                break
        _raise_some("Series", errors)
        return out

    def schema(self) -> dict[str, Any]:
        return {"type": "array", "items": {"type": "number", "minimum": self.bounds.low, "maximum": self.bounds.high}}


class PerLocator(PlainValue):
    """``{locator: [one number per sample]}`` (``width``: ``[[d numbers] per sample]``)."""

    def __init__(self, bounds: Range, *, vectors: bool = False):
        self.bounds, self.vectors = bounds, vectors

    def expected(self, dim: int | None) -> str:
        what = "[[f...] per sample]" if self.vectors else "[a number per sample]"
        return "{locator: " + what + "} or null"

    def check(self, value: Any, info: ValidationInfo) -> dict[str, list[Any]] | None:
        if value is None:
            return None
        if not isinstance(value, dict):
            _fail(f"got {_kind(value)} (expected {self.expected(None)})")
        errors: list[tuple[tuple, str]] = []
        dim = _dimension(info)
        for name, column in value.items():
            if not is_name(name):
                errors.append(((name,), "expected a locator name as the key"))
                continue
            if not isinstance(column, list):
                errors.append(((name,), f"got {_kind(column)} (expected a list, one entry per sample)"))
                continue
            for i, entry in enumerate(column):
                if self.vectors:
                    n = (
                        dim
                        if dim is not None
                        else (len(entry) if isinstance(entry, list) and len(entry) in (2, 3) else 3)
                    )
                    errors += _row_errors(entry, [self.bounds] * n, (name, i))
                else:
                    _, message = _number(entry, self.bounds)
                    if message is not None:
                        errors.append(((name, i), message))
                if len(errors) > MAX_ERRORS_PER_ARRAY:
                    break
        _raise_some("PerLocator", errors)
        return value

    def schema(self) -> dict[str, Any]:
        return {"type": ["object", "null"]}


class Numbers(PlainValue):
    """``{name: number}`` (timings, final gaps, coverage counts); ``nullable`` values allowed."""

    def __init__(
        self, bounds: Range = SIGNED, *, locators: bool = False, nullable_values: bool = False, nullable: bool = False
    ):
        self.bounds, self.locators, self.nullable_values, self.nullable = bounds, locators, nullable_values, nullable

    def expected(self, dim: int | None) -> str:
        return "{" + ("locator" if self.locators else "name") + f": {self.bounds.expected()}}}"

    def check(self, value: Any, info: ValidationInfo) -> dict[str, Any] | None:
        if value is None and self.nullable:
            return None
        if not isinstance(value, dict):
            _fail(f"got {_kind(value)} (expected {self.expected(None)})")
        errors: list[tuple[tuple, str]] = []
        for key, x in value.items():
            if self.locators and not is_state_name(key, GAP_SUFFIXES):
                errors.append(((key,), "expected a locator name as the key"))
            elif x is None and self.nullable_values:
                continue
            else:
                _, message = _number(x, self.bounds)
                if message is not None:
                    errors.append(((key,), message))
        _raise_some("Numbers", errors)
        return value

    def schema(self) -> dict[str, Any]:
        return {"type": "object", "additionalProperties": {"type": "number"}}


class AnyObject(PlainValue):
    """An object kept as written (read by no check: a perturbation's description, a session's details)."""

    def __init__(self, *, nullable: bool = False):
        self.nullable = nullable

    def expected(self, dim: int | None) -> str:
        return "an object"

    def check(self, value: Any, info: ValidationInfo) -> Any:
        if value is None and self.nullable:
            return None
        if not isinstance(value, dict):
            _fail(f"got {_kind(value)} (expected an object)")
        return value

    def schema(self) -> dict[str, Any]:
        return {"type": "object"}


class Sha256(PlainValue):
    """A SHA-256 digest: 64 lowercase hex digits."""

    def expected(self, dim: int | None) -> str:
        return "64 lowercase hex digits"

    def check(self, value: Any, info: ValidationInfo) -> str:
        if not (isinstance(value, str) and len(value) == 64 and all(c in "0123456789abcdef" for c in value)):
            _fail(f"got {_kind(value)} (expected 64 lowercase hex digits)")
        return value

    def schema(self) -> dict[str, Any]:
        return {"type": "string", "pattern": "^[0-9a-f]{64}$"}


# -- objects ------------------------------------------------------------------------------------
def _message(error: Any) -> str:
    ctx = error.get("ctx") or {}
    if error["type"] == _ERROR:
        return str(ctx["message"])
    if error["type"] in ("list_type", "tuple_type"):
        return f"got {_kind(error.get('input'))} (expected a list)"
    return f"got {_kind(error.get('input'))} ({error['msg'].lower()})"


class JsonObject(BaseModel):
    """A JSON object: its keys are the fields; unknown keys, missing keys and every bad value are reported.

    ``rules`` adds the checks of several keys at once (one pose per sample time).
    """

    model_config = ConfigDict(extra="forbid", frozen=True, defer_build=True, arbitrary_types_allowed=True)
    what: ClassVar[str] = "an object"

    @classmethod
    def value_of(cls, key: str) -> PlainValue | None:
        return next((m for m in cls.model_fields[key].metadata if isinstance(m, PlainValue)), None)

    @classmethod
    def rules(cls, data: Mapping[str, Any], context: Mapping[str, Any]) -> list[tuple[tuple, str]]:
        return []

    @model_validator(mode="wrap")
    @classmethod
    def _read(cls, data: Any, handler: Callable[[Any], Any], info: ValidationInfo) -> Any:
        if not isinstance(data, dict):
            _fail(f"got {_kind(data)} (expected {cls.what})")
        fields = {field.alias or name: name for name, field in cls.model_fields.items()}  # "from" → from_
        keys = list(fields)
        errors: list[tuple[tuple, str]] = [
            ((key,), f"unknown key (expected one of: {', '.join(sorted(keys))})") for key in data if key not in keys
        ]
        for key, name in fields.items():
            field = cls.model_fields[name]
            if key not in data and field.is_required():
                value = cls.value_of(name)
                what = value.expected(_dimension(info)) if value else "an object"
                errors.append(((key,), f"missing (expected {what})"))
        given = {k: v for k, v in data.items() if k in keys}
        result = None
        try:
            result = handler(given)
        except ValidationError as exc:
            errors += [(tuple(e["loc"]), _message(e)) for e in exc.errors() if e["type"] != "missing"]
        if not errors:
            errors = cls.rules(data, _context(info))
        if errors:
            raise _errors(cls.__name__, errors)
        return result


class Pose(JsonObject):
    """``T_world_body``: 3D ``{position, quaternion_wxyz}``, 2D ``{position, angle_deg}``."""

    what: ClassVar[str] = "a pose {position, quaternion_wxyz} (3D) or {position, angle_deg} (2D)"
    position: Annotated[tuple[float, ...], Series(limits.COORDINATE)] = Field(description="Body origin [m], world.")
    quaternion_wxyz: Annotated[tuple[float, ...] | None, Series(SIGNED)] = Field(
        None, description="3D: the rotation R_world_body as a unit quaternion (w, x, y, z)."
    )
    angle_deg: Annotated[float | None, Real(limits.ANGLE)] = Field(None, description="2D: the rotation [deg].")

    @classmethod
    def rules(cls, data: Mapping[str, Any], context: Mapping[str, Any]) -> list[tuple[tuple, str]]:
        dim = context.get("dimension")
        n = len(data["position"])
        if dim is None:
            dim = 3 if "quaternion_wxyz" in data else 2
        if dim == 3 and "angle_deg" in data:
            return [
                (("angle_deg",), "a 2D pose (angle_deg) in a plan for a 3D fixture: the plan is for another fixture")
            ]
        if dim == 2 and "quaternion_wxyz" in data:
            return [
                (
                    ("quaternion_wxyz",),
                    "a 3D pose (quaternion_wxyz) in a plan for a 2D fixture: the plan is for another fixture",
                )
            ]
        if n != dim:
            return [(("position",), f"got {n} numbers (expected {dim} for a {dim}D pose)")]
        if dim == 3:
            if "quaternion_wxyz" not in data:
                return [(("quaternion_wxyz",), "missing (expected 4 numbers, a unit quaternion w, x, y, z)")]
            q = data["quaternion_wxyz"]
            norm = math.sqrt(sum(float(x) ** 2 for x in q)) if len(q) == 4 else 0.0
            if len(q) != 4 or abs(norm - 1.0) > DEFAULT.plan_file.quaternion_norm_tol:
                return [(("quaternion_wxyz",), f"got {shorten(str(q))} (expected a unit quaternion w, x, y, z)")]
            return []
        if "angle_deg" not in data:
            return [(("angle_deg",), f"missing (expected {limits.ANGLE.expected()})")]
        return []


class Pushes(JsonObject):
    """A recorded transition's pushes: the coupling wrench on the part, sampled from the transition's start."""

    time_s: Annotated[tuple[float, ...], Series(limits.DURATION, increasing=True, nonempty=True)] = Field(
        description="Sample times from the transition's start [s]."
    )
    wrench: Annotated[tuple[tuple[float, ...], ...], Wrenches()] = Field(
        description="The push at each sample: force, moment about the body origin, world axes [N, N·m]."
    )

    @classmethod
    def rules(cls, data: Mapping[str, Any], context: Mapping[str, Any]) -> list[tuple[tuple, str]]:
        T = len(data["time_s"])
        if len(data["wrench"]) != T:
            return [(("wrench",), f"got {len(data['wrench'])} wrenches (expected {T}, one per time_s)")]
        return []


_OPTIONAL_NUMBER = Real(SIGNED, nullable=True)
_OPTIONAL_QUANTITY = Real(QUANTITY, nullable=True)


class Transition(JsonObject):
    """A transition of a plan: ``from`` → ``to`` closing ``added``, its push and knot poses."""

    from_: Annotated[tuple[str, ...], Locators()] = Field(alias="from", description="The contact state it starts in.")
    to: Annotated[tuple[str, ...] | None, Locators()] = Field(None, description="The contact state it ends in.")
    added: Annotated[str | tuple[str, ...] | None, Added()] = Field(
        None, description="The locator it closes (a list: locators closing at the same instant)."
    )
    motion: Annotated[str, Str(MOTIONS)] = Field("slide", description="free (no contact), slide or roll.")
    wrench: Annotated[tuple[float, ...] | None, Wrench(nullable=True)] = Field(
        None, description="The mean planned push [N, N·m] (null: nothing to push against)."
    )
    margin: Annotated[float | None, _OPTIONAL_NUMBER] = Field(None, description="Least normal force kept [N].")
    friction_robustness: Annotated[float | None, _OPTIONAL_NUMBER] = Field(None, description="δ of μ(1 ± δ).")
    time_s: Annotated[float, Real(limits.DURATION)] = Field(1.0, description="Planned duration [s].")
    path_length_m: Annotated[float | None, _OPTIONAL_QUANTITY] = Field(None, description="Path length [m].")
    max_constraint_violation_m: Annotated[float | None, _OPTIONAL_NUMBER] = Field(None, description="[m]")
    solve_time_s: Annotated[float | None, _OPTIONAL_QUANTITY] = Field(None, description="[s]")
    poses: tuple[Pose, ...] = Field((), description="The planned knot poses, from the start of the transition.")
    peak_force_fraction: Annotated[float | None, _OPTIONAL_QUANTITY] = Field(None, description="‖F‖ / max_force.")
    peak_torque_fraction: Annotated[float | None, _OPTIONAL_QUANTITY] = Field(None, description="‖T‖ / max_torque.")
    # a recording's
    t_start_s: Annotated[float | None, Real(limits.DURATION)] = Field(
        None, description="Recording: the session time the transition started [s]."
    )
    pushes: Pushes | None = Field(None, description="Recording: the pushes used, sampled.")
    lost: Annotated[tuple[str, ...] | None, Locators()] = Field(None, description="Recording: locators released.")


class Tried(JsonObject):
    """A transition the search priced."""

    from_: Annotated[tuple[str, ...], Locators()] = Field(alias="from", description="Its start state.")
    add: Annotated[str | tuple[str, ...], Added()] = Field(description="The locator(s) it closes.")
    ok: Annotated[bool, Flag()] = Field(False, description="Whether it worked.")
    reason: Annotated[str, Str()] = Field("", description="Why not.")
    stage: Annotated[str, Str(("fine", "precheck", "path"))] = Field("fine", description="How far it was priced.")


class Certified(JsonObject):
    """A failed transition certified by its wrench search (an infeasible plan's)."""

    from_: Annotated[tuple[str, ...], Locators()] = Field(alias="from", description="Its start state.")
    add: Annotated[str | tuple[str, ...], Added()] = Field(description="The locator(s) it closes.")
    reason: Annotated[str, Str()] = Field("", description="Why it fails.")


class PolicyEntry(JsonObject):
    """The next transition from one contact state."""

    state: Annotated[tuple[str, ...], Locators()] = Field(description="The contact state.")
    next: Annotated[tuple[str, ...] | None, Locators(nullable=True)] = Field(None, description="The next state.")
    target: Annotated[str, Locator()] = Field(description="The locator to close.")
    motion: Annotated[str, Str(MOTIONS)] = Field(description="free, roll or slide.")
    wrench: Annotated[tuple[float, ...] | None, Wrench(nullable=True)] = Field(None, description="[N, N·m]")
    margin_N: Annotated[float | None, _OPTIONAL_NUMBER] = Field(None, description="[N]")
    cost_to_go_m: Annotated[float | None, _OPTIONAL_QUANTITY] = Field(None, description="[m]")
    source: Annotated[str, Str(("plan", "pre-image"))] = Field("pre-image", description="Where it comes from.")
    checked: Annotated[bool, Flag()] = Field(False, description="A non-jamming push was found.")
    together: Annotated[tuple[str, ...], Locators()] = Field((), description="Locators closing with the target.")


class Event(JsonObject):
    """One event of the executor's log."""

    time_s: Annotated[float, Real(QUANTITY)] = Field(0.0, description="[s]")
    kind: Annotated[str, Str()] = Field("", description="What happened.")
    message: Annotated[str, Str()] = Field("", description="In words.")


class Execution(JsonObject):
    """What the planner's executor did during the verification."""

    outcome: Annotated[str, Str(("running", "reached", "failed"))] = Field("running", description="How it ended.")
    reason: Annotated[str, Str()] = Field("", description="Why.")
    failure_kind: Annotated[str | None, Str(nullable=True)] = Field(None, description="The kind of failure.")
    counts: Annotated[dict[str, Any], Numbers(QUANTITY)] = Field(default_factory=dict, description="Counters.")
    events: tuple[Event, ...] = Field((), description="What happened when.")
    max_command_force_N: Annotated[float, Real(QUANTITY)] = Field(0.0, description="[N]")
    max_command_torque_Nm: Annotated[float, Real(QUANTITY)] = Field(0.0, description="[N·m]")
    beyond_fraction_solves: Annotated[int, Count()] = Field(0, description="Solves beyond the headroom.")
    max_arm_torque_ratio: Annotated[float | None, _OPTIONAL_QUANTITY] = Field(
        None, description="With a [robot]: the most loaded joint's |τ| / τ_max under the pushes commanded."
    )
    arm_unreached_solves: Annotated[int, Count()] = Field(0, description="Solves where the arm does not reach.")


_FORCES = Range("a force", "N", -limits.FORCE_MAX_N, limits.FORCE_MAX_N)
_GAPS = Range("a gap", "m", -limits.COORDINATE_MAX_M, limits.COORDINATE_MAX_M)


class Trace(JsonObject):
    """The verification's (or session's) sampled history: one entry per sample time."""

    every_s: Annotated[float | None, Real(QUANTITY, nullable=True)] = Field(None, description="Sampling step [s].")
    names: Annotated[tuple[str, ...], Locators()] = Field(description="The locators, in the fixture's order.")
    time_s: Annotated[tuple[float, ...], Series(limits.DURATION, increasing=True, nonempty=True)] = Field(
        description="Sample times [s]."
    )
    poses: tuple[Pose, ...] = Field(description="The part's pose per sample.")
    gaps_m: Annotated[dict | None, PerLocator(_GAPS)] = Field(None, description="Gap per locator per sample [m].")
    normal_forces_N: Annotated[dict | None, PerLocator(_FORCES)] = Field(None, description="[N]")
    forces_world_N: Annotated[dict | None, PerLocator(_FORCES, vectors=True)] = Field(
        description="Force on the part at each locator, world axes [N] (null: not known)."
    )
    coupling_wrench: Annotated[Any, Wrenches(nullable=True)] = Field(None, description="The hand's push per sample.")
    felt_wrench: Annotated[Any, Wrenches(nullable=True)] = Field(None, description="What the device displayed.")
    command_wrench: Annotated[Any, Wrenches(nullable=True)] = Field(None, description="What the executor asked.")
    pressed: tuple[Annotated[tuple[str, ...], Locators()], ...] = Field(description="Locators pressed per sample.")

    @classmethod
    def rules(cls, data: Mapping[str, Any], context: Mapping[str, Any]) -> list[tuple[tuple, str]]:
        T = len(data["time_s"])
        errors: list[tuple[tuple, str]] = []
        for key in ("poses", "pressed", "coupling_wrench", "felt_wrench", "command_wrench"):
            rows = data.get(key)
            if rows is not None and len(rows) != T:
                errors.append(((key,), f"got {len(rows)} entries (expected {T}, one per time_s)"))
        names = data["names"]
        for key in ("gaps_m", "normal_forces_N", "forces_world_N"):
            columns = data.get(key)
            if columns is None:
                continue
            for name in names:
                if name not in columns:
                    errors.append(((key, name), f"missing (expected {T} entries, one per time_s)"))
                elif len(columns[name]) != T:
                    errors.append(((key, name), f"got {len(columns[name])} entries (expected {T}, one per time_s)"))
            errors += [((key, n), "not one of the trace's names") for n in columns if n not in names]
        return errors


class Verification(JsonObject):
    """The simulated haptic loop's outcome (a recording's: the session as it ran)."""

    passed: Annotated[bool, Flag()] = Field(False, description="Whether the load passed every check.")
    reason: Annotated[str, Str()] = Field("", description="Why not, or a note.")
    final_pose: Pose | None = Field(None, description="The part's pose at the end.")
    max_penetration: Annotated[float | None, _OPTIONAL_QUANTITY] = Field(None, description="[m]")
    deadline_misses: Annotated[int | None, Count(nullable=True)] = Field(None, description="Ticks over 1 ms.")
    tick_mean_us: Annotated[float | None, _OPTIONAL_QUANTITY] = Field(None, description="[µs]")
    tick_max_us: Annotated[float | None, _OPTIONAL_QUANTITY] = Field(None, description="[µs]")
    observed_sequence: tuple[Annotated[tuple[str, ...], Locators()], ...] = Field((), description="States seen.")
    final_gaps: Annotated[dict[str, Any], Numbers(_GAPS, locators=True)] = Field(
        default_factory=dict, description="Gap per locator at the end [m]."
    )
    duration_s: Annotated[float | None, Real(limits.DURATION, nullable=True)] = Field(None, description="[s]")
    felt_force_max: Annotated[float | None, _OPTIONAL_QUANTITY] = Field(None, description="[N]")
    unconverged_steps: Annotated[int | None, Count(nullable=True)] = Field(None, description="Capped solves.")
    max_solver_error: Annotated[float | None, _OPTIONAL_QUANTITY] = Field(None, description="FCLib residual.")
    max_push_force: Annotated[float | None, _OPTIONAL_QUANTITY] = Field(None, description="[N]")
    max_push_torque: Annotated[float | None, _OPTIONAL_QUANTITY] = Field(None, description="[N·m]")
    saturated_ticks: Annotated[int | None, Count(nullable=True)] = Field(None, description="Capped ticks.")
    limit_fraction: Annotated[float | None, _OPTIONAL_QUANTITY] = Field(None, description="The headroom.")
    peak_force_fraction: Annotated[float | None, _OPTIONAL_QUANTITY] = Field(None, description="‖F‖ / max_force.")
    peak_torque_fraction: Annotated[float | None, _OPTIONAL_QUANTITY] = Field(None, description="‖T‖ / max_torque")
    ticks_above_fraction: Annotated[int | None, Count(nullable=True)] = Field(None, description="Ticks above it.")
    planner_wall_time_in_loop_s: Annotated[float | None, _OPTIONAL_QUANTITY] = Field(None, description="[s]")
    failed_checks: tuple[Annotated[str, Str()], ...] = Field((), description="The checks that failed.")
    execution: Execution | None = Field(None, description="The executor's log.")
    trace: Trace | None = Field(None, description="The sampled history.")
    kind: Annotated[str | None, Str(("session",))] = Field(None, description="Recording: session.")
    robot_links: Annotated[Any, AnyObject(nullable=True)] = Field(
        None, description="With [robot]: the arm's links along the simulated load (least clearance, first hit)."
    )


INSERTION_STAGES = ("free", "insert", "seat")
INSERTION_ACTIONS = ("insert", "seat", "hold")
_HEIGHTS = Range("a height above the located pose", "m", 0.0, limits.COORDINATE_MAX_M)


class InsertionPolicyEntry(JsonObject):
    """What a pin insertion's run does in one observable state (``planner.insertion_policy``)."""

    what: ClassVar[str] = "a policy entry {engaged, seated, transition, action, next}"
    engaged: Annotated[tuple[str, ...], Locators()] = Field(description="The pins and bores engaged.")
    seated: Annotated[bool, Flag()] = Field(description="Every pin engaged and every rest pressed: hold.")
    transition: Annotated[int | None, Count(nullable=True)] = Field(
        description="The transition (stage) to run from here, an index into transitions; null: hold."
    )
    action: Annotated[str, Str(INSERTION_ACTIONS)] = Field(description="insert, seat or hold.")
    next: Annotated[tuple[str, ...], Locators()] = Field(description="The planned state it leads to.")


class InsertionPolicy(JsonObject):
    """A pin insertion's recovery: an entry per observable state, the back-off heights, the budget."""

    what: ClassVar[str] = "the insertion's policy {retries, time_s, backoff_min_m, backoff_heights_m, entries}"
    retries: Annotated[int, Count()] = Field(description="Back-offs and re-entries at most.")
    time_s: Annotated[float, Real(limits.DURATION)] = Field(description="Seconds of recovery at most [s].")
    backoff_min_m: Annotated[float, Real(_HEIGHTS)] = Field(description="A back-off rises at least this far [m].")
    backoff_heights_m: Annotated[tuple[float, ...], Series(_HEIGHTS)] = Field(
        description="The stages' ends a back-off rises to, above the located pose, ascending [m]."
    )
    entries: tuple[InsertionPolicyEntry, ...] = Field(description="One per observable state.")

    @classmethod
    def rules(cls, data: Mapping[str, Any], context: Mapping[str, Any]) -> list[tuple[tuple, str]]:
        h = [float(x) for x in data["backoff_heights_m"]]
        if any(b <= a for a, b in zip(h, h[1:], strict=False)):
            return [(("backoff_heights_m",), f"got {shorten(str(h))} (expected heights strictly ascending)")]
        return []


class Insertion(JsonObject):
    """A plan for a fixture with pins or bores: what re-runs its staged insertion (``planner.insertion``)."""

    what: ClassVar[str] = "the staged insertion {axis, goal, stages, seat_wrench, policy}"
    axis: Annotated[tuple[float, ...], Series(SIGNED)] = Field(
        description="The insertion axis u, world (a unit vector): the part moves along −u onto its pins."
    )
    goal: Pose = Field(description="The located pose the insertion ends at (the guide's end).")
    stages: tuple[Annotated[str, Str(INSERTION_STAGES)], ...] = Field(
        description="Each transition's stage: free (the approach), insert (a pin or bore entered), seat."
    )
    seat_wrench: Annotated[tuple[float, ...], Wrench()] = Field(
        description="The seating push at the located pose, about the body origin, world axes [N, N·m]."
    )
    policy: InsertionPolicy | None = Field(
        None, description="What the run does from every observable state and how it recovers (absent: no recovery)."
    )

    @classmethod
    def rules(cls, data: Mapping[str, Any], context: Mapping[str, Any]) -> list[tuple[tuple, str]]:
        u = data["axis"]
        norm = math.sqrt(sum(float(x) ** 2 for x in u)) if len(u) == 3 else 0.0
        if len(u) != 3 or abs(norm - 1.0) > DEFAULT.plan_file.quaternion_norm_tol:
            return [(("axis",), f"got {shorten(str(u))} (expected a unit vector of 3 numbers)")]
        return []


class PlanFile(JsonObject):
    """A plan file (``fixplan solve --out``): ``docs/plan-format.md``."""

    what: ClassVar[str] = "the JSON object written by 'fixplan solve --out'"
    fixture: Annotated[str | None, Str(what="the fixture file's path")] = Field(None, description="Its fixture.")
    fixture_sha256: Annotated[str | None, Sha256()] = Field(
        None, description="SHA-256 of the fixture's bytes (a mesh part: followed by its mesh file's bytes)."
    )
    status: Annotated[str, Str(PLAN_STATUSES)] = Field(description="planned, unverified or infeasible.")
    reason: Annotated[str, Str()] = Field("", description="Why not planned, or a note.")
    sequence: tuple[Annotated[tuple[str, ...], Locators()], ...] = Field((), description="The contact states.")
    transitions: tuple[Transition, ...] = Field(description="One per change of contact state.")
    tried: tuple[Tried, ...] = Field((), description="Every transition the search priced.")
    proven: Annotated[bool | None, Flag(nullable=True)] = Field(None, description="Infeasible: certified.")
    certificate: tuple[Certified, ...] = Field((), description="Infeasible: the certified failed transitions.")
    verification: Verification | None = Field(None, description="The simulated haptic loop's outcome.")
    policy: tuple[PolicyEntry, ...] | None = Field(None, description="The next transition from every state.")
    coverage: Annotated[dict | None, Numbers(SIGNED, nullable_values=True, nullable=True)] = Field(
        None, description="Policy."
    )
    timings: Annotated[dict[str, Any], Numbers(QUANTITY)] = Field(default_factory=dict, description="[s]")
    perturbation: Annotated[Any, AnyObject(nullable=True)] = Field(None, description="--perturb-seed's world.")
    robot: Annotated[Any, AnyObject(nullable=True)] = Field(
        None, description="The fixture's [robot] along the plan (kept as written; `solve` recomputes it)."
    )
    clamping: Annotated[Any, AnyObject(nullable=True)] = Field(
        None, description="--clamp: the clamping stage after loading (fixplan clamp's JSON)."
    )
    clearance_pose_range: Annotated[Any, AnyObject(nullable=True)] = Field(
        None, description="With [[pin]]: the located poses the pins' clearances allow (kept as written)."
    )
    insertion: Insertion | None = Field(
        None, description="With [[pin]] or [[bore]], a plan found: its staged insertion (what verify re-runs)."
    )


class Where(JsonObject):
    """Where a session ended: time, contact state, pose, and for a jam the push and its margin."""

    time_s: Annotated[float | None, Real(limits.DURATION, nullable=True)] = Field(None, description="[s]")
    state: Annotated[tuple[str, ...] | None, Locators(nullable=True)] = Field(None, description="Contact state.")
    pose: Pose | None = Field(None, description="The part's pose.")
    push: Annotated[tuple[float, ...] | None, Wrench(nullable=True)] = Field(None, description="[N, N·m]")
    margin: Annotated[float | None, _OPTIONAL_NUMBER] = Field(None, description="The jam's margin.")


class RecordingFile(JsonObject):
    """A haptic session's recording (``fixplan haptic --record``): ``docs/plan-format.md``."""

    what: ClassVar[str] = "the JSON object written by 'fixplan haptic --record'"
    source: Annotated[str, Str((RECORDING_SOURCE,))] = Field(description="haptic session.")
    fixture: Annotated[str, Str(what="the path of the fixture the session ran on")] = Field(
        description="The fixture file the session ran on."
    )
    fixture_sha256: Annotated[str | None, Sha256()] = Field(
        None, description="SHA-256 of the fixture's bytes (a mesh part: followed by its mesh file's bytes)."
    )
    status: Annotated[str, Str(SESSION_STATUSES)] = Field(description="How the session ended.")
    reason: Annotated[str, Str()] = Field("", description="Why.")
    where: Annotated[Any, AnyObject(nullable=True)] = Field(None, description="Where it ended.")
    sequence: tuple[Annotated[tuple[str, ...], Locators()], ...] = Field((), description="The observed states.")
    transitions: tuple[Transition, ...] = Field(description="Per change of state: poses and pushes.")
    tried: tuple[Tried, ...] = Field((), description="Empty.")
    verification: Verification = Field(description="The session as the loop ran it, with its trace.")
    session: Annotated[Any, AnyObject(nullable=True)] = Field(None, description="Device, loop timing, bridge.")
    timings: Annotated[dict[str, Any], Numbers(QUANTITY)] = Field(default_factory=dict, description="[s]")

    @classmethod
    def rules(cls, data: Mapping[str, Any], context: Mapping[str, Any]) -> list[tuple[tuple, str]]:
        errors: list[tuple[tuple, str]] = []
        trace = data["verification"].get("trace")
        if trace is None:
            errors.append((("verification", "trace"), "missing (expected the session's trace, the pushes' evidence)"))
        elif trace.get("coupling_wrench") is None:
            errors.append(
                (("verification", "trace", "coupling_wrench"), "missing (expected the pushes the session measured)")
            )
        for i, tr in enumerate(data["transitions"]):
            for key in ("t_start_s", "pushes"):
                if tr.get(key) is None:
                    errors.append((("transitions", i, key), f"missing (expected the recorded {key})"))
        where = data.get("where")
        if isinstance(where, dict):
            try:
                Where.model_validate(where, context=context)
            except ValidationError as exc:
                errors += [(("where", *e["loc"]), _message(e)) for e in exc.errors()]
        return errors


def is_recording(data: Any) -> bool:
    """The object is a haptic session's recording (its ``source`` says so)."""
    return isinstance(data, dict) and data.get("source") == RECORDING_SOURCE


def validate_plan_document(data: Any, dimension: int | None = None) -> list[Issue]:
    """Every problem of a plan file's or recording's object (dotted key path, what was expected); [] when valid.

    ``dimension`` is the fixture's (2 or 3) when known: poses and wrenches are then checked for it.
    """
    model: type[JsonObject] = RecordingFile if is_recording(data) else PlanFile
    if not isinstance(data, dict):
        return [Issue("(file)", f"got {_kind(data)} (expected {model.what})")]
    try:
        with _without_plugins():
            model.model_validate(data, context={"dimension": dimension})
    except ValidationError as exc:
        return [Issue(key_path(tuple(e["loc"]), data) or "(file)", _message(e)) for e in exc.errors()]
    return []
