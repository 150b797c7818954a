"""Input classes of the second hostile-input campaign: nesting, scheduler addresses, range edges, tiny friction.

- Deeply nested TOML in every form (dotted keys, table headers, arrays of tables, arrays,
  inline tables, dotted keys inside inline tables, mixed), from 1 to 40,000 levels: ``validate``
  keeps the contract within a bound, refuses past ``limits.MAX_TOML_NESTING`` with the line,
  and the pre-parse scan never lets through more levels than the limit.
- ``--scheduler`` addresses, well formed or not: :func:`fixplan.cluster.check_address` returns
  a host and a port in 1..65535 or refuses with one printable line; a refused address ends the
  command with exit 2 before any connection.
- Values just outside each fixture range: refused, quoting a number that reads back as exactly
  the value written.
- Tiny positive friction on seeded fixtures and wrenches: μ = 0's verdict and margin, forces in
  the cones.

The short budget (``make test``) runs a few derandomized examples of each; ``make fuzz`` more.
"""

from __future__ import annotations

import math
import re
import tempfile
import tomllib
from pathlib import Path

import numpy as np
from harness import assert_contract, budget, run_in_process, snapshot
from hypothesis import assume, event, given, note
from hypothesis import strategies as st
from mutations import PROBLEMS

from fixplan import limits

BOX = (PROBLEMS / "box-3-2-1.toml").read_text()

# -- nesting -----------------------------------------------------------------------------------
FORMS = ("dotted", "header", "array-header", "array", "inline", "inline-dotted", "mixed")


def _nested(form: str, n: int, key: str) -> str:
    """One statement nesting ``n`` levels in ``form`` (``key``: the bare key repeated)."""
    dotted = ".".join([key] * n)
    return {
        "dotted": f"{dotted} = 1",
        "header": f"[{dotted}]\nx = 1",
        "array-header": f"[[{dotted}]]\nx = 1",
        "array": "x = " + "[" * n + "]" * n,
        "inline": "x = " + f"{{{key}=" * n + "1" + "}" * n,
        "inline-dotted": f"x = {{{dotted} = 1}}",
        "mixed": "x = " + f"{{{key}.{key}=[" * max(1, n // 3) + "]}" * max(1, n // 3),
    }[form]


def _levels(value: object) -> int:
    if isinstance(value, dict):
        return 1 + max((_levels(v) for v in value.values()), default=0)
    if isinstance(value, list):
        return 1 + max((_levels(v) for v in value), default=0)
    return 0


DEPTHS = st.one_of(
    st.integers(1, 2 * limits.MAX_TOML_NESTING),
    st.integers(2 * limits.MAX_TOML_NESTING, 40_000),
    st.just(40_000),
)
KEYS = st.sampled_from(["a", "k9", "_", "-", '"q.q"', "'l'"])


@budget(20)
@given(form=st.sampled_from(FORMS), n=DEPTHS, key=KEYS, where=st.sampled_from(["top", "table", "end"]))
def test_nested_toml_is_bounded_and_refused_with_its_line(form: str, n: int, key: str, where: str) -> None:
    statement = _nested(form, n, key)
    if where == "top" and not statement.startswith("["):
        text = statement + "\n" + BOX
    elif where == "table" and not statement.startswith("["):
        text = BOX + "\n[extra]\n" + statement + "\n"
    else:
        text = BOX + "\n" + statement + "\n"
    event(f"{form}, {'over' if n > limits.MAX_TOML_NESTING // 3 else 'under'} a third of the limit")
    # the scan is sound: what it lets through parses to at most the limit's levels
    found = limits.toml_nesting(text)
    if found is None:
        assert _levels(tomllib.loads(text)) - 1 <= limits.MAX_TOML_NESTING
    else:
        line, depth = found
        assert depth > limits.MAX_TOML_NESTING
        assert 1 <= line <= text.count("\n") + 1
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "deep.toml"
        path.write_text(text)
        before = snapshot(Path(tmp))
        outcome = run_in_process(["validate", str(path)], timeout_s=20, cwd=Path(tmp))
        note(repr(outcome)[:500])
        assert_contract(outcome, before)
        if found is not None:
            assert outcome.code == 2
            lines = outcome.stderr.strip().splitlines()
            assert len(lines) == 1 and f"<toml>: line {found[0]}: " in lines[0], lines


@budget(40)
@given(
    doc=st.recursive(
        st.one_of(st.integers(-5, 5), st.floats(-1e3, 1e3, allow_nan=False), st.text("ab.[]{}#=\"'", max_size=6)),
        lambda children: st.one_of(
            st.lists(children, max_size=3),
            st.dictionaries(st.sampled_from(["a", "b.c", "d", "e.f.g"]), children, max_size=3),
        ),
        max_leaves=40,
    )
)
def test_the_scan_never_undercounts_a_document(doc: object) -> None:
    """Any TOML written from a nested value (strings holding brackets, dots and quotes included):
    the scan's depth is at least the parsed document's levels, so the limit holds."""
    text = "x = " + _inline(doc) + "\n"
    parsed = tomllib.loads(text)
    levels = _levels(parsed) - 1
    found = limits.toml_nesting(text, limit=levels - 1) if levels >= 1 else None
    if levels >= 1:
        assert found is not None, (text, levels)
    assert limits.toml_nesting(text, limit=max(levels, 1) + 64) is None


def _inline(value: object) -> str:
    """``value`` as an inline TOML value; a dict's keys with dots are written dotted (``b.c = …``)."""
    if isinstance(value, dict):
        seen: set[str] = set()
        parts = []
        for k, v in value.items():
            first = k.split(".")[0]
            if first in seen:  # keep the document valid: one entry per first key segment
                continue
            seen.add(first)
            parts.append(f"{k} = {_inline(v)}")
        return "{" + ", ".join(parts) + "}"
    if isinstance(value, list):
        return "[" + ", ".join(_inline(v) for v in value) + "]"
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    return repr(value)


# -- scheduler addresses -----------------------------------------------------------------------
ADDRESS_PARTS = st.one_of(
    st.sampled_from(
        ["tcp://", "tls://", "inproc://", "ws://", "", "tcp:/", "TCP://", "[", "]", "::1", ":", "127.0.0.1", "0",
         "65535", "65536", "-1", "host", "a..b", "-x", "x-", "é", " ", "\x00", "/", "%eth0", "1e3", "8786"]
    ),
    st.text(max_size=6),
)  # fmt: skip


@budget(200)
@given(parts=st.lists(ADDRESS_PARTS, max_size=6))
def test_scheduler_addresses_are_checked_before_connecting(parts: list[str]) -> None:
    from fixplan.cluster import check_address
    from fixplan.errors import InputError

    address = "".join(parts)
    try:
        host, port = check_address(address)
    except InputError as exc:
        message = str(exc)
        event("refused")
        assert "\n" not in message and message.isprintable()
        assert message.startswith("check_address.address expects an address like tcp://HOST:8786")
        return
    event("accepted")
    assert address.startswith("tcp://")
    assert 1 <= port <= 65535 and host and host in address
    assert all(c.isprintable() and not c.isspace() for c in address)


@budget(6)
@given(parts=st.lists(ADDRESS_PARTS, min_size=1, max_size=4), command=st.sampled_from(["robust", "solve"]))
def test_a_refused_address_ends_the_command_at_once(parts: list[str], command: str) -> None:
    from fixplan.cluster import check_address
    from fixplan.errors import InputError

    address = "".join(parts)
    try:
        check_address(address)
        accepted = True
    except InputError:
        accepted = False
    assume(not accepted and not address.startswith("-"))  # an accepted one would try to connect
    args = (
        [command, str(PROBLEMS / "naive-order-jams.toml")]
        if command == "robust"
        else ["solve", "--batch", str(PROBLEMS)]
    )
    outcome = run_in_process([*args, "--scheduler", address], timeout_s=20)
    note(repr(outcome))
    assert_contract(outcome)
    assert outcome.code == 2 and "--scheduler" in outcome.stderr
    assert len(outcome.stderr.strip().splitlines()) == 1


# -- values just outside their ranges ---------------------------------------------------------
RANGE_KEYS = [
    ("workpiece.mass", "mass = 2.0", "mass = {v}", limits.MASS),
    ("scene.gravity[0]", "gravity = [0.0, 0.0, -9.81]", "gravity = [{v}, 0.0, -9.81]", limits.GRAVITY),
    ("locator.S1.friction", 'name = "S1"\nposition = [0.04, 0.0, 0.025]\nradius = 0.0\nfriction = 0.25',
     'name = "S1"\nposition = [0.04, 0.0, 0.025]\nradius = 0.0\nfriction = {v}', limits.FRICTION),
    ("workpiece.size[2]", "size = [0.20, 0.10, 0.05]", "size = [0.20, 0.10, {v}]", limits.SIZE),
    ("manipulator.max_force", "max_force = 40.0", "max_force = {v}", limits.MAX_FORCE),
]  # fmt: skip


@st.composite
def just_outside(draw: st.DrawFn, rng: limits.Range) -> float:
    above = draw(st.booleans())
    end = rng.high if above else rng.low
    toward = math.inf if above else -math.inf
    how = draw(st.sampled_from(["ulps", "relative", "absolute"]))
    if how == "ulps":
        v = end
        for _ in range(draw(st.integers(1, 1000))):
            v = math.nextafter(v, toward)
    elif how == "relative":
        v = end + math.copysign(abs(end) * draw(st.floats(1e-16, 1e-2)) or 5e-324, toward)
    else:
        v = end + math.copysign(draw(st.floats(5e-324, 1e-9)), toward)
    assume(not rng.contains(v) and math.isfinite(v))
    return v


@budget(40)
@given(which=st.integers(0, len(RANGE_KEYS) - 1), data=st.data())
def test_values_just_outside_are_quoted_exactly(which: int, data: st.DataObject) -> None:
    key, line, replacement, rng = RANGE_KEYS[which]
    v = data.draw(just_outside(rng))
    assert line in BOX
    text = BOX.replace(line, replacement.format(v=repr(v)), 1)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "f.toml"
        path.write_text(text)
        outcome = run_in_process(["validate", str(path)], timeout_s=20, cwd=Path(tmp))
    note(repr(outcome))
    assert_contract(outcome)
    assert outcome.code == 2
    m = re.search(re.escape(f"{key}: got ") + r"(\S+) \(expected", outcome.stderr)
    assert m, outcome.stderr
    assert float(m.group(1)) == v, (m.group(1), v)  # exactly the value, never the limit


@budget(30)
@given(i=st.integers(0, 5), data=st.data())
def test_wrench_components_just_outside_are_quoted_as_typed(i: int, data: st.DataObject) -> None:
    ranges = limits.wrench_ranges(6)
    v = data.draw(just_outside(ranges[i]))
    parts = ["0"] * 6
    parts[i] = repr(v)
    outcome = run_in_process(["classify", "--wrench", ",".join(parts)], timeout_s=30)
    assert_contract(outcome)
    assert outcome.code == 2 and f"number {i + 1} is {v!r} (expected" in outcome.stderr, outcome.stderr


# -- tiny positive friction -------------------------------------------------------------------
TINY_MU = st.one_of(st.sampled_from([1e-14, 1e-12, 1e-10, 1e-9]), st.floats(1e-300, 1e-6))


@budget(12)
@given(
    mu=TINY_MU, seed=st.integers(0, 2**32 - 1), problem=st.sampled_from(["box-3-2-1", "default-goal", "three-supports"])
)
def test_tiny_friction_gives_the_frictionless_verdict(mu: float, seed: int, problem: str) -> None:
    import fixplan
    from fixplan.jamming import classify
    from fixplan.jamming.programs import force_cone_violation
    from fixplan.locating import contact_set

    if problem == "three-supports":  # frictionless: pushes along the base slide
        from conftest import box_on_three_supports

        zero, tiny, pose = box_on_three_supports(mu=0.0), box_on_three_supports(mu=mu), "start"
    else:
        text, pose = (BOX, "start") if problem == "box-3-2-1" else (fixplan.default_fixture_path().read_text(), "goal")
        zero = fixplan.loads(re.sub(r"friction = [0-9.e+-]+", "friction = 0.0", text))
        tiny = fixplan.loads(re.sub(r"friction = [0-9.e+-]+", f"friction = {mu!r}", text))
    rng = np.random.default_rng(seed)
    W = np.column_stack([rng.uniform(-10, 10, (4, 3)), rng.uniform(-0.5, 0.5, (4, 3))])
    m = tiny.workpiece.mass_kg
    cs = contact_set(tiny, pose, None)
    for r0, r in zip(classify(zero, W, pose=pose), classify(tiny, W, pose=pose), strict=True):
        event(r0.mode)
        weight = m * 9.81 + float(np.abs(r.wrench[:3]).sum())
        assert r.mode == r0.mode, (mu, r.wrench, r.mode, r.certificate, r0.mode)
        assert abs(r.margin - r0.margin) <= 2.0 * mu * weight / math.sqrt(m) + 1e-7
        lam = np.concatenate([r.contact_forces[c.name] for c in cs.contacts])
        assert force_cone_violation(cs, lam) <= 1e-9 * max(1.0, float(np.abs(lam).max()))
