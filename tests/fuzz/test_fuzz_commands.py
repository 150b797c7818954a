"""Odd command lines: options with values of every kind, outputs onto users' files.

Each run happens in a folder holding a user's files (a fixture, a picture, a CSV, a plan, a
dangling symbolic link); none may change without ``--force``, and none may be created outside
the folder. The classes that can block in the kernel (a named pipe) or write to a device run in
a subprocess with a timeout (``test_subprocess_classes``).
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

import pytest
from harness import LONG, assert_contract, budget, run_in_process, run_subprocess, snapshot
from hypothesis import event, given, note
from hypothesis import strategies as st
from mutations import PROBLEMS, number_list, wrench_text

USER_FILES = {
    "f.toml": (PROBLEMS / "box-3-2-1.toml").read_bytes(),
    "disk.toml": (PROBLEMS / "disk-2d.toml").read_bytes(),
    "picture.png": b"\x89PNG a user's picture",
    "w.csv": b"Fx,Fy,Fz,Tx,Ty,Tz\n0,0,0,0,0,0\n5,0,0,0,0,0\n",
    "bad.csv": b"1,2\n\xff\xfe\nx,y,z,1,2,3\n",
    "plan.json": b'{"status": "planned", "transitions": [{"from": ["B1"], "added": "NOPE"}]}',
    "notes.md": b"# my notes\n",
}


def _folder(tmp: str) -> Path:
    folder = Path(tmp)
    for name, data in USER_FILES.items():
        (folder / name).write_bytes(data)
    (folder / "dangling.csv").symlink_to(folder / "missing" / "target.csv")
    return folder


# paths are written as names and resolved in the run's folder ("@" prefix), or used as they are
INPUTS = st.sampled_from(["@f.toml", "@disk.toml", "@notes.md", "@picture.png", "@nope.toml", "@", "@dangling.csv"])
OUTPUTS = st.sampled_from(
    ["@new.png", "@new.csv", "@sub/new.json", "@picture.png", "@f.toml", "@w.csv", "@notes.md", "@dangling.csv",
     "@", "@new.txt", "@new.html", "/dev/full", "@map.CSV"]
)  # fmt: skip
TEXTS = st.one_of(
    st.sampled_from(["", ",", "B1", "B1,B1", "NOPE", "S1,S2,E1", "start", "goal", "x\ny", "\x1b[2J", "[/x]"]),
    st.text(max_size=12),
)


def _opt(name: str, value: st.SearchStrategy) -> st.SearchStrategy:
    return st.tuples(st.just(name), value)


BATCH = _opt("--batch", st.sampled_from(["@", "@f.toml", "@nope"]))  # starts a Dask cluster: long runs only
SLOW = (BATCH,)

OPTIONS = {
    "validate": [_opt("--verbose", st.none())],
    "classify": [
        _opt("--wrench", st.one_of(wrench_text(), number_list())),
        _opt("--wrenches", st.sampled_from(["@w.csv", "@bad.csv", "@picture.png", "@nope.csv", "@"])),
        _opt("--contacts", TEXTS),
        _opt("--at", number_list()),
        _opt("--pose", TEXTS),
        _opt("--backend", st.sampled_from(["clarabel", "cvxpy", "x"])),
        _opt("--out", OUTPUTS),
        _opt("--force", st.none()),
        _opt("--json", st.none()),
    ],
    "search": [
        _opt("--motion", st.one_of(number_list(), st.just("0.1,0,0,0,0,0"))),
        _opt("--contacts", TEXTS),
        _opt("--at", number_list()),
        _opt("--pose", TEXTS),
        _opt("--objective", st.sampled_from(["margin", "effort", "x"])),
        _opt("--min-margin", st.sampled_from(["0", "-1", "nan", "1e300", "5", "x"])),
        _opt("--json", st.none()),
    ],
    "map": [
        _opt("--axes", st.sampled_from(["Fx,Tz", "Fx,Mz", "Fy,Fy", "Fx", "Tz,Fx", "x,y", "", "Fx,Fy,Fz"])),
        _opt("--range", st.sampled_from(["-1:1,-1:1", "1:-1,0:1", "-1e7:1e7,0:1", "nan:1,0:1", "x", "0:0,0:1", ":,:"])),
        _opt("--n", st.sampled_from(["2", "3", "1", "0", "-3", "1001", "x"])),
        _opt("--wrench", st.one_of(wrench_text(), number_list())),
        _opt("--contacts", TEXTS),
        _opt("--out", OUTPUTS),
        _opt("--force", st.none()),
        _opt("--json", st.none()),
    ],
    "simulate": [
        _opt("--duration", st.sampled_from(["0", "0.01", "-1", "1e12", "nan", "inf", "x", "1e-9"])),
        _opt("--dt", st.sampled_from(["1e-3", "0", "1e-300", "0.5", "-1", "nan", "2"])),
        _opt("--wrench", st.one_of(wrench_text(), number_list())),
        _opt("--tolerance", st.sampled_from(["1e-8", "0", "1e-300", "2", "nan"])),
        _opt("--pose", TEXTS),
        _opt("--out", OUTPUTS),
        _opt("--every", st.sampled_from(["1", "0", "-1", "1000000", "x"])),
        _opt("--json", st.none()),
    ],
    "solve": [  # on files that fail fast (not full, missing): the outputs and options are what is fuzzed
        _opt("--order", TEXTS),
        _opt("--out", OUTPUTS),
        _opt("--report", OUTPUTS),
        _opt("--force", st.none()),
        _opt("--no-verify", st.none()),
        _opt("--accel", st.sampled_from(["0", "1", "1e9", "nan", "x"])),
        _opt("--perturb-seed", st.sampled_from(["0", "-1", "x"])),
        BATCH,
        _opt("--json", st.none()),
    ],
    "view": [
        _opt("--plan", st.sampled_from(["@plan.json", "@notes.md", "@picture.png", "@nope.json", "@"])),
        _opt("--out", OUTPUTS),
        _opt("--frames", st.sampled_from(["2", "1", "0", "x", "3000"])),
        _opt("--force", st.none()),
        _opt("--json", st.none()),
    ],
    "generate": [
        _opt("--count", st.sampled_from(["1", "0", "-1", "x"])),
        _opt("--seed", st.sampled_from(["0", "-1", "x", "99999999999999999999"])),
        _opt("--out", st.sampled_from(["@", "@gen", "@f.toml", "@dangling.csv"])),
        _opt("--force", st.none()),
        _opt("--list", st.none()),
        _opt("--json", st.none()),
    ],
    "fclib": [
        _opt("--tol", st.sampled_from(["1e-8", "0", "-1", "nan", "x"])),
        _opt("--max-iter", st.sampled_from(["1", "0", "x"])),
        _opt("--solver", st.sampled_from(["auto", "nsgs", "x", ""])),
        _opt("--json", st.none()),
    ],
}
FILES = {
    "solve": st.sampled_from(["@disk.toml", "@nope.toml", "@notes.md", "@picture.png"]),
    "view": st.sampled_from(["@disk.toml", "@nope.toml", "@notes.md"]),
    "generate": st.sampled_from(["box-321", "plate-2d", "nope", ""]),
    "fclib": st.sampled_from(["@f.toml", "@picture.png", "@nope.hdf5", "@"]),
}


@st.composite
def command_line(draw: st.DrawFn) -> list[str]:
    command = draw(st.sampled_from(sorted(OPTIONS)))
    args = [command]
    if draw(st.integers(0, 9)) > 0:
        args.append(draw(FILES.get(command, INPUTS)))
    options = OPTIONS[command] if LONG else [o for o in OPTIONS[command] if o not in SLOW]
    chosen = draw(st.permutations(options))[: draw(st.integers(0, 5))]
    for strategy in chosen:
        name, value = draw(strategy)
        args.append(name)
        if value is not None:
            args.append(value)
    if command == "map" and "--n" not in args:
        args += ["--n", "2"]  # the default 100 x 100 grid is a long run, not a hostile one
    if command == "view" and "--frames" not in args:
        args += ["--frames", "2"]
    return args


def _resolve(args: list[str], folder: Path) -> list[str]:
    return [str(folder / a[1:]) if a.startswith("@") else a for a in args]


@budget(60)
@given(args=command_line())
def test_command_line(args: list[str]) -> None:
    """Any command line: exit 0/1/2, one-line messages, strict JSON, no user file changed or created outside."""
    if args[0] == "simulate" and "--force" in args:  # pragma: no cover - the strategy never draws it
        return
    with tempfile.TemporaryDirectory() as tmp:
        folder = _folder(tmp)
        before = snapshot(folder)
        resolved = _resolve(args, folder)
        outcome = run_in_process(resolved, timeout_s=60, cwd=folder)
        note(repr(outcome))
        event(f"{args[0]} exit {outcome.code}")
        assert_contract(outcome, before)
        assert not (folder / "missing").exists(), "a file was created through a dangling symbolic link"


@pytest.mark.parametrize(
    "case",
    ["fifo-fixture", "fifo-wrenches", "fifo-plan", "dev-full-force", "dev-null-fixture", "fifo-output"],
)
def test_subprocess_classes(case: str, tmp_path: Path) -> None:
    """What can block in the kernel or write to a device, in a subprocess with a 30 s bound: exit 2, one line."""
    folder = _folder(str(tmp_path))
    fifo = folder / "pipe"
    os.mkfifo(fifo)
    args = {
        "fifo-fixture": ["validate", str(fifo)],
        "fifo-wrenches": ["classify", str(folder / "f.toml"), "--wrenches", str(fifo)],
        "fifo-plan": ["view", str(folder / "f.toml"), "--plan", str(fifo), "--out", str(folder / "s.html")],
        "dev-full-force": ["simulate", str(folder / "f.toml"), "--duration", "0.01", "--out", "/dev/full", "--force"],
        "dev-null-fixture": ["classify", "/dev/null", "--wrench", "0,0,0,0,0,0"],
        "fifo-output": ["simulate", str(folder / "f.toml"), "--duration", "0.01", "--out", str(fifo), "--force"],
    }[case]
    before = snapshot(folder)
    outcome = run_subprocess(args, timeout_s=30)
    assert_contract(outcome, before)
    assert outcome.code == 2
    assert len(outcome.stderr.strip().splitlines()) == 1, outcome.stderr
    assert "not a regular file" in outcome.stderr or "named pipe" in outcome.stderr or "device" in outcome.stderr


def test_help_and_version_on_stdout() -> None:
    """Bare fixplan prints the help (several lines, on stdout, exit 0); --version prints the version."""
    bare = run_in_process([])
    assert bare.code == 0 and bare.stderr == ""
    assert bare.stdout.startswith("Usage: fixplan") and len(bare.stdout.splitlines()) > 10
    assert "validate" in bare.stdout and "classify" in bare.stdout
    version = run_in_process(["--version"])
    from importlib.metadata import version as installed

    from fixplan import aot

    assert version.code == 0
    assert version.stdout.splitlines() == [f"fixplan {installed('fixplan')}", f"kernels: {aot.status()}"]


def test_generate_into_the_folder_only(tmp_path: Path) -> None:
    """generate --out DIR writes only inside DIR (a sanity check that the harness sees created files)."""
    if shutil.which("true") is None:  # pragma: no cover
        pytest.skip("no POSIX tools")
    outcome = run_in_process(["generate", "box-321", "--count", "1", "--out", str(tmp_path / "gen"), "--json"])
    assert_contract(outcome)
    assert outcome.code == 0 and [p.name for p in (tmp_path / "gen").iterdir()] == ["box-321-s0-000.toml"]
