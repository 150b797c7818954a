"""Reading untyped TOML tables into typed values, collecting every problem with its key path.

The fixture loader asks a :class:`Reader` for each key; the reader records an
:class:`~fixplan.errors.Issue` (dotted key path, what is wrong, what was expected) instead of
raising, so ``fixplan validate`` can print all problems of a file at once. A value that could
not be read comes back as ``None`` and the caller skips checks that depend on it.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from typing import Any

from fixplan.errors import SHOWN_CHARS as _SHOWN_CHARS
from fixplan.errors import Issue, quote_number, shorten
from fixplan.limits import Range


def _kind(value: Any) -> str:
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, int) and abs(value) >= 10**_SHOWN_CHARS:
        return f"an integer of {len(str(abs(value)))} digits"
    if isinstance(value, int | float):
        return f"the number {value!r}"
    if isinstance(value, str):
        return f"the string {shorten(value)}"
    if isinstance(value, list):
        return f"a list of {len(value)}"
    if isinstance(value, dict):
        return "a table"
    return type(value).__name__


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _as_float(value: int | float) -> float | None:
    """``float(value)``, or None for an integer too large for a float (``10**400``)."""
    try:
        return float(value)
    except OverflowError:
        return None


class Reader:
    """Collects :class:`Issue` objects while reading values out of nested tables."""

    def __init__(self) -> None:
        self.issues: list[Issue] = []

    def error(self, key: str, message: str) -> None:
        self.issues.append(Issue(key, message))

    # -- tables ------------------------------------------------------------------------------
    def table(self, parent: Mapping[str, Any], name: str, path: str, *, required: bool) -> dict | None:
        if name not in parent:
            if required:
                self.error(path, "missing (expected a table)")
            return None
        value = parent[name]
        if not isinstance(value, dict):
            self.error(path, f"got {_kind(value)} (expected a table)")
            return None
        return value

    def tables(self, parent: Mapping[str, Any], name: str, path: str) -> list[dict]:
        if name not in parent:
            return []
        value = parent[name]
        if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
            self.error(path, f"got {_kind(value)} (expected an array of tables [[{name}]])")
            return []
        return value

    def unknown_keys(self, table: Mapping[str, Any], allowed: Iterable[str], path: str) -> None:
        allowed = set(allowed)
        for key in table:
            if key not in allowed:
                where = f"{path}.{key}" if path else key
                self.error(where, f"unknown key (expected one of: {', '.join(sorted(allowed))})")

    # -- scalars -----------------------------------------------------------------------------
    def number(
        self,
        table: Mapping[str, Any],
        name: str,
        path: str,
        *,
        required: bool = False,
        default: float | None = None,
        minimum: float | None = None,
        exclusive_minimum: float | None = None,
        maximum: float | None = None,
        bounds: Range | None = None,
        what: str = "a number",
        too_large: str | None = None,
    ) -> float | None:
        """A number of ``table``; ``too_large`` is a hint added when it is above ``bounds`` (units)."""
        if name not in table:
            if required:
                self.error(path, f"missing (expected {what})")
            return default
        raw = table[name]
        if not _is_number(raw):
            self.error(path, f"got {_kind(raw)} (expected {what})")
            return None
        value = _as_float(raw)
        if value is None:
            self.error(path, f"got {_kind(raw)}, too large for a float (expected {_expected(what, bounds)})")
            return None
        if not math.isfinite(value):
            self.error(path, f"got {value} (expected a finite number)")
            return None
        given = quote_number(raw)  # as written, never rounded to the limit
        if exclusive_minimum is not None and value <= exclusive_minimum:
            self.error(path, f"got {given} (expected {what} > {exclusive_minimum:g})")
            return None
        if minimum is not None and value < minimum:
            self.error(path, f"got {given} (expected {what} ≥ {minimum:g})")
            return None
        if maximum is not None and value > maximum:
            self.error(path, f"got {given} (expected {what} ≤ {maximum:g})")
            return None
        if bounds is not None and not bounds.contains(value):
            hint = f"; {too_large}" if too_large and value > bounds.high else ""
            self.error(path, f"got {given} (expected {bounds.expected()}{hint})")
            return None
        return value

    def integer(
        self, table: Mapping[str, Any], name: str, path: str, *, required: bool, allowed: tuple[int, ...]
    ) -> int | None:
        expected = " or ".join(str(a) for a in allowed)
        if name not in table:
            if required:
                self.error(path, f"missing (expected {expected})")
            return None
        value = table[name]
        if not isinstance(value, int) or isinstance(value, bool) or value not in allowed:
            self.error(path, f"got {_kind(value)} (expected {expected})")
            return None
        return int(value)

    def string(
        self,
        table: Mapping[str, Any],
        name: str,
        path: str,
        *,
        required: bool = False,
        choices: tuple[str, ...] | None = None,
    ) -> str | None:
        if name not in table:
            if required:
                expected = f"one of: {', '.join(choices)}" if choices else "a string"
                self.error(path, f"missing (expected {expected})")
            return None
        value = table[name]
        if not isinstance(value, str) or not value.strip():
            self.error(path, f"got {_kind(value)} (expected a non-empty string)")
            return None
        if choices is not None and value not in choices:
            self.error(path, f"got {shorten(value)} (expected one of: {', '.join(choices)})")
            return None
        return value

    def vector(
        self,
        table: Mapping[str, Any],
        name: str,
        path: str,
        length: int,
        *,
        required: bool = False,
        default: list[float] | None = None,
        what: str = "numbers",
        dimension_hint: int | None = None,
        bounds: Range | None = None,
        too_large: str | None = None,
    ) -> list[float] | None:
        """A list of ``length`` numbers; every bad element is reported, and then None is returned.

        ``too_large`` is a hint added (once) to the first element above ``bounds`` (units).
        """
        if name not in table:
            if required:
                self.error(path, f"missing (expected {length} {what})")
            return None if default is None else list(default)
        value = table[name]
        if not isinstance(value, list):
            self.error(path, f"got {_kind(value)} (expected a list of {length} {what})")
            return None
        if len(value) != length:
            hint = f" for a {dimension_hint}D scene" if dimension_hint else ""
            self.error(path, f"got {len(value)} numbers (expected {length}{hint})")
            return None
        out: list[float] = []
        hinted = too_large is None
        for i, x in enumerate(value):
            where = f"{path}[{i}]"
            if not _is_number(x):
                self.error(where, f"got {_kind(x)} (expected a number)")
                continue
            v = _as_float(x)
            if v is None:
                self.error(where, f"got {_kind(x)}, too large for a float (expected {_expected('a number', bounds)})")
                continue
            if not math.isfinite(v):
                self.error(where, f"got {x} (expected a finite number)")
                continue
            if bounds is not None and not bounds.contains(v):
                hint = ""
                if not hinted and v > bounds.high:
                    hint, hinted = f"; {too_large}", True
                self.error(where, f"got {quote_number(x)} (expected {bounds.expected()}{hint})")
                continue
            out.append(v)
        return out if len(out) == length else None


def _expected(what: str, bounds: Range | None) -> str:
    return what if bounds is None else bounds.expected()
