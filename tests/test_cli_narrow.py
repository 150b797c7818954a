"""At 80 columns the CLI's tables cut nothing a reader needs (issue 21 §6).

``solve``'s table cut the push column (``-16.4,-5.1…``), and ``solve --batch`` cut the file
names, so that four ``gen-plate-2d-s…`` rows could not be told apart.
"""

from __future__ import annotations

import json
import shutil

from conftest import PROBLEMS

from fixplan.cli import main


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
