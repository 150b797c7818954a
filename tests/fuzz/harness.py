"""The contract every fuzzed run must keep, and two ways to run the CLI.

The contract: exit status 0, 1 or 2 within a time bound; no traceback and no
``internal error``; with ``--json`` and exit 0/1, stdout is exactly one strict JSON object
(``NaN``/``Infinity`` refused); a failure (exit 2) explains itself on stderr, each line printable;
every file that existed before the run is byte-for-byte unchanged unless ``--force`` was given.

``run_in_process`` runs ``fixplan.cli.main`` inside pytest with typer's ``CliRunner`` isolation
(fast: no interpreter start); a timer interrupts a run past its bound. ``run_subprocess`` is for
the classes that can hang in C (a named pipe) or abort the interpreter (a malformed HDF5 file
reaching compiled code), so that they cannot take pytest down.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from conftest import CLI, ROOT

EXIT_OK = (0, 1, 2)


class Hang(BaseException):  # noqa: N818 - BaseException: fixplan's main must not turn it into exit 3
    """Raised by the timer when an in-process run exceeds its bound."""


@dataclass(frozen=True)
class Outcome:
    args: tuple[str, ...]
    code: int
    stdout: str
    stderr: str
    seconds: float


def run_in_process(args: Sequence[str], timeout_s: float = 60.0, cwd: Path | None = None) -> Outcome:
    """``fixplan ARGS`` through ``fixplan.cli.main`` with stdout/stderr captured by CliRunner.

    ``cwd``: the working directory during the run (default outputs such as ``map.png`` land there).
    """
    import time

    from typer.testing import CliRunner

    from fixplan.cli import main

    def on_alarm(signum, frame):  # noqa: ARG001
        raise Hang(f"fixplan {' '.join(args)} ran past {timeout_s} s")

    runner = CliRunner()
    previous = signal.signal(signal.SIGALRM, on_alarm)
    here = os.getcwd()
    t0 = time.perf_counter()
    try:
        if cwd is not None:
            os.chdir(cwd)
        with runner.isolation() as streams:
            out, err = streams[0], streams[1]
            signal.setitimer(signal.ITIMER_REAL, timeout_s)
            try:
                code = main(list(args))
            finally:
                signal.setitimer(signal.ITIMER_REAL, 0)
            sys.stdout.flush()
            sys.stderr.flush()
            stdout = out.getvalue().decode("utf-8", "replace")
            stderr = err.getvalue().decode("utf-8", "replace") if err is not None else ""
    finally:
        signal.signal(signal.SIGALRM, previous)
        os.chdir(here)
    return Outcome(tuple(args), code, stdout, stderr, time.perf_counter() - t0)


def run_subprocess(
    args: Sequence[str], timeout_s: float = 60.0, cwd: Path | None = None, stdout: object = None
) -> Outcome:
    """``fixplan ARGS`` in a fresh interpreter; a run past ``timeout_s`` is killed and reported as a hang.

    ``stdout``: where its standard output goes (a file, a descriptor); by default it is captured.
    """
    import time

    t0 = time.perf_counter()
    env = dict(os.environ, MPLBACKEND="Agg")
    env.pop("FIXPLAN_DEBUG", None)
    try:
        proc = subprocess.run(
            [*CLI, *args],
            stdout=subprocess.PIPE if stdout is None else stdout,
            stderr=subprocess.PIPE,
            text=True,
            errors="replace",
            timeout=timeout_s,
            cwd=cwd,
            env=env,
            stdin=subprocess.DEVNULL,
        )
    except subprocess.TimeoutExpired:
        raise AssertionError(f"fixplan {' '.join(args)} hung: killed after {timeout_s} s") from None
    return Outcome(tuple(args), proc.returncode, proc.stdout or "", proc.stderr, time.perf_counter() - t0)


def _refuse_constant(name: str) -> float:
    raise ValueError(f"non-standard JSON constant {name}")


def snapshot(folder: Path) -> dict[Path, bytes]:
    """Every regular file under ``folder`` with its bytes."""
    return {p: p.read_bytes() for p in folder.rglob("*") if p.is_file() and not p.is_symlink()}


def assert_contract(
    outcome: Outcome, before: dict[Path, bytes] | None = None, *, json_expected: bool | None = None
) -> None:
    """Check one run against the contract (see the module docstring); a failure names the command."""
    cmd = "fixplan " + " ".join(repr(a) if (" " in a or not a) else a for a in outcome.args)
    where = f"\n  command: {cmd}\n  exit: {outcome.code}\n  stderr: {outcome.stderr[-2000:]}"
    assert outcome.code in EXIT_OK, f"exit status {outcome.code} (expected 0, 1 or 2){where}"
    assert "Traceback" not in outcome.stderr and "Traceback" not in outcome.stdout, f"a traceback{where}"
    assert "internal error" not in outcome.stderr, f"an internal error{where}"
    if outcome.code == 2:
        lines = [line for line in outcome.stderr.splitlines() if line.strip()]
        assert lines, f"exit 2 without a message{where}"
        for line in lines:
            assert line.isprintable(), f"a message line with control characters: {line!r}{where}"
    wants_json = "--json" in outcome.args if json_expected is None else json_expected
    if wants_json and outcome.code in (0, 1) and "--help" not in outcome.args:
        text = outcome.stdout.strip()
        try:
            obj = json.loads(text, parse_constant=_refuse_constant)
        except ValueError as exc:
            raise AssertionError(f"stdout is not one strict JSON object ({exc}): {text[:300]!r}{where}") from None
        assert isinstance(obj, dict), f"JSON is not an object{where}"
    if before is not None and "--force" not in outcome.args:
        for path, data in before.items():
            assert path.exists(), f"{path} was deleted{where}"
            assert path.read_bytes() == data, f"{path} was changed without --force{where}"


# -- budgets -----------------------------------------------------------------------------------
# ``make test`` runs a short derandomized budget (the same examples every run, about a minute);
# ``make fuzz`` sets FIXPLAN_FUZZ=long: FIXPLAN_FUZZ_SCALE (default 20) times more examples with
# fresh seeds, keeping Hypothesis' example database so a failure found once is replayed first.
LONG = os.environ.get("FIXPLAN_FUZZ") == "long"
SCALE = int(os.environ.get("FIXPLAN_FUZZ_SCALE", "20"))


def budget(examples: int):  # type: ignore[no-untyped-def]
    """Hypothesis settings for a test that runs ``examples`` cases in the short budget."""
    from hypothesis import HealthCheck, settings
    from hypothesis.database import DirectoryBasedExampleDatabase

    return settings(
        max_examples=examples * SCALE if LONG else examples,
        deadline=None,
        derandomize=not LONG,
        database=DirectoryBasedExampleDatabase(str(ROOT / ".hypothesis")) if LONG else None,
        suppress_health_check=list(HealthCheck),
        print_blob=True,
    )
