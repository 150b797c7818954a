"""Mutated fixture files: every command keeps the contract of ``harness.assert_contract``."""

from __future__ import annotations

import tempfile
from pathlib import Path

from harness import assert_contract, budget, run_in_process, snapshot
from hypothesis import event, given, note
from hypothesis import strategies as st
from mutations import fixture_bytes, fixture_case, number_list, wrench_text


def _write(folder: Path, data: bytes) -> Path:
    path = folder / "f.toml"
    path.write_bytes(data)
    return path


@budget(120)
@given(data=st.one_of(fixture_bytes(), fixture_bytes(numeric_only=True)), verbose=st.booleans())
def test_validate_mutated_fixture(data: bytes, verbose: bool) -> None:
    """validate: exit 0 or 2 with one line per issue (FILE: key: message), the same on a second run."""
    with tempfile.TemporaryDirectory() as tmp:
        path = _write(Path(tmp), data)
        before = snapshot(Path(tmp))
        args = ["validate", str(path), *(["--verbose"] if verbose else [])]
        first = run_in_process(args, timeout_s=20, cwd=Path(tmp))
        note(repr(first))
        event(f"validate exit {first.code}")
        assert_contract(first, before)
        assert first.code in (0, 2)
        if first.code == 2:
            for line in first.stderr.splitlines():
                assert line.startswith(f"{path}: "), line  # FILE: key: message
        again = run_in_process(args, timeout_s=20, cwd=Path(tmp))
        assert (again.code, again.stdout, again.stderr) == (first.code, first.stdout, first.stderr), "not deterministic"


COMMANDS = ("classify", "search", "simulate", "map", "validate")


@budget(30)
@given(
    case=fixture_case(),
    command=st.sampled_from(COMMANDS),
    data=st.data(),
    json_out=st.booleans(),
    picture=st.booleans(),
)
def test_commands_on_mutated_fixture(
    case: tuple[bytes, int], command: str, data: st.DataObject, json_out: bool, picture: bool
) -> None:
    """classify, search, simulate, map on a mutated file: exit 0/1/2, strict JSON, no output lost."""
    text, ndof = case
    numbers = data.draw(st.one_of(wrench_text(ndof), wrench_text(ndof), wrench_text(ndof), number_list()))
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        path = _write(folder, text)
        if picture:
            (folder / "m.png").write_bytes(b"a user's picture")
        before = snapshot(folder)
        extra = {
            "classify": ["--wrench", numbers],
            "search": ["--motion", numbers],
            "simulate": ["--duration", "0.02", "--dt", "1e-3", "--wrench", numbers],
            "map": ["--n", "3", "--out", str(folder / "m.png")],
            "validate": [],
        }[command]
        args = [command, str(path), *extra, *(["--json"] if json_out and command != "validate" else [])]
        outcome = run_in_process(args, timeout_s=60, cwd=folder)
        note(repr(outcome))
        event(f"{command} exit {outcome.code}")
        assert_contract(outcome, before)
        if picture and command == "map":
            assert outcome.code == 2
