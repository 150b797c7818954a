"""Outputs that are the users' inputs, outputs where nothing can be written, standard output that takes nothing.

The classes: an output that is a hard link to an input (the fixture, the
wrench list, the plan) or a symbolic link to one; a hard link to a user's file that is no input;
an output in a full place (a file-size limit, drawn per run: the write fails partway, as on a
full disk); an output where no file can be made (``/proc``, a device, under a file); standard
output on ``/dev/full`` or a pipe whose reader is gone. Each run keeps the contract
(:func:`harness.assert_contract`) and more: with ``--force`` too, every input is byte-for-byte
what it was and still the same file; no temporary file is left; after exit 2 an output that
existed holds what it held; a file never receives bytes through another name.
"""

from __future__ import annotations

import contextlib
import os
import resource
import tempfile
from pathlib import Path

import pytest
from harness import assert_contract, budget, run_in_process, run_subprocess, snapshot
from hypothesis import event, given, note
from hypothesis import strategies as st
from mutations import PROBLEMS

FIXTURE = (PROBLEMS / "box-3-2-1.toml").read_bytes()
WRENCHES = b"Fx,Fy,Fz,Tx,Ty,Tz\n1,0,0,0,0,0\n0,0,-5,0,0,0\n"
NOTES = b"# a user's notes, no input of any command\n"

# command -> (its arguments with the output as "{out}", the inputs it reads, the output's suffix)
COMMANDS = {
    "classify": (["classify", "f.toml", "--wrenches", "w.csv", "--out", "{out}"], ["f.toml", "w.csv"], ".csv"),
    "simulate": (["simulate", "f.toml", "--duration", "0.01", "--out", "{out}"], ["f.toml"], ".csv"),
    "map": (["map", "f.toml", "--n", "3", "--out", "{out}"], ["f.toml"], ".png"),
    "solve": (["solve", "f.toml", "--no-verify", "--out", "{out}"], ["f.toml"], ".json"),
    "solve-report": (["solve", "f.toml", "--no-verify", "--report", "{out}"], ["f.toml"], ".md"),
    "view": (["view", "f.toml", "--plan", "plan.json", "--out", "{out}"], ["f.toml", "plan.json"], ".html"),
}
TARGETS = ["hard link to an input", "symbolic link to an input", "hard link to a user's file", "new", "existing",
           "full place", "/proc", "under a file", "device"]  # fmt: skip


@pytest.fixture(scope="module")
def plan_json() -> bytes:
    """A plan of the box (solve --no-verify), and every command run once: no kernel compiles under a size limit."""
    with tempfile.TemporaryDirectory() as tmp:
        folder = _folder(tmp, b"{}")
        for name, (args, _, suffix) in COMMANDS.items():
            if name != "view":
                outcome = run_in_process([a.replace("{out}", f"warm-{name}{suffix}") for a in args], cwd=folder)
                assert outcome.code in (0, 1), outcome.stderr
        data = (folder / "warm-solve.json").read_bytes()
        assert run_in_process(["view", "f.toml", "--plan", "warm-solve.json", "--out", "v.html"], cwd=folder).code == 0
        return data


def _folder(tmp: str, plan: bytes) -> Path:
    folder = Path(tmp)
    (folder / "f.toml").write_bytes(FIXTURE)
    (folder / "w.csv").write_bytes(WRENCHES)
    (folder / "plan.json").write_bytes(plan)
    (folder / "notes.md").write_bytes(NOTES)
    return folder


@contextlib.contextmanager
def _file_size_limit(nbytes: int | None):
    if nbytes is None:
        yield
        return
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    resource.setrlimit(resource.RLIMIT_FSIZE, (nbytes, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))


def _identity(path: Path) -> tuple[int, int, bytes]:
    info = os.stat(path)
    return info.st_dev, info.st_ino, path.read_bytes()


@budget(12)
@given(
    command=st.sampled_from(sorted(COMMANDS)),
    target=st.sampled_from(TARGETS),
    which=st.integers(0, 1),
    force=st.booleans(),
    limit=st.integers(0, 3000),
)
def test_outputs_never_reach_an_input(plan_json, command, target, which, force, limit) -> None:
    args, inputs, suffix = COMMANDS[command]
    source = inputs[which % len(inputs)]
    with tempfile.TemporaryDirectory() as tmp:
        folder = _folder(tmp, plan_json)
        out = folder / f"out{suffix}"
        if target == "hard link to an input":
            os.link(folder / source, out)
        elif target == "symbolic link to an input":
            out.symlink_to(folder / source)
        elif target == "hard link to a user's file":
            os.link(folder / "notes.md", out)
        elif target in ("existing", "full place"):
            out.write_bytes(b"OLD")
        elif target == "/proc":
            out = Path("/proc/version")
        elif target == "under a file":
            out = folder / "f.toml" / f"out{suffix}"
        elif target == "device":
            out = Path("/dev/full")
        before = {name: _identity(folder / name) for name in (*inputs, "notes.md")}
        existed = out.read_bytes() if out.is_file() and not out.is_symlink() else None
        argv = [a.replace("{out}", str(out)) for a in args] + (["--force"] if force else [])
        note(f"{target}: {argv} (limit {limit} B)")
        with _file_size_limit(limit if target == "full place" else None):
            outcome = run_in_process(argv, timeout_s=120, cwd=folder)
        event(f"{target}: exit {outcome.code}")
        assert_contract(outcome, json_expected=False)
        for name, identity in before.items():  # with --force too: the same file, the same bytes
            assert _identity(folder / name) == identity, f"{name} changed: {outcome}"
        assert not [p.name for p in folder.iterdir() if ".tmp" in p.name], f"a temporary file was left: {outcome}"
        if target in ("hard link to an input", "symbolic link to an input"):
            assert outcome.code == 2 and "same file" in outcome.stderr, outcome
        if outcome.code == 2 and existed is not None:
            assert out.read_bytes() == existed, f"{out} changed although the command failed: {outcome}"
        if target == "full place" and force:
            assert outcome.code == 2 and "cannot write" in outcome.stderr or out.stat().st_size <= limit, outcome
        if target in ("/proc", "under a file", "device"):
            assert outcome.code == 2, outcome


STDOUT_COMMANDS = [
    ["validate", "f.toml"],
    ["classify", "f.toml", "--wrench", "1,0,0,0,0,0"],
    ["classify", "f.toml", "--wrenches", "w.csv", "--json"],
    ["simulate", "f.toml", "--duration", "0.01", "--json"],
    ["schema"],
    ["generate", "--list"],
]


@budget(3)
@given(args=st.sampled_from(STDOUT_COMMANDS), sink=st.sampled_from(["/dev/full", "closed pipe"]))
def test_stdout_that_takes_nothing_is_one_line_and_exit_2(args, sink) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        folder = _folder(tmp, b"{}")
        before = snapshot(folder)
        if sink == "/dev/full":
            with open("/dev/full", "w") as full:
                outcome = run_subprocess(args, timeout_s=120, cwd=folder, stdout=full)
            reason = "no space left on the device"
        else:
            read, write = os.pipe()
            os.close(read)
            try:
                outcome = run_subprocess(args, timeout_s=120, cwd=folder, stdout=write)
            finally:
                os.close(write)
            reason = "the reader closed the pipe"
        note(repr(outcome))
        assert_contract(outcome, before, json_expected=False)
        assert outcome.code == 2
        assert outcome.stderr == f"fixplan: cannot write to standard output: {reason}\n"
