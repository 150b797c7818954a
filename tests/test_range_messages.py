"""A value outside its range is quoted as given, never rounded to the limit.

``mass = 10000.0001`` was reported as ``got 10000`` (``:g`` keeps six digits), which reads as
"the limit itself is refused"; the same for gravity, friction and the command line's numbers.
For values just outside each range (one ulp to a relative 1e-3 beyond either end), the message
must quote the value exactly: ``repr`` (the shortest text that reads back as the same float), or
its six-digit form when that reads back exactly too (``200``, ``1e+12``).
"""

from __future__ import annotations

import re

import numpy as np
import pytest
from conftest import PROBLEMS, ROOT, run_cli
from hypothesis import given, settings
from hypothesis import strategies as st

import fixplan
from fixplan import limits
from fixplan.errors import FixtureError, InputError, quote_number

BOX = (PROBLEMS / "box-3-2-1.toml").read_text()

# (what the message names, the line of box-3-2-1.toml to rewrite, its replacement with {v}, the range)
KEYS = [
    ("workpiece.mass", "mass = 2.0", "mass = {v}", limits.MASS),
    ("scene.gravity[2]", "gravity = [0.0, 0.0, -9.81]", "gravity = [0.0, 0.0, {v}]", limits.GRAVITY),
    ("locator.B1.friction", "friction = 0.25", "friction = {v}", limits.FRICTION),
    ("locator.B1.radius", "radius = 0.0", "radius = {v}", limits.TIP_RADIUS),
    ("workpiece.size[0]", "size = [0.20, 0.10, 0.05]", "size = [{v}, 0.10, 0.05]", limits.SIZE),
    ("locator.B1.position[0]", "position = [0.04, 0.02, 0.0]", "position = [{v}, 0.02, 0.0]", limits.COORDINATE),
    ("workpiece.start.rpy_deg[2]", "rpy_deg = [0.0, 0.0, 0.0]", "rpy_deg = [0.0, 0.0, {v}]", limits.ANGLE),
    ("manipulator.max_force", "max_force = 40.0", "max_force = {v}", limits.MAX_FORCE),
]


def _outside(rng: limits.Range, above: bool, ulps: int, rel: float) -> float:
    """A float just outside ``rng``: ``ulps`` steps past the end, or a relative ``rel`` past it."""
    end = rng.high if above else rng.low
    direction = np.inf if above else -np.inf
    v = end
    for _ in range(ulps):
        v = float(np.nextafter(v, direction))
    if rel > 0.0:
        step = rel * max(abs(end), 1e-300)
        v = end + step if above else end - step
    assert not rng.contains(v)
    return v


def _beyond(rng: limits.Range):  # type: ignore[no-untyped-def]
    return st.builds(
        lambda above, ulps, rel: _outside(rng, above, ulps, rel),
        st.booleans(),
        st.integers(1, 64),
        st.one_of(st.just(0.0), st.floats(1e-15, 1e-3)),
    )


def _quoted(message: str, before: str) -> float:
    """The number quoted right after ``before`` in ``message``."""
    m = re.search(re.escape(before) + r"(\S+) \(expected", message)
    assert m, message
    return float(m.group(1))


def _fixture_with(line: str, replacement: str, v: float) -> str:
    assert line in BOX
    return BOX.replace(line, replacement.format(v=repr(v)), 1)


@pytest.mark.parametrize(("key", "line", "replacement", "rng"), KEYS, ids=[k[0] for k in KEYS])
def test_the_issue_examples(key, line, replacement, rng):
    """The first value past the upper end: ``got 10000.0001``-style, not the limit."""
    v = float(np.nextafter(rng.high, np.inf)) if key != "workpiece.mass" else 10000.0001
    with pytest.raises(FixtureError) as err:
        fixplan.loads(_fixture_with(line, replacement, v))
    message = str(err.value)
    assert f"{key}: got {v!r} (expected" in message, message


@pytest.mark.parametrize(("key", "line", "replacement", "rng"), KEYS, ids=[k[0] for k in KEYS])
@settings(max_examples=15, deadline=None, derandomize=True)
@given(data=st.data())
def test_fixture_values_just_outside_are_quoted_as_given(key, line, replacement, rng, data):
    v = data.draw(_beyond(rng))
    if key in ("locator.B1.radius", "locator.B1.friction") and v < 0.0:
        expected_tail = "≥ 0"  # these keys' own minimum speaks first for a negative value
    else:
        expected_tail = rng.expected()
    with pytest.raises(FixtureError) as err:
        fixplan.loads(_fixture_with(line, replacement, v))
    message = str(err.value)
    assert _quoted(message, f"{key}: got ") == v, message  # exactly the value, not the limit
    assert f"got {v!r} (expected" in message or f"got {v:g} (expected" in message
    assert expected_tail in message


@settings(max_examples=40, deadline=None, derandomize=True)
@given(data=st.data(), i=st.integers(0, 5))
def test_command_line_numbers_just_outside_are_quoted_as_typed(data, i):
    ranges = limits.wrench_ranges(6)
    v = data.draw(_beyond(ranges[i]))
    parts = ["0"] * 6
    parts[i] = repr(v)
    with pytest.raises(InputError) as err:
        limits.parse_numbers(",".join(parts), "--wrench", 6, ranges)
    assert f"number {i + 1} is {v!r} (expected" in str(err.value)  # as typed
    assert _quoted(str(err.value), f"number {i + 1} is ") == v


@pytest.mark.parametrize(
    ("args", "shown"),
    [
        (["simulate", "--duration", "1000000.0001"], "--duration is 1000000.0001"),
        (["simulate", "--dt", "1.0000000001"], "--dt is 1.0000000001"),
        (["classify", "--wrench", "1000000.0000001,0,0,0,0,0"], "is 1000000.0000001 (expected"),
    ],
)
def test_cli_options_quote_the_value(args, shown):
    proc = run_cli(*args, timeout=120, cwd=ROOT)
    assert proc.returncode == 2, proc.stderr
    assert shown in proc.stderr


@pytest.mark.parametrize(
    ("value", "text"),
    [
        (10000.0001, "10000.0001"),
        (-5e-324, "-5e-324"),
        (10, "10"),
        (np.float64(1.5), "1.5"),
        (" 7.25 ", "7.25"),
        (1e12, "1e+12"),
        (200.0, "200"),
        (100.00000000000001, "100.00000000000001"),
    ],
)
def test_quote_number(value, text):
    assert quote_number(value) == text
    assert re.fullmatch(r"[-+0-9.e]+", quote_number(value))
