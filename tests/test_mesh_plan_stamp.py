"""A plan's ``fixture_sha256`` covers a mesh part's file: a plan made on one mesh is not replayed on an edited one.

The digest of a mesh fixture is the SHA-256 of the fixture's bytes followed by the mesh file's
(``cat fixture.toml part.stl | sha256sum``); a primitive fixture's is that of its bytes alone, as
before, so every plan already written still verifies.
"""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import pytest
from conftest import PROBLEMS, run_cli

from fixplan.errors import InputError
from fixplan.fixture import fixture_of_plan, fixture_sha256, fixture_stamp


def mesh_fixture(tmp_path: Path) -> tuple[Path, Path]:
    """A copy of ``problems/meshes/l-bracket.toml`` and its STL in ``tmp_path``."""
    for name in ("l-bracket.toml", "l-bracket.stl"):
        shutil.copy(PROBLEMS / "meshes" / name, tmp_path / name)
    return tmp_path / "l-bracket.toml", tmp_path / "l-bracket.stl"


def test_the_digest_is_the_fixture_bytes_then_the_mesh_bytes(tmp_path: Path) -> None:
    fixture, stl = mesh_fixture(tmp_path)
    stamp = fixture_stamp(fixture)
    assert stamp["fixture_sha256"] == hashlib.sha256(fixture.read_bytes() + stl.read_bytes()).hexdigest()
    assert fixture_sha256(fixture) == (stamp["fixture_sha256"], "l-bracket.stl")
    box = PROBLEMS / "box-3-2-1.toml"
    assert fixture_stamp(box)["fixture_sha256"] == hashlib.sha256(box.read_bytes()).hexdigest()  # unchanged


def test_an_edited_or_missing_mesh_refuses_the_plan_in_one_line(tmp_path: Path) -> None:
    fixture, stl = mesh_fixture(tmp_path)
    plan = tmp_path / "plan.json"
    data = fixture_stamp(fixture)
    assert fixture_of_plan(data, plan, None) == (fixture, None)
    original = stl.read_bytes()
    stl.write_bytes(original[:-50] + original[-50:-2] + b"\x01\x00")  # one attribute word of one triangle
    with pytest.raises(InputError, match=r"or its mesh file 'l-bracket.stl' changed since the plan was made") as exc:
        fixture_of_plan(data, plan, None)
    assert "\n" not in str(exc.value)
    # with --fixture: a warning, and the file as it is now
    path, note = fixture_of_plan(data, plan, fixture)
    assert path == fixture and note is not None and "changed since the plan was made" in note
    stl.unlink()
    with pytest.raises(InputError, match="changed since the plan was made"):
        fixture_of_plan(data, plan, None)
    stl.write_bytes(original)
    assert fixture_of_plan(data, plan, None) == (fixture, None)


def test_verify_refuses_a_plan_whose_mesh_was_edited(tmp_path: Path) -> None:
    fixture, stl = mesh_fixture(tmp_path)
    plan = tmp_path / "plan.json"
    plan.write_text(json.dumps({**fixture_stamp(fixture), "status": "planned"}))
    before = run_cli("verify", str(plan))
    assert "changed since the plan was made" not in before.stderr
    stl.write_bytes(stl.read_bytes() + b"\0")  # a trailing byte: the same triangles, another file
    after = run_cli("verify", str(plan), check_rc=2)
    lines = after.stderr.strip().splitlines()
    assert len(lines) == 1 and "or its mesh file 'l-bracket.stl' changed since the plan was made" in lines[0]
    assert "Traceback" not in after.stderr
