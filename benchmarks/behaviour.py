"""Snapshot of what fixplan answers, to show a refactoring keeps behaviour identical.

``python behaviour.py snapshot OUT.json`` runs the public commands in-process (typer's runner, so
it measures the command-line contract, not internal names) on every file in ``problems/``, on a
seeded generated set and on the FCLib files under ``../shared`` when present, and writes every
answer with wall-clock fields removed. ``python behaviour.py compare OLD.json NEW.json`` prints
each difference: statuses, verdicts, sequences and exit codes must be equal; numbers are compared
with a relative tolerance (``--rtol``, default 1e-6 with an absolute floor of 1e-9) and the largest
relative difference is reported. Exit 0 when identical within tolerance, 1 otherwise.

Used for issue-free refactorings: take a snapshot before, one after, compare.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import tomllib
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
PROBLEMS = ROOT / "problems"
SHARED = ROOT.parent / "shared" / "data"
# Keys that are simulated time (deterministic), kept although they contain "time".
KEEP_KEYS = {"time_s", "t_s", "sim_time_s", "duration_s"}


def _is_timing(key: str) -> bool:
    """Keys measured on the wall clock (differ run to run); simulated time (``time_s`` of a plan,
    ``duration_s``) is deterministic and kept, except in ``fclib`` answers where ``time_s`` is wall
    time (dropped there by :func:`snapshot`)."""
    k = key.lower()
    return k in {"timings", "deadline_misses"} or any(
        t in k for t in ("wall_time", "elapsed", "cpu_time", "solve_time", "tick_us", "_us")
    )


def without_wall_clock(obj: Any, drop: frozenset[str] = frozenset()) -> Any:
    """``obj`` (a command's JSON answer) without its wall-clock fields, the keys in ``drop`` and checkout paths."""
    if isinstance(obj, dict):
        return {k: without_wall_clock(v, drop) for k, v in obj.items() if not _is_timing(k) and k not in drop}
    if isinstance(obj, list):
        return [without_wall_clock(v, drop) for v in obj]
    if isinstance(obj, str):  # paths of the checkout differ between clones and worktrees
        return obj.replace(str(ROOT) + "/", "")
    return obj


def _run(args: list[str], drop: frozenset[str] = frozenset()) -> dict[str, Any]:
    from typer.testing import CliRunner

    from fixplan.cli import app

    result = CliRunner().invoke(app, args)
    out: dict[str, Any] = {"exit": result.exit_code}
    text = result.stdout.strip()
    try:
        out["json"] = without_wall_clock(json.loads(text), drop) if text else None
    except json.JSONDecodeError:
        out["text"] = without_wall_clock(text.splitlines()[-1]) if text else ""
    return out


def _in_folder(data: Any, folder: str, placeholder: str) -> Any:
    """``data`` with every string's ``folder`` prefix replaced by ``placeholder`` (JSON-like values)."""
    if isinstance(data, str):
        return data.replace(folder, placeholder)
    if isinstance(data, list):
        return [_in_folder(x, folder, placeholder) for x in data]
    if isinstance(data, dict):
        return {k: _in_folder(v, folder, placeholder) for k, v in data.items()}
    return data


def snapshot(out_path: Path, quick: bool) -> None:
    answers: dict[str, Any] = {}
    expected = tomllib.loads((PROBLEMS / "expected.toml").read_text())
    for i, case in enumerate(expected.get("case", [])):
        args = [
            "classify",
            str(PROBLEMS / case["file"]),
            "--json",
            "--wrench",
            ",".join(repr(float(x)) for x in case["wrench"]),
            "--pose",
            case.get("pose", "start"),
        ]
        if "contacts" in case:
            args += ["--contacts", ",".join(case["contacts"])]
        answers[f"classify/{i}/{case['file']}"] = _run(args)
        print(f"classify {i}", file=sys.stderr)
    files = sorted(p for p in PROBLEMS.glob("*.toml") if p.name != "expected.toml")
    for path in files:
        answers[f"validate/{path.name}"] = _run(["validate", str(path), "--json"])
    for path in files:
        answers[f"solve/{path.name}"] = _run(["solve", str(path), "--json"])
        print(f"solve {path.name}: {answers[f'solve/{path.name}']['exit']}", file=sys.stderr)
    for motion in ("0.1,0,0,0,0,0", "0,0.1,0,0,0,0", "0,0,1,0,0,0"):
        for objective in ("margin", "effort"):
            key = f"search/box-3-2-1/{motion}/{objective}"
            answers[key] = _run(
                [
                    "search",
                    str(PROBLEMS / "box-3-2-1.toml"),
                    "--motion",
                    motion,
                    "--objective",
                    objective,
                    "--pose",
                    "goal",
                    "--json",
                ]
            )
    answers["simulate/default"] = _run(["simulate", "--json"])
    with tempfile.TemporaryDirectory() as tmp:
        counts = {"box-321": 2 if quick else 6, "plate-2d": 3 if quick else 10}
        for family, count in counts.items():
            d = Path(tmp) / family
            _run(["generate", family, "--count", str(count), "--seed", "515", "--out", str(d)])
            for path in sorted(d.glob("*.toml")):
                key = f"solve/generated/{path.name}"
                # the plan names its fixture by path: the temporary folder differs run to run
                answers[key] = _in_folder(_run(["solve", str(path), "--json"]), str(d), f"<generated>/{family}")
                print(f"{key}: {answers[key]['exit']}", file=sys.stderr)
    for folder in ("fclib", "fclib-siconos"):
        for path in sorted((SHARED / folder).glob("*.hdf5")) if (SHARED / folder).is_dir() else []:
            if path.stat().st_size > 2_000_000:
                continue
            for solver in ("nsgs", "auto"):
                answers[f"fclib/{solver}/{path.name}"] = _run(
                    ["fclib", str(path), "--solver", solver, "--max-iter", "200", "--json"],
                    drop=frozenset({"time_s"}),
                )
            print(f"fclib {path.name}", file=sys.stderr)
    out_path.write_text(json.dumps(answers, indent=1, sort_keys=True))


def _compare(a: Any, b: Any, where: str, rtol: float, diffs: list[str], worst: list[float]) -> None:
    if isinstance(a, bool) or isinstance(b, bool) or not (isinstance(a, (int, float)) and isinstance(b, (int, float))):
        if isinstance(a, dict) and isinstance(b, dict):
            for k in sorted(set(a) | set(b)):
                if k not in a or k not in b:
                    diffs.append(f"{where}.{k}: only in {'new' if k in b else 'old'}")
                else:
                    _compare(a[k], b[k], f"{where}.{k}", rtol, diffs, worst)
        elif isinstance(a, list) and isinstance(b, list):
            if len(a) != len(b):
                diffs.append(f"{where}: length {len(a)} -> {len(b)}")
            for i, (x, y) in enumerate(zip(a, b, strict=False)):
                _compare(x, y, f"{where}[{i}]", rtol, diffs, worst)
        elif a != b:
            diffs.append(f"{where}: {a!r} -> {b!r}")
        return
    fa, fb = float(a), float(b)
    if math.isnan(fa) and math.isnan(fb):
        return
    rel = abs(fa - fb) / max(abs(fa), abs(fb), 1e-9)
    worst[0] = max(worst[0], rel)
    if rel > rtol and abs(fa - fb) > 1e-9:
        diffs.append(f"{where}: {fa!r} -> {fb!r} (rel {rel:.1e})")


def compare(old: Path, new: Path, rtol: float) -> int:
    a, b = json.loads(old.read_text()), json.loads(new.read_text())
    diffs: list[str] = []
    worst = [0.0]
    _compare(a, b, "", rtol, diffs, worst)
    for line in diffs:
        print(line)
    print(
        f"{len(a)} answers compared; {len(diffs)} differences beyond rtol {rtol:g}; "
        f"largest relative difference of any number {worst[0]:.2e}"
    )
    return 0 if not diffs else 1


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="cmd", required=True)
    s = sub.add_parser("snapshot")
    s.add_argument("out", type=Path)
    s.add_argument("--quick", action="store_true", help="fewer generated fixtures")
    c = sub.add_parser("compare")
    c.add_argument("old", type=Path)
    c.add_argument("new", type=Path)
    c.add_argument("--rtol", type=float, default=1e-6)
    ns = parser.parse_args()
    if ns.cmd == "snapshot":
        snapshot(ns.out, ns.quick)
        return 0
    return compare(ns.old, ns.new, ns.rtol)


if __name__ == "__main__":
    sys.exit(main())
