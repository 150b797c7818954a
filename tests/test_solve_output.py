"""What ``fixplan solve`` prints and reports (papercuts a new user met).

At 80 columns ``solve``'s table cut the push column (``-16.4,-5.1…``), and ``solve --batch``
cut the file names, so that four ``gen-plate-2d-s…`` rows could not be told apart. The report
of an infeasible plan said verification was skipped by ``--no-verify``, and listed the same
"too weak" reason once per pricing.
"""

from __future__ import annotations

import json
import shutil

from conftest import PROBLEMS

from fixplan.cli import main

SOURCE = PROBLEMS / "gen-plate-2d-s2026-000.toml"


def test_solve_at_80_columns_prints_every_push_number_whole(capsys, monkeypatch, tmp_path):
    monkeypatch.setenv("COLUMNS", "80")
    plan = tmp_path / "plan.json"
    capsys.readouterr()
    main(["solve", str(PROBLEMS / "box-tilted-start.toml"), "--no-verify", "--out", str(plan)])
    out = capsys.readouterr().out
    assert "…" not in out
    wrenches = [tr["wrench"] for tr in json.loads(plan.read_text())["transitions"]]
    assert len(wrenches) >= 3
    lines = out.splitlines()
    for i, w in enumerate(wrenches, 1):
        expected = f"  {i}: " + ", ".join(f"{x:.3g}" for x in w)
        assert expected in lines, f"push {i} not printed whole: {expected!r}"


def test_batch_at_80_columns_keeps_file_names_whole(capsys, monkeypatch, tmp_path):
    monkeypatch.setenv("COLUMNS", "80")
    names = ["gen-plate-2d-s2026-002.toml", "gen-plate-2d-s2026-003.toml"]
    for n in names:
        shutil.copyfile(PROBLEMS / n, tmp_path / n)
    capsys.readouterr()
    main(["solve", "--batch", str(tmp_path), "--no-verify"])
    out = capsys.readouterr().out
    assert "…" not in out
    for n in names:
        assert sum(n in line for line in out.splitlines()) == 2, out  # its table row and its reason line


def test_an_infeasible_report_says_why_verification_did_not_run_and_lists_each_transition_once(capsys, tmp_path):
    # box-weak-hand: a 0.5 N hand cannot slide a 2 kg part (μ m g / sqrt(1 + μ²) = 4.76 N) onto
    # S1, S2 or E1 from {B1, B2, B3}: three transitions, each priced twice (cheap check, then path)
    report = tmp_path / "plan.md"
    capsys.readouterr()
    rc = main(["solve", str(PROBLEMS / "box-weak-hand.toml"), "--report", str(report)])
    out = capsys.readouterr().out
    assert rc == 1
    text = report.read_text()
    assert "--no-verify" not in text  # it was not given
    assert "Not run: there is no plan to run in the loop." in text
    tried = [line for line in text.splitlines() if line.startswith("- {B1, B2, B3} + ")]
    assert sorted(line.split(":")[0] for line in tried) == ["- {B1, B2, B3} + E1", "- {B1, B2, B3} + S1",
                                                            "- {B1, B2, B3} + S2"]  # fmt: skip
    assert "6 priced, 6 failed (3 distinct transitions)." in text
    # stdout states the reason once, and says that the force named is not the least that moves the part
    assert out.count("too weak") == 1
    assert "accelerates the part at 1 m/s²" in out and "--accel 0.01 --friction-margin 0" in out


def test_a_report_without_verification_names_no_verify(capsys, tmp_path):
    report = tmp_path / "plan.md"
    main(["solve", str(SOURCE), "--no-verify", "--report", str(report)])
    assert "Not run (`--no-verify`)." in report.read_text()
