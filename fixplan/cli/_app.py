"""The ``fixplan`` application: its options, the parsing shared by the commands, JSON output, and ``main``.

The commands register themselves on :data:`app` in the modules of :mod:`fixplan.cli`;
:func:`main` turns every expected failure into one line and exit 2.
"""

from __future__ import annotations

import functools
import json
import math
import sys
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import typer

from fixplan import limits
from fixplan.cli.flags import with_flags
from fixplan.errors import FixplanError, FixtureError, InputError, InputFileError, SolverError, one_line
from fixplan.files import CommandStreams, StdoutError, check_output, document_stream

try:  # typer ≥ 0.20 vendors click; older typer depends on it
    from typer._click import exceptions as click_exc
except ImportError:  # pragma: no cover - depends on the installed typer
    from click import exceptions as click_exc  # type: ignore[no-redef]

_CLICK_EXIT = tuple(c for c in (getattr(click_exc, "Exit", None),) if c is not None)
_CLICK_ABORT = tuple(c for c in (getattr(click_exc, "Abort", None),) if c is not None)

app = typer.Typer(
    name="fixplan",
    help="Plan how a workpiece is loaded into a fixture without jamming.",
    add_completion=False,
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
)

FileArg = Annotated[
    Path | None, typer.Argument(help="Fixture file (TOML). Default: the bundled 3-2-1 box.", show_default=False)
]
JsonOpt = Annotated[bool, typer.Option("--json", help="Print one JSON object on stdout.")]
ContactsOpt = Annotated[
    str | None,
    typer.Option(
        "--contacts",
        help="Comma-separated contact names (default: locators touching at the pose, plus [[contact]] entries).",
    ),
]
AtOpt = Annotated[
    str | None,
    typer.Option("--at", help="World point X,Y[,Z] the moments are taken about (default: the body-frame origin)."),
]
PoseOpt = Annotated[str, typer.Option("--pose", help="Analyse the part at its 'start' or 'goal' pose.")]


def _err(message: str) -> None:
    try:
        typer.echo(one_line(f"fixplan: {message}"), err=True)
    except OSError:
        pass  # standard error is gone too: the exit status is all that is left


def _console():  # type: ignore[no-untyped-def]
    """A Rich console for tables: no markup, so a name like ``[/x]`` prints as written instead of failing."""
    from rich.console import Console

    return Console(markup=False, highlight=False, emoji=False)


def _version(value: bool) -> None:
    if value:
        from importlib.metadata import PackageNotFoundError, version

        try:
            typer.echo(f"fixplan {version('fixplan')}")
        except PackageNotFoundError:  # pragma: no cover - running from a source tree without install
            typer.echo("fixplan (version unknown: not installed)")
        from fixplan import aot

        typer.echo(f"kernels: {aot.status()}")
        raise typer.Exit(0)


@app.callback()
def _root(
    version: Annotated[
        bool,
        typer.Option(
            "--version",
            help="Print the version and which kernels run (ahead-of-time or JIT), and exit.",
            callback=_version,
            is_eager=True,
        ),
    ] = False,
) -> None:
    """Plan how a workpiece is loaded into a fixture without jamming."""


def _load(path: Path | None):
    """The fixture at ``path`` (default: the bundled box); every command takes mesh parts, pins and bores."""
    from fixplan.fixture import default_fixture_path, load

    return load(path if path is not None else default_fixture_path())


def _numbers(
    text: str, what: str, n: int | None = None, ranges: list[limits.Range] | limits.Range | None = None
) -> np.ndarray:
    """Comma-separated finite numbers (:func:`fixplan.limits.parse_numbers`)."""
    return limits.parse_numbers(text, what, n, ranges)


def _shown(text: str) -> str:
    """A user's text quoted in a message: escaped, and cut when long."""
    from fixplan.errors import shorten

    return shorten(text)


def _wrench(text: str, what: str, ndof: int) -> np.ndarray:
    return _numbers(text, what, ndof, limits.wrench_ranges(ndof))


def _names(text: str | None, option: str = "--contacts") -> list[str] | None:
    if text is None:
        return None
    names = [s.strip() for s in text.split(",") if s.strip()]
    if not names:
        raise InputError(f"{option} is empty (expected comma-separated locator names)")
    return names


def _pose(fixture, pose: str):
    if pose not in ("start", "goal"):
        raise InputError(f"--pose must be 'start' or 'goal', got {pose!r}")
    if pose == "goal":
        from fixplan.model import require_full

        require_full(fixture, "--pose goal")
    return pose


def _writable(path: Path, force: bool, option: str = "--out") -> Path:
    return check_output(path, force, option=option)


def _json_text(obj: dict[str, Any], *, compact: bool = False) -> str:
    """Strict JSON (no NaN or Infinity); a non-finite number is named by its place and refused."""
    try:
        if compact:
            return json.dumps(obj, separators=(",", ":"), allow_nan=False, default=_json_default)
        return json.dumps(obj, indent=2, allow_nan=False, default=_json_default)
    except ValueError:
        where = _nonfinite_path(obj, "") or "?"
        raise SolverError(
            f"the result has a non-finite number at {where} (a numerical failure inside the valid ranges; "
            "please report it with the input)"
        ) from None


def _nonfinite_path(obj: Any, path: str) -> str | None:
    if isinstance(obj, np.ndarray):
        obj = obj.tolist()
    if isinstance(obj, dict):
        for k, v in obj.items():
            if (found := _nonfinite_path(v, f"{path}.{k}" if path else str(k))) is not None:
                return found
    elif isinstance(obj, list | tuple):
        for i, v in enumerate(obj):
            if (found := _nonfinite_path(v, f"{path}[{i}]")) is not None:
                return found
    elif isinstance(obj, float | np.floating) and not math.isfinite(float(obj)):
        return path
    return None


def _emit_json(obj: dict[str, Any], *, compact: bool = False) -> None:
    """One JSON object on stdout: indented for people, compact for large batches."""
    document_stream().write(_json_text(obj, compact=compact) + "\n")


def _json_default(x: Any) -> Any:
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, np.floating | np.integer):
        return x.item()
    raise TypeError(type(x))


@functools.cache
def click_command() -> Any:
    """The click command of :data:`app`, built once per process.

    typer builds it from every command's signature (28 of them) on each call of ``app`` or of
    ``typer.main.get_command``: built twice per run, it was 0.1 s of every command's start.
    """
    return typer.main.get_command(app)


def _repeated_option(args: list[str]) -> str | None:
    """The message for an option that takes a value given twice to one command, else None.

    Click keeps the last value and drops the others silently (``--wrench A --wrench B`` would
    classify B alone): a repeated option is refused instead, naming the values given.
    """
    command = click_command()
    commands = getattr(command, "commands", {})
    rest = list(args)
    while rest and rest[0].startswith("-"):  # root options (--version, --help)
        rest.pop(0)
    if not rest or rest[0] not in commands:
        return None
    valued: dict[str, str] = {}  # every spelling of an option that takes one value -> its first name
    for param in commands[rest[0]].params:
        opts = [*getattr(param, "opts", ()), *getattr(param, "secondary_opts", ())]
        if opts and opts[0].startswith("-") and not (getattr(param, "is_flag", False) or param.multiple):
            valued.update({o: param.opts[0] for o in param.opts})
    seen: dict[str, list[str]] = {}
    tokens = iter(rest[1:])
    for token in tokens:
        if token == "--":
            break
        name, eq, value = token.partition("=")
        if name not in valued:
            continue
        if not eq:
            value = next(tokens, "")
        seen.setdefault(valued[name], []).append(value)
    for name, values in seen.items():
        if len(values) > 1:
            shown = ", ".join(_shown(v) for v in values)
            several = name == "--wrench" and "--wrenches" in valued  # classify reads many from a file
            way = "; to classify several wrenches, list them in a CSV file for --wrenches FILE" if several else ""
            return f"{name} is given {len(values)} times ({shown}): expected it once{way}"
    return None


def main(argv: list[str] | None = None) -> int:
    """Entry point: run the app and turn every expected failure into one line and exit 2.

    Standard output is guarded for the command (:class:`fixplan.files.CommandStreams`): one that
    cannot be written (``/dev/full``, a closed pipe) is exit 2 with one line, also when it shows
    only at the last flush; with ``--json`` everything but the document goes to stderr.
    """
    args = sys.argv[1:] if argv is None else list(argv)
    if not args:  # bare `fixplan`: the help, on stdout, as `fixplan --help` prints it
        args = ["--help"]
    options = args[: args.index("--")] if "--" in args else args
    with CommandStreams(document="--json" in options) as streams:
        code = _run(args)
        try:
            streams.flush()
        except StdoutError as exc:
            _err(str(exc))
            code = 2
    return code


def _run(args: list[str]) -> int:
    """The command line ``args`` run, every expected failure turned into one line; the exit status."""
    import warnings

    if (repeated := _repeated_option(args)) is not None:
        _err(repeated)
        return 2
    try:
        # numpy's RuntimeWarnings (overflow, invalid value) are not messages for users: results are
        # checked for finiteness where they leave fixplan (strict JSON, the solvers' own checks)
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore", RuntimeWarning)
            rv = click_command()(args=args, prog_name="fixplan", standalone_mode=False)
    except (FixtureError, InputFileError) as exc:
        for issue in exc.issues:
            typer.echo(issue.format(exc.source), err=True)
        return 2
    except FixplanError as exc:
        _err(with_flags(str(exc)))
        return 2
    except (typer.Exit, *_CLICK_EXIT) as exc:
        return int(exc.exit_code)
    except (typer.Abort, *_CLICK_ABORT):
        _err("aborted")
        return 130
    except click_exc.UsageError as exc:
        hint = (
            f" (see 'fixplan {exc.ctx.info_name} --help')"
            if exc.ctx is not None and exc.ctx.info_name != "fixplan"
            else " (see 'fixplan --help')"
        )
        _err(exc.format_message().replace("\n", " ") + hint)
        return 2
    except click_exc.ClickException as exc:
        _err(exc.format_message().replace("\n", " "))
        return 2
    except KeyboardInterrupt:
        _err("interrupted")
        return 130
    except RecursionError:
        _err("input nested too deeply (refused)")
        return 2
    except Exception as exc:  # noqa: BLE001 - a bug in fixplan, not bad input: one line, exit 3
        import os

        if os.environ.get("FIXPLAN_DEBUG"):
            raise
        _err(f"internal error: {type(exc).__name__}: {exc} (a bug in fixplan; FIXPLAN_DEBUG=1 shows the traceback)")
        return 3
    return rv if isinstance(rv, int) else 0
