"""The command line: JSON contracts, exit codes, and never overwriting a user's file."""

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import PROBLEMS, run_cli

from fixplan.cli import main

fixplan = run_cli


def test_classify_json_contract(tmp_path):
    csv = tmp_path / "w.csv"
    csv.write_text("Fx,Fy,Fz,Tx,Ty,Tz\n0,0,0,0,0,0\n6,0,0,0,0,0\n\n# comment\n0,0,30,0,0,0\n")
    out = json.loads(fixplan("classify", "--wrenches", str(csv), "--json", check_rc=0).stdout)
    assert [r["mode"] for r in out["results"]] == ["held", "slides", "separates"]
    r = out["results"][1]
    assert r["wrench"] == [6, 0, 0, 0, 0, 0]
    assert set(r) >= {"wrench", "mode", "margin", "contact_forces", "certificate", "acceleration", "residuals"}
    assert r["acceleration"][0] == pytest.approx((6 - 0.25 * 2 * 9.81) / 2, rel=1e-8)
    assert set(r["contact_forces"]) == {"B1", "B2", "B3"}
    total = np.sum([f["force_world"] for f in r["contact_forces"].values()], axis=0)
    assert total[2] == pytest.approx(2 * 9.81, rel=1e-8)


def test_search_json_and_exit_codes():
    out = json.loads(fixplan("search", "--motion", "0.1,0,0,0,0,0", "--json", check_rc=0).stdout)
    assert out["found"] and out["check_mode"] == "slides" and out["margin"] > 0
    weak = fixplan(
        "search", str(PROBLEMS / "box-3-2-1.toml"), "--motion", "0,0,0,0,0,5", "--contacts", "B1,B2,B3", "--json"
    )
    assert weak.returncode in (0, 1)


def test_map_writes_png_and_csv_and_refuses_to_overwrite(tmp_path):
    png = tmp_path / "m.png"
    out = json.loads(fixplan("map", "--n", "6", "--out", str(png), "--json", check_rc=0).stdout)
    assert png.stat().st_size > 1000 and png.read_bytes()[:4] == b"\x89PNG"
    rows = png.with_suffix(".csv").read_text().splitlines()
    assert rows[0] == "Fx,Tz,mode,margin" and len(rows) == 37
    assert sum(out["counts"].values()) == 36
    before = png.read_bytes()
    again = fixplan("map", "--n", "6", "--out", str(png))
    assert again.returncode == 2 and "exists" in again.stderr and png.read_bytes() == before


def test_simulate_json_contract(tmp_path):
    traj = tmp_path / "t.csv"
    out = json.loads(
        fixplan(
            "simulate",
            str(PROBLEMS / "box-3-2-1.toml"),
            "--duration",
            "0.2",
            "--wrench",
            "-5,-5,-5,0,0,0",
            "--json",
            "--out",
            str(traj),
            check_rc=0,
        ).stdout
    )
    assert out["steps"] == 200 and out["time"] == pytest.approx(0.2)
    assert set(out["pose"]) == {"position", "quaternion_wxyz"}
    assert set(out["velocity"]) == {"linear", "angular"}
    assert out["max_penetration"] <= 1e-6
    assert {c["name"] for c in out["contacts"]} == {"B1", "B2", "B3", "S1", "S2", "E1"}
    assert all(set(c) == {"name", "gap", "normal_force", "mode"} for c in out["contacts"])
    assert all(c["mode"] != "open" for c in out["contacts"])
    assert len(traj.read_text().splitlines()) == 202


def test_simulate_refuses_contact_only_fixture():
    proc = fixplan("simulate", str(PROBLEMS / "peg-hole-mid.toml"))
    assert (
        proc.returncode == 2 and "no geometry to simulate" in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
    )


def test_goal_needs_full_fixture():
    proc = fixplan("classify", str(PROBLEMS / "box-3-supports.toml"), "--wrench", "0,0,0,0,0,0", "--pose", "goal")
    assert proc.returncode == 2 and "full fixture" in proc.stderr


def test_fclib_cli_converges_and_reports_json(fclib_dir):
    path = next(iter(sorted(fclib_dir.glob("Box_Stacks*.hdf5"))))
    out = json.loads(fixplan("fclib", str(path), "--json", check_rc=0).stdout)
    assert out["converged"] and out["error"] <= 1e-8
    assert len(out["reaction"]) == len(out["velocity"]) == 3 * out["contacts"]
    assert {"error", "iterations", "converged", "time_s", "reaction", "velocity"} <= set(out)


def test_fclib_cli_exit_codes(fclib_dir, tmp_path):
    path = next(iter(sorted(fclib_dir.glob("Capsules*.hdf5"))))
    assert fixplan("fclib", str(path), "--solver", "nsgs", "--max-iter", "5").returncode == 1
    bad = tmp_path / "x.hdf5"
    bad.write_text("not hdf5")
    proc = fixplan("fclib", str(bad))
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1
    proc = fixplan("fclib", str(path), "--solver", "nope")
    assert proc.returncode == 2 and "known solvers" in proc.stderr


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["classify", "--wrench", "1,0,0,0,0,0", "--wrench=2,0,0,0,0,0"], "--wrenches FILE"),
        (["map", "--wrench", "1,0,0,0,0,0", "--axes", "Fx,Tz", "--wrench", "3,0,0,0,0,0"], "expected it once"),
        (["simulate", "--duration", "0.01", "--duration", "0.02"], "--duration is given 2 times ('0.01', '0.02')"),
        (["solve", "--out", "a.json", "--out", "b.json"], "--out is given 2 times"),
    ],
)
def test_a_repeated_option_is_refused_not_dropped(capsys, monkeypatch, tmp_path, args, message):
    # click kept the last --wrench and dropped the others silently
    monkeypatch.chdir(tmp_path)  # where a command that is not refused would write its outputs
    rc = main(args)
    err = capsys.readouterr().err
    assert rc == 2 and message in err and len(err.strip().splitlines()) == 1


def test_repeated_flags_and_values_that_look_like_options_are_not_refused(capsys):
    rc = main(["classify", "--wrench", "0,0,-5,0,0,0", "--json", "--json"])
    assert rc == 0 and json.loads(capsys.readouterr().out)["results"][0]["mode"]


# -- the library names settings and arguments; the CLI prints the user's flags -------------------------
def test_library_errors_name_the_setting_and_the_cli_prints_the_flag(capsys):
    """``RobustSettings.check`` and ``search_wrench`` raise with the setting's or argument's name (an API
    caller sets that); the command line puts the flag the user typed in its place (one table, cli/flags.py)."""
    import fixplan
    from fixplan.cli.flags import FLAGS, with_flags
    from fixplan.errors import InputError
    from fixplan.jamming.search import search_wrench
    from fixplan.robust import RobustSettings

    with pytest.raises(InputError, match=r"^RobustSettings\.mu_spread must be a fraction in \[0, 1\], got 1.5$"):
        RobustSettings(mu_spread=1.5).check()
    fx = fixplan.load(PROBLEMS / "rect-3.toml")
    with pytest.raises(InputError, match=r"^search_wrench\.motion is zero"):
        search_wrench(fx, [0.0, 0.0, 0.0])
    assert all(flag.startswith("--") and not name.startswith("-") for name, flag in FLAGS.items())
    assert with_flags("RobustSettings.latency_s [ms] must be 0 .. 100 ms, got 200.0") == (
        "--latency-ms must be 0 .. 100 ms, got 200.0"
    )
    path = str(PROBLEMS / "naive-order-jams.toml")
    cases = [
        (["robust", path, "--mu-spread", "1.5"], "fixplan: --mu-spread must be a fraction in [0, 1], got 1.5\n"),
        (
            ["search", path, "--motion", "0,0,0"],
            "fixplan: --motion is zero (expected the desired acceleration of the part)\n",
        ),
        (
            ["robust", path, "--scheduler", "localhost:8786"],
            "fixplan: --scheduler expects an address like tcp://HOST:8786",
        ),
        (["solve", path, "--order", "NOPE"], "fixplan: --order names unknown locators: NOPE"),
    ]
    for args, start in cases:
        assert main(args) == 2, args
        err = capsys.readouterr().err
        assert err.strip().splitlines()[-1].startswith(start.strip()), (args, err)
        assert not any(name in err for name in FLAGS), err


def test_result_reasons_name_the_argument_and_the_cli_prints_the_flag(capsys, tmp_path):
    """A result's reason (not an exception) names the argument too: ``solve``'s unverified plan says
    ``solve.run_verification=False``, the search's unreachable default margin ``search_wrench.min_margin_N``;
    the command line prints ``--no-verify`` and ``--min-margin`` there, in its text and its JSON."""
    import fixplan
    from fixplan.jamming.search import search_wrench
    from fixplan.planner.solve import solve

    plate = PROBLEMS / "gen-plate-2d-s2026-000.toml"
    unverified = solve(fixplan.load(plate), run_verification=False)
    assert unverified.status == "unverified" and "(solve.run_verification=False)" in unverified.reason
    assert main(["solve", str(plate), "--no-verify"]) == 1
    out = capsys.readouterr().out
    assert "verification skipped (--no-verify)" in out and "run_verification" not in out
    # rect-3 (1 kg) with a 6 N hand: the default margin m g = 9.81 N is out of reach
    weak = tmp_path / "weak.toml"
    weak.write_text((PROBLEMS / "rect-3.toml").read_text() + "\n[manipulator]\nmax_force = 6.0\nmax_torque = 5.0\n")
    res = search_wrench(fixplan.load(weak), [0.1, 0.0, 0.0], ["B1", "B2"], objective="effort")
    assert res.found and "a smaller search_wrench.min_margin_N asks for a lighter push" in res.reason
    args = ["search", str(weak), "--motion", "0.1,0,0", "--contacts", "B1,B2", "--objective", "effort"]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "a smaller --min-margin asks for a lighter push" in out and "min_margin_N" not in out
    assert main([*args, "--json"]) == 0
    assert "a smaller --min-margin asks" in json.loads(capsys.readouterr().out)["reason"]


def test_no_planner_or_search_text_names_a_flag():
    """The planner's and the search's texts (reasons, notes) name settings and arguments; a flag appears
    only through the CLI (``cli/flags.py``). Every string literal that is not a docstring is read; a
    quoted command line (``'fixplan solve --out'``, where a file comes from) is no flag asked for."""
    import ast
    import importlib
    import re

    root = Path(importlib.import_module("fixplan").__file__).parent
    found = []
    for folder in ("planner", "jamming"):
        for path in sorted((root / folder).rglob("*.py")):
            tree = ast.parse(path.read_text())
            docs = {
                id(node.body[0].value)
                for node in ast.walk(tree)
                if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef)
                and node.body
                and isinstance(node.body[0], ast.Expr)
                and isinstance(node.body[0].value, ast.Constant)
            }
            found += [
                f"{path.relative_to(root)}:{node.lineno}: {node.value!r}"
                for node in ast.walk(tree)
                if isinstance(node, ast.Constant)
                and isinstance(node.value, str)
                and id(node) not in docs
                and re.search(r"(^|[\s(`'])--[a-z]", re.sub(r"'fixplan [a-z-]+ --[a-z-]+'", "", node.value))
            ]
    assert not found, "texts that name a command-line flag:\n" + "\n".join(found)


def test_no_library_error_message_starts_with_a_flag():
    """Outside ``cli/`` an error names the argument or setting, never the command-line flag: every
    ``raise SomeError(...)`` whose message is a literal (or f-string) is read, and none begins with
    ``--`` (the CLI maps names to flags through ``cli/flags.py``)."""
    import ast
    import importlib

    root = Path(importlib.import_module("fixplan").__file__).parent
    found = []
    for path in sorted(root.rglob("*.py")):
        if "cli" in path.relative_to(root).parts:
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if not (isinstance(node, ast.Raise) and isinstance(node.exc, ast.Call) and node.exc.args):
                continue
            first = node.exc.args[0]
            head = first.values[0] if isinstance(first, ast.JoinedStr) and first.values else first
            if isinstance(head, ast.Constant) and isinstance(head.value, str) and head.value.startswith("--"):
                found.append(f"{path.relative_to(root)}:{node.lineno}")
    assert not found, f"library errors that start with a flag: {found}"
