"""A plan file names its fixture (path and SHA-256 of the bytes), so that ``fixplan verify PLAN`` finds it later.

Once, a plan written by ``solve --out`` was verified against the bundled box ("the plan is
for another fixture") because it did not name its fixture.
"""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import pytest
from conftest import PROBLEMS

from fixplan.cli import main

SOURCE = PROBLEMS / "gen-plate-2d-s2026-000.toml"  # 2D, two transitions: solved and re-run in seconds


def _run(capsys, *args: str) -> tuple[int, str, str]:
    capsys.readouterr()
    rc = main([*map(str, args)])
    out, err = capsys.readouterr()
    return rc, out, err


@pytest.fixture
def solved(tmp_path, capsys) -> tuple[Path, Path]:
    """A copy of the fixture in its own folder, and the plan solved for it (``--no-verify``)."""
    fixture = tmp_path / "fx" / "plate.toml"
    fixture.parent.mkdir()
    shutil.copyfile(SOURCE, fixture)
    plan = tmp_path / "plan.json"
    rc, _, err = _run(capsys, "solve", fixture, "--no-verify", "--out", plan)
    assert rc == 1, err  # unverified
    return fixture, plan


def test_the_plan_names_its_fixture_by_resolved_path_and_content_hash(solved):
    fixture, plan = solved
    data = json.loads(plan.read_text())
    assert list(data)[:2] == ["fixture", "fixture_sha256"]
    assert data["fixture"] == str(fixture.resolve())
    assert data["fixture_sha256"] == hashlib.sha256(fixture.read_bytes()).hexdigest()


def test_verify_finds_the_named_fixture_from_any_folder(solved, capsys, monkeypatch, tmp_path):
    _, plan = solved
    monkeypatch.chdir(tmp_path / "fx")
    rc, out, err = _run(capsys, "verify", plan)
    assert rc == 0, err
    assert "passed" in out and "{B1, B2, S}" in out  # the plate's locators, not the box's


def test_an_edited_fixture_is_refused_with_the_way_on(solved, capsys):
    fixture, plan = solved
    fixture.write_text(fixture.read_text() + "# edited\n")
    rc, out, err = _run(capsys, "verify", plan)
    assert rc == 2 and out == ""
    assert len(err.strip().splitlines()) == 1
    assert "changed since the plan was made" in err and "--fixture" in err and "fixplan solve" in err
    # told to go on with the file as it is now, verify warns and runs (a comment changes no physics)
    rc, out, err = _run(capsys, "verify", plan, "--fixture", fixture)
    assert rc == 0 and "warning:" in err and "changed since the plan was made" in err


def test_a_moved_fixture_is_refused_and_found_with_fixture(solved, capsys):
    fixture, plan = solved
    moved = fixture.with_name("moved.toml")
    fixture.rename(moved)
    rc, _, err = _run(capsys, "verify", plan)
    assert rc == 2 and "which is not there" in err and "--fixture" in err
    rc, _, err = _run(capsys, "verify", plan, "--fixture", moved)
    assert rc == 0 and "warning" not in err  # the same bytes under another name


def test_a_relative_name_is_read_beside_the_plan(solved, capsys, monkeypatch, tmp_path):
    _, plan = solved
    data = json.loads(plan.read_text())
    data["fixture"] = "fx/plate.toml"  # relative to the plan's folder, as a recorded session may write it
    plan.write_text(json.dumps(data))
    monkeypatch.chdir(PROBLEMS)
    rc, _, err = _run(capsys, "verify", plan)
    assert rc == 0, err


def test_a_plan_naming_no_fixture_suggests_fixture(solved, capsys):
    _, plan = solved
    data = json.loads(plan.read_text())
    del data["fixture"], data["fixture_sha256"]
    plan.write_text(json.dumps(data))
    rc, _, err = _run(capsys, "verify", plan)
    assert rc == 2 and len(err.strip().splitlines()) == 1
    assert "another fixture" in err and "--fixture FILE" in err


@pytest.mark.parametrize(
    ("key", "value", "expected"),
    [("fixture_sha256", "abc", "64 lowercase hex digits"), ("fixture", 3, "expected the fixture file's path")],
)
def test_malformed_fixture_keys_are_one_line_errors(solved, capsys, key, value, expected):
    _, plan = solved
    data = json.loads(plan.read_text())
    data[key] = value
    plan.write_text(json.dumps(data))
    rc, _, err = _run(capsys, "verify", plan)
    assert rc == 2 and expected in err and len(err.strip().splitlines()) == 1
