"""``fixplan verify PLAN`` and ``fixplan map`` on fixtures with pins and bores.

verify re-runs the staged insertion a plan file holds (fixplan/planner/insertion_file.py) and must
end where ``solve``'s own verification ended; a plan whose fixture changed, or whose claims the
fixture rules out, is refused in one line (exit 2); a physically false push fails the run (exit 1).
map classifies the contacts classify does, pins' included: cell by cell the same verdicts.
"""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import pytest
from conftest import PROBLEMS

import fixplan
from fixplan.cli import main
from fixplan.errors import InputError
from fixplan.interactive.record import verify_recording
from fixplan.plan_schema import validate_plan_document
from fixplan.planner.plan import plan_for_fixture

HOUSING = PROBLEMS / "housing-2-pins.toml"  # starts located: the plan holds it with the seating push
LOAD = PROBLEMS / "housing-2-pins-load.toml"  # from above: approach, P1, P2, seat
SHAFT = PROBLEMS / "shaft-into-bore.toml"  # a shaft tilted in a bore's chamfer: approach, B1, B1.bottom


def _run(capsys, *args: object) -> tuple[int, str, str]:
    capsys.readouterr()
    rc = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return rc, out, err


def _solved(capsys, tmp_path: Path, source: Path, *options: str) -> tuple[Path, Path, dict]:
    """A copy of ``source`` in its own folder and the plan ``solve --out`` writes for it (and its JSON)."""
    fixture = tmp_path / "fx" / source.name
    fixture.parent.mkdir(exist_ok=True)
    shutil.copyfile(source, fixture)
    plan = tmp_path / f"{source.stem}.json"
    rc, _, err = _run(capsys, "solve", fixture, "--out", plan, *options)
    assert rc == (1 if "--no-verify" in options else 0), err
    return fixture, plan, json.loads(plan.read_text())


@pytest.mark.parametrize(
    ("source", "observed", "offsets"),
    [
        (HOUSING, [["B1", "B2", "B3", "P1", "P2"]], {"P1.axis_offset": 1e-4}),
        (LOAD, [["P1"], ["P1", "P2"], ["B1", "B2", "B3", "P1", "P2"]], {"P1.axis_offset": 1e-4}),
        (SHAFT, [["B1"], ["B1", "B1.bottom"]], {}),
    ],
)
def test_verify_reruns_the_plan_and_ends_where_solve_did(capsys, tmp_path, source, observed, offsets):
    """verify PLAN passes (exit 0) with solve's final gaps to 1e-9 m and its observed states.

    The housing is seated toward +x against P1: H1's axis ends the radial play (D − d)/2 = 0.1 mm
    from P1's; the rests (and the shaft's bore bottom) end closed.
    """
    fixture, plan, data = _solved(capsys, tmp_path, source)
    solved = data["verification"]
    assert data["status"] == "planned" and solved["passed"]
    # the policy (what the run does from every state, how it recovers) with every plan that inserts;
    # a part that starts located is only held: no policy
    policy = {"policy"} if source != HOUSING else set()
    assert set(data["insertion"]) == {"axis", "goal", "stages", "seat_wrench"} | policy
    # the file follows the format and reads back as the same file (it did not: B1.bottom, P1.axis_offset)
    assert validate_plan_document(data, 3) == []
    assert plan_for_fixture(data, fixplan.load(fixture), "p.json").to_json() == data
    rc, out, err = _run(capsys, "verify", plan, "--json")
    assert rc == 0, err
    doc = json.loads(out)
    assert doc["passed"] is True and doc["failed_checks"] == [] and "trace" not in doc
    assert doc["observed_sequence"] == observed == solved["observed_sequence"]
    assert set(doc["final_gaps"]) == set(solved["final_gaps"])
    for name, gap in solved["final_gaps"].items():
        assert doc["final_gaps"][name] == pytest.approx(gap, abs=1e-9), name
    for name, gap in doc["final_gaps"].items():
        if name.endswith(".axis_offset"):
            assert gap == pytest.approx(offsets.get(name, 0.0), abs=3e-5), name
        else:  # a rest or the bore's bottom: closed
            assert abs(gap) <= 1e-6, name
    # the human output: the same status line as a plan of locators
    rc, out, _ = _run(capsys, "verify", plan)
    assert rc == 0 and out.startswith(f"{plan}: passed (plan re-run in the loop") and "not supported" not in out


def test_a_plan_whose_fixture_was_edited_is_refused_in_one_line(capsys, tmp_path):
    fixture, plan, _ = _solved(capsys, tmp_path, LOAD, "--no-verify")
    fixture.write_text(fixture.read_text().replace("mass = 2.0", "mass = 2.5"))
    rc, out, err = _run(capsys, "verify", plan)
    assert rc == 2 and out == "" and len(err.strip().splitlines()) == 1, err
    assert "changed since the plan was made" in err and "Traceback" not in err and "not supported" not in err


def _tamper(data: dict, key: str) -> dict:
    data = json.loads(json.dumps(data))
    if key == "no insertion":
        del data["insertion"]
    elif key == "axis":
        data["insertion"]["axis"] = [1.0, 0.0, 0.0]
    elif key == "stages":
        data["insertion"]["stages"] = ["free", "insert", "seat", "seat"]
    elif key == "seat beyond the hand":
        data["insertion"]["seat_wrench"] = [0.0, 0.0, -1e5, 0.0, 0.0, 0.0]
    elif key == "sequence":
        data["sequence"][-1] = ["B1", "B2", "B3", "P1"]
    elif key == "approach":
        data["transitions"][0]["added"] = "P2"
    elif key == "a pin it lacks":
        data["sequence"][2] = ["P7"]
    elif key == "no guide":
        data["transitions"][0]["poses"] = data["transitions"][0]["poses"][:1]
    elif key == "no push":
        data["transitions"][2]["wrench"] = None
    return data


@pytest.mark.parametrize(
    ("key", "words"),
    [
        ("no insertion", "insertion: missing (expected the staged insertion"),
        ("axis", "the plan is for another fixture: its insertion axis (1, 0, 0) is 90°"),
        ("stages", "insertion.stages: got ['free', 'insert', 'seat', 'seat'] (expected ['free', 'insert', 'insert', 'seat']"),
        ("seat beyond the hand", "insertion.seat_wrench: a push of 1e+05 N"),
        ("sequence", "sequence[4]: got {B1, B2, B3, P1} (expected every pin engaged and every rest pressed"),
        ("approach", "transitions[0]: the approach (insertion.stages[0]: free): got P2"),
        ("a pin it lacks", "it names locators P7 that"),
        ("no guide", "transitions[0].poses: got 1 (expected the guide's poses, at least its start and end)"),
        ("no push", "transitions[2].wrench: got null (expected the stage's planned push"),
    ],
)  # fmt: skip
def test_a_plan_the_fixture_rules_out_is_refused_before_the_run(capsys, tmp_path, key, words):
    _, plan, data = _solved(capsys, tmp_path, LOAD, "--no-verify")
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(_tamper(data, key)))
    rc, out, err = _run(capsys, "verify", bad)
    assert rc == 2 and out == "", err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and words in lines[0] and "Traceback" not in err, err


def test_a_seating_push_that_does_not_hold_fails_the_run(capsys, tmp_path):
    """The housing starts located: the run only holds it with the file's seating push.

    The file's pushes m g down (with 0.3 m g toward P1): turned up, the hand lifts the part off
    its rests and the run fails (exit 1) — verify runs the file's push, not one it plans anew.
    """
    _, plan, data = _solved(capsys, tmp_path, HOUSING, "--no-verify")
    seat = data["insertion"]["seat_wrench"]
    assert seat[0] == pytest.approx(0.3 * 2.0 * 9.81, rel=1e-12) and seat[2] == pytest.approx(-2.0 * 9.81, rel=1e-12)
    data["insertion"]["seat_wrench"] = [0.0, 0.0, 2.0 * 9.81, 0.0, 0.0, 0.0]
    bad = tmp_path / "zero-seat.json"
    bad.write_text(json.dumps(data))
    rc, out, err = _run(capsys, "verify", bad, "--json")
    assert rc == 1, err
    doc = json.loads(out)
    assert doc["passed"] is False and "executor" in doc["failed_checks"]


def test_a_recording_on_a_fixture_with_pins_is_refused_in_one_line():
    """Its replay's goal (every locator pressed) says nothing of the pins; a bore has no locator at all."""
    with pytest.raises(InputError) as exc:
        verify_recording(fixplan.load(SHAFT), {"source": "haptic session"}, source="rec.json")
    assert "rec.json: a recording on a fixture with pins or bores" in str(exc.value) and "\n" not in str(exc.value)


# -- map ---------------------------------------------------------------------------------------------
def _map_and_classify(capsys, tmp_path: Path, fixture: Path, axes: str, rng: str, n: int, *extra: str):
    """The map's verdict per cell (its CSV) and classify's for the same wrenches."""
    png = tmp_path / "map.png"
    rc, out, err = _run(
        capsys, "map", fixture, "--axes", axes, "--range", rng, "--n", n, "--out", png, "--force", "--json", *extra
    )
    assert rc == 0, err
    rows = list(csv.DictReader(png.with_suffix(".csv").open()))
    assert len(rows) == n * n
    names = ("Fx", "Fy", "Fz", "Tx", "Ty", "Tz")
    wrenches = tmp_path / "wrenches.csv"
    with wrenches.open("w") as fh:
        for r in rows:
            w = [0.0] * 6
            for a in axes.split(","):
                w[names.index(a)] = float(r[a])
            fh.write(",".join(repr(x) for x in w) + "\n")
    rc, out, err = _run(capsys, "classify", fixture, "--wrenches", wrenches, "--json", *extra)
    assert rc == 0, err
    doc = json.loads(out)
    return [r["mode"] for r in rows], [r["mode"] for r in doc["results"]], doc["contacts"], rows


def test_map_on_the_housing_gives_classify_s_verdict_in_every_cell(capsys, tmp_path):
    """A 4 × 4 grid of Fx ∈ [−30, 30] N, Fz ∈ [−40, 10] N at the located pose.

    Pushed toward +x the part is held by P1's wall (its contacts' normals are −x): on the rests
    alone those cells slide. Toward −x it leaves P1 (0.2 mm of play that way) or, pressed down
    hard enough, jams on the rests' friction.
    """
    mapped, classified, contacts, rows = _map_and_classify(capsys, tmp_path, HOUSING, "Fx,Fz", "-30:30,-40:10", 4)
    assert contacts == ["B1", "B2", "B3", "P1", "P1#2"]
    assert mapped == classified
    assert {"held", "jammed", "separates"} <= set(mapped)
    assert [m == "held" for m in mapped] == [float(r["Fx"]) > 0.0 for r in rows]
    rests, _, _, _ = _map_and_classify(capsys, tmp_path, HOUSING, "Fx,Fz", "-30:30,-40:10", 4, "--contacts", "B1,B2,B3")
    assert "held" not in rests  # without the pin's contacts the map would not be classify's


def test_map_on_a_shaft_in_its_bore_gives_classify_s_verdict_in_every_cell(capsys, tmp_path):
    """No locator at all: the cocked shaft's only contacts are its bore's."""
    mapped, classified, contacts, _ = _map_and_classify(
        capsys, tmp_path, PROBLEMS / "shaft-in-bore.toml", "Fx,Ty", "-2:2,-0.05:0.05", 3
    )
    assert contacts and all(c.startswith("B1") for c in contacts)
    assert mapped == classified and len(set(mapped)) >= 2


def test_view_replays_a_pin_plan_s_trace(capsys, tmp_path):
    """The trace has a column per locator, pin and bore; the scene draws the locators' (it failed on the pins')."""
    fixture, plan, data = _solved(capsys, tmp_path, HOUSING)
    assert data["verification"]["trace"]["names"] == ["B1", "B2", "B3", "P1", "P2"]
    rc, out, err = _run(
        capsys, "view", fixture, "--plan", plan, "--out", tmp_path / "scene.html", "--frames", 5, "--json"
    )
    assert rc == 0, err
    doc = json.loads(out)
    assert (
        doc["source"] == "trace"
        and doc["frames"] == 5
        and doc["samples"] == len(data["verification"]["trace"]["time_s"])
    )
