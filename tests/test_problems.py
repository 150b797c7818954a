"""The problem library ``problems/*.toml`` and its hand-derived verdicts ``problems/expected.toml``.

Every expected mode was derived by hand (closed forms, written in each case's ``why``), never by
running fixplan; these tests hold :func:`fixplan.classify` and
:func:`fixplan.jamming.can_wedge` to them. The loading tests only need the fixture loader.
"""

from __future__ import annotations

import itertools
import math
import tomllib
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import PROBLEMS, ROBOT_DATA_MISSING, library, library_params, needs_robot_data, run_cli

import fixplan
from fixplan.locating import locator_gaps

EXPECTED = PROBLEMS / "expected.toml"

MODES = {"held", "jammed", "separates", "rolls", "slides", "pivots", "indeterminate"}
BALANCED = {"held", "jammed"}
REQUIRED = (
    "box-3-2-1.toml",
    "box-3-2-1-soft.toml",
    "box-tilted-start.toml",
    "cylinder-5.toml",
    "rect-3.toml",
    "disk-2d.toml",
    "box-bad-design.toml",
    "box-3-supports.toml",
    "polygon-2d.toml",
)
CASE_KEYS = {"file", "pose", "contacts", "wrench", "mode", "why"}
WEDGE_KEYS = {"file", "wedges", "why"}
TOUCHING_KEYS = {"file", "names"}


def _problem_files() -> list[Path]:
    """Every fixture file of the library (``expected.toml`` holds verdicts, not a fixture)."""
    return sorted(p for p in PROBLEMS.glob("*.toml") if p.name != EXPECTED.name)


def _expected() -> dict[str, Any]:
    if not EXPECTED.is_file():
        return {}
    with EXPECTED.open("rb") as fh:
        return tomllib.load(fh)


def _indexed(kind: str) -> list[tuple[str, dict[str, Any]]]:
    """Entries of one table kind with ids ``file:index`` (index counted per file)."""
    counts: dict[str, int] = {}
    out = []
    for entry in _expected().get(kind, []):
        name = str(entry.get("file", "?"))
        i = counts.get(name, 0)
        counts[name] = i + 1
        out.append((f"{name}:{i}", entry))
    return out


def _load(name: str) -> fixplan.Fixture:
    if needs_robot_data(PROBLEMS / name):
        pytest.skip(str(ROBOT_DATA_MISSING))
    return _loaded(name)


@cache
def _loaded(name: str) -> fixplan.Fixture:
    return fixplan.load(PROBLEMS / name)


# -- the library itself (needs only the loader) ---------------------------------------------------
def test_library_has_the_required_files() -> None:
    names = {p.name for p in _problem_files()}
    assert len(names) >= 11, sorted(names)
    missing = [n for n in REQUIRED if n not in names]
    assert not missing, f"missing problem files: {missing}"
    assert len([n for n in names if n.startswith("peg-hole-")]) >= 3
    assert {"box-on-incline.toml", "box-3-supports.toml"} & names
    assert EXPECTED.is_file()


@pytest.mark.parametrize("path", library_params(), ids=lambda p: p.name)
def test_problem_loads(path: Path) -> None:
    fixture = fixplan.load(path)
    lines = path.read_text(encoding="utf-8").splitlines()
    header = list(itertools.takewhile(lambda ln: ln.startswith("#"), lines))
    assert len(header) >= 3, f"{path.name}: start with a comment block saying what it shows"
    assert fixture.names, "no contacts"
    if fixture.is_full:
        assert fixture.goal is not None  # the located pose exists


def test_validate_cli_accepts_every_problem() -> None:
    """``fixplan validate problems/*.toml`` (the verdict table included) exits 0 and flags the bad design.

    Without example-robot-data the fixtures that name its robots are left out (they say so, exit 2),
    and the verdict table says how many of its entries it did not check."""
    files = [str(p) for p in [*library(), EXPECTED]]
    proc = run_cli("validate", *files, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    lines = {line.split(":")[0]: line for line in proc.stdout.splitlines()}
    warnings = {line.split(":")[0]: line for line in proc.stderr.splitlines()}
    bad_design = str(PROBLEMS / "box-bad-design.toml")
    # the warning is a line of its own (FILE: key: warning: ...), not hidden inside the ok line
    assert lines[bad_design].startswith(f"{bad_design}: ok (")
    assert warnings[bad_design] == (
        f"{bad_design}: locator: warning: the locators do not determine the pose (rank G = 5 < 6): "
        "the part can move while touching every locator"
    )
    assert "warning" not in lines[str(PROBLEMS / "box-3-2-1.toml")]
    assert set(warnings) == {bad_design}, proc.stderr
    assert "expected verdicts" in lines[str(EXPECTED)]


def test_validate_rejects_a_broken_verdict_table(tmp_path: Path) -> None:
    bad = tmp_path / "expected.toml"
    bad.write_text(
        f'[[case]]\nfile = "{PROBLEMS / "box-3-2-1.toml"}"\nwrench = [1.0, 2.0]\nmode = "flies"\nwhy = "x"\n'
    )
    proc = run_cli("validate", bad, timeout=None)
    assert proc.returncode == 2
    assert f"{bad}: case[0].wrench: got 2 numbers (expected 6 for a 3D scene)" in proc.stderr
    assert f"{bad}: case[0].mode: got 'flies'" in proc.stderr


def test_expected_names_existing_files_and_is_well_formed() -> None:
    data = _expected()
    assert data, f"{EXPECTED} is missing or empty"
    assert set(data) <= {"case", "wedge", "touching", "plan", "clamp"}, sorted(data)
    cases = data.get("case", [])
    assert len(cases) >= 40
    existing = {p.name for p in _problem_files()}
    per_file: dict[str, int] = {}
    for i, case in enumerate(cases):
        where = f"case[{i}] ({case.get('file')})"
        assert set(case) <= CASE_KEYS, f"{where}: unknown keys {set(case) - CASE_KEYS}"
        assert case["file"] in existing, f"{where}: no such problem file"
        per_file[case["file"]] = per_file.get(case["file"], 0) + 1
        assert case["mode"] in MODES, where
        assert isinstance(case.get("why"), str) and len(case["why"]) > 20, f"{where}: derive it in 'why'"
        fixture = _load(case["file"])
        wrench = case["wrench"]
        assert len(wrench) == fixture.ndof, f"{where}: wrench needs {fixture.ndof} numbers"
        assert all(math.isfinite(float(x)) for x in wrench), where
        pose = case.get("pose", "start")
        assert pose in ("start", "goal"), where
        if pose == "goal":
            assert fixture.is_full, f"{where}: 'goal' needs a full fixture"
        for name in case.get("contacts", []):
            assert name in fixture.names, f"{where}: unknown contact {name!r}"
    for name in existing:
        assert per_file.get(name, 0) >= 3, f"{name}: needs at least 3 cases"
    for entry in data.get("wedge", []):
        assert set(entry) <= WEDGE_KEYS and entry["file"] in existing, entry
        assert isinstance(entry["wedges"], bool), entry
    for entry in data.get("touching", []):
        assert set(entry) <= TOUCHING_KEYS and entry["file"] in existing, entry


@pytest.mark.parametrize(("cid", "entry"), _indexed("touching"), ids=[i for i, _ in _indexed("touching")])
def test_locators_touching_at_start(cid: str, entry: dict[str, Any]) -> None:
    fixture = _load(entry["file"])
    gaps = locator_gaps(fixture.workpiece, fixture.start, fixture.locators)
    touching = [loc.name for loc, gap in zip(fixture.locators, gaps, strict=True) if gap <= fixture.tolerances.touch_m]
    assert touching == list(entry["names"]), dict(zip([loc.name for loc in fixture.locators], gaps, strict=True))


# -- verdicts (need fixplan.classify / fixplan.jamming.can_wedge) ---------------------------------
@pytest.mark.parametrize(("cid", "case"), _indexed("case"), ids=[i for i, _ in _indexed("case")])
def test_expected_verdict(cid: str, case: dict[str, Any]) -> None:
    fixture = _load(case["file"])
    wrench = np.array(case["wrench"], dtype=float)
    results = fixplan.classify(fixture, [wrench], contacts=case.get("contacts"), pose=case.get("pose", "start"))
    assert len(results) == 1
    result = results[0]
    assert result.mode == case["mode"], f"{cid}: got {result.mode!r}, expected {case['mode']!r} -- {case['why']}"
    assert result.margin >= 0.0
    if case["mode"] in BALANCED:
        assert result.margin <= 1e-6 * max(1.0, float(np.linalg.norm(wrench))), result.margin
    else:
        assert result.margin > 0.0
    assert isinstance(result.contact_forces, dict)


@pytest.mark.parametrize(("cid", "entry"), _indexed("wedge"), ids=[i for i, _ in _indexed("wedge")])
def test_expected_wedging(cid: str, entry: dict[str, Any]) -> None:
    from fixplan.jamming import can_wedge

    contact_set = fixplan.contact_set(_load(entry["file"]))
    assert bool(can_wedge(contact_set)) is entry["wedges"], entry["why"]
