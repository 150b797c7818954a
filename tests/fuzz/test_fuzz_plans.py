"""Mutated plan files and haptic recordings: ``fixplan verify`` and ``fixplan view --plan`` keep the contract.

The seeds are a plan of the default box (``solve``, verified) and a recording of a session the
planner's executor drove (``haptic --record``'s format). A mutation changes one to three places
(a place is reached by descending from the top at random, so every level is hit): drop a key,
null a value, a 4,301-digit integer or ``NaN`` written into the text, 1e308, an empty list, a
value of another type, a locator name the fixture lacks; or a claim that is physically false:
every push zeroed, no transitions, no sequence, knot poses at 1e308. Besides
``harness.assert_contract`` (exit 0, 1 or 2, no traceback, strict ``--json``, exit 2 explained on
stderr): every line of an exit 2 names the plan file, and a false claim never gives "passed".
"""

from __future__ import annotations

import copy
import json
import tempfile
from pathlib import Path
from typing import Any

import pytest
from harness import assert_contract, budget, run_in_process, snapshot
from hypothesis import event, given, note
from hypothesis import strategies as st

import fixplan

HUGE = "__HUGE_INT__"  # written as a 4,301-digit integer (json.dumps cannot write one)
NAN = "__NAN__"  # written as the NaN token
ODD = [None, "x", "", "NOPE", True, 0, -1, 1e308, -1e308, 5e-324, [], {}, [None], ["NOPE"], [1e308] * 3, HUGE, NAN]
FALSE_CLAIMS = ("zero pushes", "no transitions", "no sequence", "far poses")


@pytest.fixture(scope="module")
def seeds() -> dict[str, dict[str, Any]]:
    from fixplan.fixture import fixture_stamp
    from fixplan.interactive.record import plan_json
    from fixplan.interactive.session import HapticSession

    box = fixplan.load(fixplan.default_fixture_path())
    plan = fixplan.solve(box).plan.with_extras(**fixture_stamp(box.source)).to_json()
    session = HapticSession(box, None, realtime=False, synchronous=True, duration_s=10.0).run()
    recording = plan_json(session, box)
    return {k: json.loads(json.dumps(v)) for k, v in (("plan", plan), ("recording", recording))}


@st.composite
def place(draw: st.DrawFn, doc: Any) -> tuple:
    """A path into ``doc`` (keys and indices), descending at random: shallow places as likely as deep ones."""
    path: tuple = ()
    node = doc
    while isinstance(node, dict | list) and node:
        keys = list(node) if isinstance(node, dict) else list(range(len(node)))
        key = draw(st.sampled_from(keys))
        path, node = (*path, key), node[key]
        if draw(st.integers(0, 3)) == 0:
            break
    return path


def _set(doc: Any, path: tuple, value: Any) -> None:
    parent = doc
    for p in path[:-1]:
        parent = parent[p]
    parent[path[-1]] = value


def _drop(doc: Any, path: tuple) -> None:
    parent = doc
    for p in path[:-1]:
        parent = parent[p]
    del parent[path[-1]]


def false_claim(doc: dict[str, Any], kind: str) -> None:
    """Make the file claim what did not happen (the fixture or physics rules it out)."""
    if kind == "zero pushes":
        for tr in doc["transitions"]:
            if "pushes" in tr:
                tr["pushes"]["wrench"] = [[0.0] * len(w) for w in tr["pushes"]["wrench"]]
            if tr.get("wrench") is not None:
                tr["wrench"] = [0.0] * len(tr["wrench"])
        if doc.get("source") != "haptic session":  # a solved plan's pushes are re-solved: drop its knots instead
            for tr in doc["transitions"]:
                tr["poses"] = []
            doc["transitions"] = doc["transitions"][:1]
    elif kind == "no transitions":
        doc["transitions"] = []
    elif kind == "no sequence":
        doc["sequence"] = []
        doc["transitions"] = []
    elif kind == "far poses":
        for tr in doc["transitions"]:
            for p in tr.get("poses", []):
                p["position"] = [1e308] * len(p["position"])


@st.composite
def mutated(draw: st.DrawFn, seeds: dict[str, dict[str, Any]]) -> tuple[str, str, str]:
    """(which seed, the file's text, the kind of mutation)."""
    which = draw(st.sampled_from(sorted(seeds)))
    doc = copy.deepcopy(seeds[which])
    kind = draw(st.sampled_from(["values", "values", "values", *FALSE_CLAIMS]))
    if kind == "values":
        for _ in range(draw(st.integers(1, 3))):
            path = draw(place(doc))
            if not path:
                continue
            if draw(st.integers(0, 3)) == 0:
                _drop(doc, path)
            else:
                _set(doc, path, draw(st.sampled_from(ODD)))
    else:
        false_claim(doc, kind)
    text = json.dumps(doc).replace(json.dumps(HUGE), "7" * 4301).replace(json.dumps(NAN), "NaN")
    return which, text, kind


def _check(outcome: Any, before: dict[Path, bytes], path: Path, kind: str) -> None:
    note(repr(outcome))
    event(f"{outcome.args[0]} {kind}: exit {outcome.code}")
    assert_contract(outcome, before)
    if outcome.code == 2:
        for line in outcome.stderr.splitlines():
            assert str(path) in line, f"a line that does not name the plan file: {line!r}"
    if kind in FALSE_CLAIMS:
        assert outcome.code != 0, f"{kind}: exit 0 for a physically false claim"
        assert "passed" not in outcome.stdout.replace('"passed": false', ""), f"{kind}: passed"


@budget(12)
@given(data=st.data(), json_out=st.booleans())
def test_verify_mutated_plans_and_recordings(seeds, data: st.DataObject, json_out: bool) -> None:
    which, text, kind = data.draw(mutated(seeds))
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        path = folder / f"{which}.json"
        path.write_text(text)
        before = snapshot(folder)
        outcome = run_in_process(["verify", str(path), *(["--json"] if json_out else [])], timeout_s=120, cwd=folder)
        _check(outcome, before, path, kind)


@budget(8)
@given(data=st.data())
def test_view_mutated_plans_and_recordings(seeds, data: st.DataObject) -> None:
    which, text, kind = data.draw(mutated(seeds))
    kind = "values" if kind == "zero pushes" else kind  # view draws what the file says, it judges nothing
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        path = folder / f"{which}.json"
        path.write_text(text)
        before = snapshot(folder)
        args = ["view", str(fixplan.default_fixture_path()), "--plan", str(path), "--out", str(folder / "s.html")]
        outcome = run_in_process([*args, "--frames", "2", "--json"], timeout_s=120, cwd=folder)
        note(repr(outcome))
        event(f"view {kind}: exit {outcome.code}")
        assert_contract(outcome, before)
        if outcome.code == 2:
            for line in outcome.stderr.splitlines():
                assert str(path) in line, f"a line that does not name the plan file: {line!r}"
        if kind in FALSE_CLAIMS and which == "plan":  # a recording's claims are judged by verify's re-run
            assert outcome.code == 2, f"{kind}: a plan the fixture rules out was drawn"
