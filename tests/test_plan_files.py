"""Plan files and haptic recordings as input: the format, strict JSON, and claims checked before a replay.

Every file the package writes validates against :mod:`fixplan.plan_schema`; every hostile one is
refused with one line per problem (``FILE: key.path: got ... (expected ...)``, exit 2) or fails
its verification (exit 1) — never "passed" for a claim that is physically false. Each test's
docstring says what the code did before.
"""

from __future__ import annotations

import copy
import json
import re
from pathlib import Path

import numpy as np
import pytest
from conftest import PROBLEMS

import fixplan
from fixplan.errors import InputError
from fixplan.files import parse_strict_json
from fixplan.fixture import fixture_stamp
from fixplan.interactive import record
from fixplan.interactive.record import plan_json, push_disagreement, verify_plan_file, verify_recording
from fixplan.interactive.session import HapticSession
from fixplan.locating import start_state
from fixplan.plan_schema import validate_plan_document
from fixplan.planner.plan import Plan, plan_for_fixture


def strict(obj: dict) -> dict:
    """``obj`` as a file holds it (strict JSON written, read back)."""
    return parse_strict_json(json.dumps(obj, allow_nan=False), "test")  # type: ignore[return-value]


@pytest.fixture(scope="module")
def box(default_fixture):
    return default_fixture


@pytest.fixture(scope="module")
def plan_data(default_plan, box):
    """The default box's plan as ``fixplan solve --out`` writes it (with its fixture's stamp)."""
    return strict(default_plan.plan.with_extras(**fixture_stamp(box.source)).to_json())


@pytest.fixture(scope="module")
def recording(box):
    """A session driven by the planner's executor (no wall clock), recorded like ``haptic --record``."""
    session = HapticSession(box, None, realtime=False, synchronous=True, duration_s=10.0)
    result = session.run()
    assert result.status == "reached", result.reason
    return strict(plan_json(result, box))


def cli(capsys, *args: str) -> tuple[int, list[str], str]:
    """``fixplan ARGS`` in this process: exit status, stderr lines, stdout."""
    from fixplan.cli import main

    capsys.readouterr()
    code = main([str(a) for a in args])
    out = capsys.readouterr()
    return code, [line for line in out.err.splitlines() if line.strip()], out.out


def write(tmp_path: Path, name: str, obj: dict | str | bytes) -> Path:
    path = tmp_path / name
    if isinstance(obj, bytes):
        path.write_bytes(obj)
    else:
        path.write_text(obj if isinstance(obj, str) else json.dumps(obj))
    return path


# -- what the package writes validates -------------------------------------------------------------
def test_every_plan_and_recording_the_package_writes_validates(
    plan_data, recording, default_plan_unverified, jams_plan, box
):
    plate = fixplan.load(PROBLEMS / "naive-order-jams.toml")
    written = [
        (plan_data, box),
        (strict(default_plan_unverified.to_json()), box),
        (strict(jams_plan.to_json()), plate),
        (recording, box),
    ]
    for data, fixture in written:
        assert validate_plan_document(data) == []
        assert validate_plan_document(data, fixture.dimension) == []
        plan = plan_for_fixture(data, fixture, "written")  # and its claims hold for its fixture
        assert plan.to_json() == data  # read back: the same file


def test_a_2d_recording_validates_and_verifies():
    plate = fixplan.load(PROBLEMS / "gen-plate-2d-s2026-000.toml")
    result = HapticSession(plate, None, realtime=False, synchronous=True, duration_s=10.0).run()
    data = strict(plan_json(result, plate))
    assert validate_plan_document(data, 2) == []
    assert push_disagreement(data, plate) is None
    v = verify_recording(plate, data)
    assert v.passed, v.reason


# -- the JSON parser ------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("text", "match"),
    [
        ('{"status": ' + "9" * 4301 + "}", "a number of 4301 characters"),
        ('{"status": "planned", "proven": 1e999}', "1e999 is too large for a float"),
        ('{"status": NaN}', "NaN is not JSON"),
        ('{"a": -Infinity}', "-Infinity is not JSON"),
        ('{"status": "planned", "status": "infeasible"}', "'status' appears twice"),
        ("[" * 50_000 + "]" * 50_000, "nested 50000 deep"),
    ],
)
def test_hostile_json_is_refused_with_one_line(text, match):
    with pytest.raises(InputError, match=match) as info:
        parse_strict_json(text, "p.json")
    assert "\n" not in str(info.value) and str(info.value).startswith("p.json: ")


def test_strict_json_reads_what_json_reads():
    text = '{"a": [1, -2.5e-3, 1e308, 0], "b": {"c": null, "d": "[{not nesting}]"}, "e": true}'
    assert parse_strict_json(text, "x") == json.loads(text)


def test_a_huge_integer_in_a_plan_exits_2_for_verify_and_view(capsys, tmp_path, plan_data, box):
    """Before: 'Exceeds the limit (4300 digits)' was an internal error (exit 3) in verify and view."""
    text = json.dumps(plan_data).replace('"proven": null', '"proven": ' + "1" * 4301)
    path = write(tmp_path, "plan.json", text)
    for args in (("verify", path), ("view", box.source, "--plan", path, "--out", tmp_path / "s.html")):
        code, err, _ = cli(capsys, *args)
        assert code == 2 and len(err) == 1 and "4301" in err[0], err
    assert not (tmp_path / "s.html").exists()


@pytest.mark.parametrize(
    "data",
    [b"\xff\xfe\x00{", b'{"status": "planned", "transitions": []} \xe9', b"x" * (2 << 20)],
    ids=["utf16", "latin1", "huge"],
)
def test_unreadable_plan_files_exit_2_with_one_line(capsys, tmp_path, data):
    code, err, _ = cli(capsys, "verify", write(tmp_path, "p.json", data))
    assert code == 2 and len(err) == 1 and err[0].startswith("fixplan: ") and "p.json" in err[0], err


# -- the format, with key paths -------------------------------------------------------------------
def test_a_recording_without_its_verification_is_refused_with_the_key(capsys, tmp_path, recording):
    """Before: "verification": null gave TypeError, no verification KeyError (exit 3)."""
    null = {**recording, "verification": None}
    missing = {k: v for k, v in recording.items() if k != "verification"}
    for name, data, words in (
        ("null.json", null, "verification: got null (expected an object)"),
        ("missing.json", missing, "verification: missing (expected an object)"),
    ):
        code, err, out = cli(capsys, "verify", write(tmp_path, name, data))
        assert code == 2 and err == [f"{tmp_path / name}: {words}"], err
        assert "passed" not in out


def test_every_bad_value_is_one_line_with_its_key_path(recording, plan_data):
    bad = copy.deepcopy(recording)
    bad["transitions"][2]["pushes"]["wrench"][0][1] = "x"
    bad["transitions"][0]["pushes"]["time_s"] = []
    bad["verification"]["trace"]["poses"][3]["position"][2] = 1e308
    bad["verification"]["trace"]["pressed"][1] = ["B1", None]
    bad["status"] = "great"
    del bad["transitions"][1]["t_start_s"]
    issues = {i.key: i.message for i in validate_plan_document(bad, 3)}
    assert issues == {
        "status": "got 'great' (expected one of: reached, jammed, short, diverged, error)",
        "transitions[0].pushes.time_s": (
            "got a list of 0 (expected a non-empty list of numbers, non-decreasing, each a duration [s] in [0, 1e+06])"
        ),
        "transitions[2].pushes.wrench[0][1]": "got the string 'x' (expected a force component [N] in [-1e+06, 1e+06])",
        "verification.trace.poses[3].position[2]": "got 1e+308 (expected a coordinate [m] in [-1000, 1000])",
        "verification.trace.pressed[1][1]": "got null (expected a locator name)",
    }
    # a missing key of a recording is named once the rest is valid
    fixed = copy.deepcopy(recording)
    del fixed["transitions"][1]["t_start_s"]
    assert [(i.key, i.message) for i in validate_plan_document(fixed, 3)] == [
        ("transitions[1].t_start_s", "missing (expected the recorded t_start_s)")
    ]
    typo = {**plan_data, "transitons": []}
    assert [i.key for i in validate_plan_document(typo, 3)] == ["transitons"]


# -- a recording names its fixture ----------------------------------------------------------------
def test_a_recording_without_its_fixture_is_an_error_not_the_default_box(capsys, tmp_path, recording):
    """Before: it was verified against the bundled box, with a warning, and passed."""
    data = {k: v for k, v in recording.items() if k != "fixture"}
    path = write(tmp_path, "rec.json", data)
    code, err, out = cli(capsys, "verify", path)
    assert code == 2 and out == ""
    assert err == [f"{path}: fixture: missing (expected the path of the fixture the session ran on)"]
    gone = write(tmp_path, "gone.json", {**recording, "fixture": str(tmp_path / "nowhere.toml")})
    code, err, _ = cli(capsys, "verify", gone)
    assert code == 2 and len(err) == 1 and "nowhere.toml" in err[0] and "not there" in err[0]


# -- the pushes the file claims are the ones re-run -----------------------------------------------
def test_zeroed_pushes_fail_and_say_they_contradict_the_trace(recording, box):
    """Before: zeroing every push still gave "passed: the recorded pushes load the part"."""
    assert push_disagreement(recording, box) is None
    zero = copy.deepcopy(recording)
    for tr in zero["transitions"]:
        tr["pushes"]["wrench"] = [[0.0] * box.ndof for _ in tr["pushes"]["wrench"]]
    n = sum(len(tr["pushes"]["time_s"]) for tr in zero["transitions"])
    words = push_disagreement(zero, box)
    assert words is not None and words.startswith("the recorded pushes contradict the session's trace at ")
    v = verify_recording(box, zero)
    assert not v.passed and "evidence" in v.failed_checks and "goal" in v.failed_checks
    # nothing pushes the part: it stays in the state it started in
    assert [tuple(s) for s in v.observed_sequence] == [tuple(sorted(start_state(box)))]
    bad = int(re.search(r"at (\d+) samples", words).group(1))  # type: ignore[union-attr]
    assert 0.9 * n <= bad <= n and words in v.reason


def test_the_replay_runs_the_claimed_pushes_not_the_trace(recording, box):
    """The trace zeroed, the pushes kept: the part is loaded by the pushes, and the file still fails (its evidence disagrees)."""
    data = copy.deepcopy(recording)
    trace = data["verification"]["trace"]
    trace["coupling_wrench"] = [[0.0] * box.ndof for _ in trace["coupling_wrench"]]
    v = verify_recording(box, data)
    assert [tuple(s) for s in v.observed_sequence][-1] == tuple(sorted(loc.name for loc in box.locators))
    assert not v.passed and v.failed_checks == ["evidence"], v.reason


def test_a_recording_without_transitions_cannot_pass(capsys, tmp_path, recording, box):
    """Before: "transitions": [] also passed (the trace's pushes were re-run)."""
    data = {**recording, "transitions": []}
    v = verify_recording(box, data)
    assert not v.passed and v.failed_checks == ["no pushes"]
    code, err, out = cli(capsys, "verify", write(tmp_path, "rec.json", data))
    assert code == 1 and "FAILED" in out and "no transitions" in out and "passed" not in out


def test_pushes_beyond_the_hands_limits_are_refused(recording, box):
    F_max, _, _ = box.hand_limits()
    data = copy.deepcopy(recording)
    data["transitions"][1]["pushes"]["wrench"][2][:3] = [0.0, 0.0, -2.0 * F_max]
    with pytest.raises(InputError, match=r"transitions\[1\]\.pushes\.wrench\[2\]: a push of .* hand's limits"):
        plan_for_fixture(data, box, "rec.json")


# -- a solved plan's claims, before it is replayed ------------------------------------------------
def _names(box) -> list[str]:
    return [loc.name for loc in box.locators]


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        (lambda d, box: d.update(transitions=[]), r"transitions: got 0 \(expected 3, one per step of the sequence\)"),
        (lambda d, box: d.update(transitions=[], sequence=[]), r"sequence\[0\]: got \[\] \(expected the state"),
        (
            lambda d, box: d.update(transitions=[], sequence=[d["sequence"][0]]),
            r"sequence\[0\]: got \{B1, B2, B3\} \(expected every locator",
        ),
        (
            lambda d, box: [p.update(position=[1e308] * 3) for tr in d["transitions"] for p in tr["poses"]],
            r"transitions\[0\]\.poses\[0\]\.position\[0\]: got 1e\+308 \(expected a coordinate",
        ),
        (
            lambda d, box: d["transitions"][1]["poses"][-1].update(position=[900.0, 0.0, 0.0]),
            r"transitions\[1\]\.poses\[\d+\]\.position: 900 m from the start \(expected within",
        ),
        (
            lambda d, box: d["transitions"][2]["poses"][0].update(position=[0.11, 0.05, 0.03]),
            r"transitions\[2\]\.poses\[0\]: .* from where transitions\[1\] ends",
        ),
        (
            lambda d, box: d["transitions"][0].update(added="S1"),
            r"transitions\[0\]: \{B1, B2, B3\} \+ S1 → .*\(expected sequence\[1\]",
        ),
        (lambda d, box: d["transitions"][1].update(added="NOPE"), "another fixture: it names locators NOPE"),
        (
            lambda d, box: d["transitions"][0].update(wrench=[0.0, 0.0, -1e5, 0.0, 0.0, 0.0]),
            r"transitions\[0\]\.wrench: a push of 1e\+05 N, 0 N·m \(expected within the hand's limits",
        ),
        (
            lambda d, box: d["transitions"][0].update(time_s=-1),
            r"transitions\[0\]\.time_s: got -1 \(expected a duration",
        ),
    ],
    ids=[
        "no transitions",
        "no sequence",
        "start only",
        "1e308 poses",
        "far pose",
        "broken knots",
        "wrong added",
        "unknown locator",
        "push beyond limits",
        "negative time",
    ],  # fmt: skip
)
def test_a_plan_the_fixture_rules_out_is_refused_before_a_replay(plan_data, box, edit, match):
    """Before: a plan with no transitions, or with 1e308 knot poses, passed ("every check passed")."""
    data = copy.deepcopy(plan_data)
    edit(data, box)
    with pytest.raises(InputError, match=match):
        plan_for_fixture(data, box, "plan.json")


def test_bogus_plans_exit_2_for_verify_with_one_line(capsys, tmp_path, plan_data):
    empty = write(tmp_path, "empty.json", {**plan_data, "transitions": []})
    code, err, out = cli(capsys, "verify", empty)
    assert (
        code == 2
        and out == ""
        and err == [f"fixplan: {empty}: transitions: got 0 (expected 3, one per step of the sequence)"]
    )
    huge = copy.deepcopy(plan_data)
    for tr in huge["transitions"]:
        for p in tr["poses"]:
            p["position"] = [1e308] * 3
    code, err, out = cli(capsys, "verify", write(tmp_path, "huge.json", huge))
    assert code == 2 and out == "" and all("position" in line and "1e+308" in line for line in err[:-1]), err
    assert err[-1].endswith("more problems not shown") and len(err) == 11


def test_a_replanned_verification_says_so(plan_data, box, monkeypatch):
    """Before: the executor's re-plans were hidden behind "every check passed". A plan whose claims
    hold is verified as solve verifies it (re-planning from states its policy does not cover is the
    executor's last resort), and the reason names the re-plans; bogus claims never reach the run
    (the tests above)."""
    from fixplan.planner import verify as verify_module

    real = verify_module.verify

    def replanning(*args, **kwargs):
        v = real(*args, **kwargs)
        v.execution.counts["replans"] = 2  # as if the executor had planned anew twice on the way
        return v

    monkeypatch.setattr(verify_module, "verify", replanning)
    v = verify_plan_file(box, plan_data, source="plan.json")
    assert v.passed and "replanned" not in v.failed_checks
    assert "the executor re-planned 2 times on the way" in v.reason


def test_a_plan_that_is_all_at_the_start_needs_no_transitions():
    """box-3-2-1 starts located: its plan has no transitions, and that is its true claim."""
    fx = fixplan.load(PROBLEMS / "box-3-2-1.toml")
    result = fixplan.solve(fx, run_verification=False)
    data = strict(result.to_json())
    assert data["transitions"] == [] and start_state(fx) == frozenset(_names(fx))
    plan = plan_for_fixture(data, fx, "p.json")
    assert isinstance(plan, Plan) and plan.sequence == (tuple(sorted(_names(fx))),)


def test_recorded_pushes_are_the_transitions_series(recording):
    times, pushes, ndof = record.recorded_pushes(recording)
    first = recording["transitions"][0]
    assert ndof == 6 and np.all(np.diff(times) >= 0)
    assert times[0] == pytest.approx(first["t_start_s"] + first["pushes"]["time_s"][0])
    np.testing.assert_array_equal(pushes[0], first["pushes"]["wrench"][0])
    assert len(times) == sum(len(tr["pushes"]["time_s"]) for tr in recording["transitions"])


def test_the_docs_describe_every_key_of_the_format():
    """docs/plan-format.md names every key the models declare (a key added to the format is documented)."""
    from conftest import ROOT

    from fixplan import plan_schema

    text = (ROOT / "docs" / "plan-format.md").read_text(encoding="utf-8")
    models = [
        plan_schema.PlanFile, plan_schema.RecordingFile, plan_schema.Transition, plan_schema.Pose,
        plan_schema.Pushes, plan_schema.Tried, plan_schema.PolicyEntry, plan_schema.Verification,
        plan_schema.Execution, plan_schema.Trace, plan_schema.Where, plan_schema.Insertion,
        plan_schema.InsertionPolicy, plan_schema.InsertionPolicyEntry,
    ]  # fmt: skip
    missing = [
        f"{model.__name__}.{field.alias or name}"
        for model in models
        for name, field in model.model_fields.items()
        if f"`{field.alias or name}`" not in text
    ]
    assert missing == []
