"""The ``fixplan`` command line.

Every command validates its fixture first. Bad input (a malformed file, a wrench of the wrong
length, an unknown contact) prints clear one-line errors on stderr and exits with status 2,
never a traceback. ``--json`` prints exactly one JSON object on stdout; progress and logs go
to stderr. Files are never overwritten without ``--force``.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import typer

from fixplan import limits
from fixplan.errors import FixplanError, FixtureError, InputError, InputFileError, SolverError, one_line
from fixplan.files import check_distinct, check_output, write_output, write_text
from fixplan.settings import DEFAULT

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
    typer.echo(one_line(f"fixplan: {message}"), err=True)


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
        raise typer.Exit(0)


@app.callback()
def _root(
    version: Annotated[
        bool, typer.Option("--version", help="Print the version and exit.", callback=_version, is_eager=True)
    ] = False,
) -> None:
    """Plan how a workpiece is loaded into a fixture without jamming."""


def _load(path: Path | None):
    from fixplan.fixture import default_fixture_path, load

    return load(path if path is not None else default_fixture_path())


def _numbers(
    text: str, what: str, n: int | None = None, ranges: list[limits.Range] | limits.Range | None = None
) -> np.ndarray:
    """Comma-separated finite numbers, ``n`` of them, each inside its range (when given)."""
    shown = _shown(text)
    try:
        values = np.array([float(x) for x in text.split(",")], dtype=float)
    except ValueError:
        raise InputError(f"{what} must be comma-separated numbers, got {shown}") from None
    if n is not None and values.shape[0] != n:
        raise InputError(f"{what} expects {n} numbers, got {values.shape[0]} in {shown}")
    if not np.all(np.isfinite(values)):
        raise InputError(f"{what} must be finite numbers, got {shown}")
    if ranges is not None:
        per = ranges if isinstance(ranges, list) else [ranges] * len(values)
        for i, (x, rng) in enumerate(zip(values, per, strict=False)):
            if not rng.contains(float(x)):
                raise InputError(f"{what}: number {i + 1} is {x:g} (expected {rng.expected()})")
    return values


def _shown(text: str) -> str:
    """A user's text quoted in a message: escaped, and cut when long."""
    from fixplan.schema import shorten

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
    sys.stdout.write(_json_text(obj, compact=compact) + "\n")


def _json_default(x: Any) -> Any:
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, np.floating | np.integer):
        return x.item()
    raise TypeError(type(x))


@app.command()
def validate(
    files: Annotated[list[Path], typer.Argument(help="Fixture files (or expected-verdict tables) to check.")],
    verbose: Annotated[
        bool,
        typer.Option(
            "--verbose",
            "-v",
            help="Also show the goal pose, each locator's gap at the start, and whether the locators determine the pose.",
        ),
    ] = False,
) -> None:
    """Check fixture files; print one line per problem (FILE: key: message) and exit 2 if any.

    Warnings (an under-determined fixture, an implausible density) print on stderr as
    FILE: key: warning: ... and do not change the exit status.
    """
    from fixplan.expectations import check_expectations, looks_like_expectations, read_toml
    from fixplan.fixture import load

    bad = False
    for path in files:
        data = read_toml(path)
        if data is not None and looks_like_expectations(data):
            issues, counts = check_expectations(path, data)
            for issue in issues:
                typer.echo(issue.format(str(path)), err=True)
            bad |= bool(issues)
            if not issues:
                typer.echo(
                    one_line(
                        f"{path}: ok (expected verdicts: " + ", ".join(f"{n} {k}" for k, n in counts.items()) + ")"
                    )
                )
            continue
        try:
            fixture = load(path)
        except FixtureError as exc:
            bad = True
            for issue in exc.issues:
                typer.echo(issue.format(str(path)), err=True)
            continue
        summary = _fixture_summary(fixture)
        for issue in summary["warnings"]:
            typer.echo(issue.format(str(path)), err=True)
        typer.echo(one_line(f"{path}: ok ({summary['kind']}{summary['note']})"))
        if verbose:
            for line in summary["details"]:
                typer.echo(one_line(f"  {line}"))
    if bad:
        raise typer.Exit(2)


def _fixture_summary(fixture) -> dict[str, Any]:  # type: ignore[no-untyped-def]
    """What validate says about a loaded fixture: kind, note, warnings, and the --verbose details."""
    from fixplan.errors import Issue
    from fixplan.locating import contact_set, locator_contact
    from fixplan.spatial import rpy_from_matrix

    d = fixture.dimension
    kind = f"{d}D {fixture.workpiece.shape.name}, {len(fixture.locators)} locators, {len(fixture.contacts)} contacts"
    warnings = list(fixture.warnings)
    details: list[str] = []
    note = ""

    def pose_text(pose) -> str:  # type: ignore[no-untyped-def]
        pos = ", ".join(f"{x:.6g}" for x in pose.p_world)
        if d == 3:
            rpy = ", ".join(f"{x:.4g}" for x in np.degrees(rpy_from_matrix(pose.R_world_body)))
            return f"position [{pos}] m, rpy [{rpy}] deg"
        return f"position [{pos}] m, angle {np.degrees(pose.angle_rad):.4g} deg"

    details.append(f"start: {pose_text(fixture.start)}")
    for loc in fixture.locators:
        gap = locator_contact(fixture.workpiece, fixture.start, loc).gap_m
        touching = "touching" if gap <= fixture.tolerances.touch_m else "open"
        details.append(f"  {loc.name}: gap {gap:.3g} m at the start ({touching})")
    if fixture.is_full:
        note = ", goal " + ("given and checked" if fixture.goal_given is not None else "computed")
        cs = contact_set(fixture, "goal", [loc.name for loc in fixture.locators])
        rank = int(np.linalg.matrix_rank(cs.G, tol=DEFAULT.numerics.rank_tol))
        determined = rank >= fixture.ndof
        details.append(f"goal ({'given' if fixture.goal_given is not None else 'computed'}): {pose_text(fixture.goal)}")
        details.append(
            f"rank of G at the goal: {rank} of {fixture.ndof}: "
            + ("the locators determine the pose" if determined else "the locators do NOT determine the pose")
        )
        if not determined:
            warnings.append(
                Issue(
                    "locator",
                    f"warning: the locators do not determine the pose (rank G = {rank} < {fixture.ndof}): "
                    "the part can move while touching every locator",
                )
            )
    else:
        need = 6 if d == 3 else 3
        details.append(f"no goal: {len(fixture.locators)} locators, a full fixture has {need} (analysis only)")
    return {"kind": kind, "note": note, "warnings": warnings, "details": details}


CLASSIFY_TABLE_ROWS = 50  # above this many wrenches, classify prints counts per mode instead of every row


def _classify_table(fixture, results, names) -> None:  # type: ignore[no-untyped-def]
    from rich.table import Table

    table = Table(title=f"{fixture.name}: contacts {', '.join(names)}")
    table.add_column("#", justify="right")
    table.add_column("wrench")
    table.add_column("mode")
    table.add_column("margin", justify="right")
    table.add_column("decided by")
    for i, r in enumerate(results, 1):
        margin = f"{r.margin:.3g}" if math.isfinite(r.margin) else "-"
        table.add_row(str(i), ",".join(f"{x:g}" for x in r.wrench), r.mode, margin, r.certificate)
    _console().print(table)


def _classify_summary(fixture, results, names, out: Path | None) -> None:  # type: ignore[no-untyped-def]
    """Counts per mode for a long list of wrenches (the rows go to --out)."""
    from collections import Counter

    counts = Counter(r.mode for r in results)
    typer.echo(one_line(f"{fixture.name}: {len(results)} wrenches on contacts {', '.join(names)}"))
    for mode, k in counts.most_common():
        typer.echo(f"  {mode:13s} {k:6d}  ({100 * k / len(results):.1f} %)")
    if out is None:
        typer.echo(
            f"(more than {CLASSIFY_TABLE_ROWS} wrenches: counts per mode only; --out FILE.csv writes one row per wrench)"
        )


def _write_classify_csv(path: Path, results: list[dict[str, Any]], ndof: int) -> None:
    import csv

    axes = AXES_3D if ndof == 6 else AXES_2D

    def write(p: Path) -> None:
        with open(p, "w", newline="", encoding="utf-8") as fh:
            out = csv.writer(fh)
            out.writerow(["index", *axes, "mode", "margin", "certificate"])
            for i, r in enumerate(results, 1):
                margin = "" if r["margin"] is None else f"{r['margin']:.6g}"
                out.writerow([i, *(f"{x:.12g}" for x in r["wrench"]), r["mode"], margin, r["certificate"]])

    write_output(path, write)


@app.command()
def classify(
    file: FileArg = None,
    wrench: Annotated[
        str | None,
        typer.Option("--wrench", help="Fx,Fy,Fz,Tx,Ty,Tz (2D: Fx,Fy,Mz), about the body origin, world axes."),
    ] = None,
    wrenches: Annotated[Path | None, typer.Option("--wrenches", help="CSV file, one wrench per line.")] = None,
    contacts: ContactsOpt = None,
    at: AtOpt = None,
    pose: PoseOpt = "start",
    backend: Annotated[
        str, typer.Option("--backend", help="clarabel (fast matrix path) or cvxpy (reference model).")
    ] = "clarabel",
    out: Annotated[
        Path | None,
        typer.Option("--out", help="Write one CSV row per wrench: index, wrench, mode, margin, certificate."),
    ] = None,
    force: Annotated[bool, typer.Option("--force", help="Overwrite --out if it exists.")] = False,
    json_out: JsonOpt = False,
) -> None:
    """Classify pushes: held, jammed, separates, slides, pivots, rolls or indeterminate.

    More than 50 wrenches print as counts per mode (the rows go to --out or --json).
    """
    from fixplan.jamming import classify as run
    from fixplan.locating import contact_set

    fixture = _load(file)
    if (wrench is None) == (wrenches is None):
        raise InputError("give exactly one of --wrench or --wrenches")
    n = fixture.ndof
    if wrench is not None:
        W = _wrench(wrench, "--wrench", n)[None, :]
    else:
        W = _read_wrench_csv(wrenches, n)  # type: ignore[arg-type]
    at_p = None if at is None else _numbers(at, "--at", fixture.dimension, limits.COORDINATE)
    p = _pose(fixture, pose)
    names = _names(contacts)
    check_distinct([("FILE", file), ("--wrenches", wrenches), ("--out", out)])
    target = None if out is None else _writable(out, force)
    cs = contact_set(fixture, p, names)
    if len(cs) == 0:
        from fixplan.locating import locator_gaps

        where = fixture.start if p == "start" else fixture.goal
        gaps = locator_gaps(fixture.workpiece, where, fixture.locators)
        nearest = ""
        if len(gaps):
            k = int(np.argmin(gaps))
            nearest = f"; the nearest is {fixture.locators[k].name}, {gaps[k]:.3g} m away"
        raise InputError(
            f"{fixture.source}: no contacts to analyse at the {pose} pose: no locator touches the workpiece"
            f"{nearest} (name hypothetical contacts with --contacts)"
        )
    for c in cs.contacts:
        if c.kind == "locator" and c.gap_m > fixture.tolerances.touch_m:
            _err(f"warning: {c.name} does not touch at the {pose} pose (gap {c.gap_m:.3g} m); analysed as if it did")
    # a long batch printed as compact JSON is encoded by the processes that classify it
    text = json_out and target is None and len(W) > 100
    results = run(fixture, W, names, at_p, pose=p, backend=backend, as_json="text" if text else json_out)
    if text:
        texts = [r for r in results if isinstance(r, str)]
        if len(texts) == len(results):
            head = _json_text({"file": fixture.source, "pose": pose, "contacts": cs.names, "results": []}, compact=True)
            sys.stdout.write(head[:-2] + ",".join(texts) + "]}\n")  # head ends with "results":[]}
            return
        results = [json.loads(r) if isinstance(r, str) else r for r in results]  # a non-finite number: reported below
    if target is not None:
        rows: list[dict[str, Any]] = [r if isinstance(r, dict) else r.to_json() for r in results]
        _write_classify_csv(target, rows, n)
    if json_out:
        _emit_json(
            {"file": fixture.source, "pose": pose, "contacts": cs.names, "results": results},
            compact=len(results) > 100,
        )
    else:
        if len(results) > CLASSIFY_TABLE_ROWS:
            _classify_summary(fixture, results, cs.names, target)
        else:
            _classify_table(fixture, results, cs.names)
        if target is not None:
            typer.echo(f"wrote {target}")


def _read_wrench_csv(path: Path, n: int) -> np.ndarray:
    """Wrenches from a CSV file, one per line; every bad line is reported (FILE: line K: ...)."""
    from fixplan.errors import Issue
    from fixplan.files import read_user_text

    text = read_user_text(path, expected=f"a CSV file of wrenches, {n} numbers per line")
    rows = []
    issues: list[Issue] = []
    ranges = limits.wrench_ranges(n)
    seen_data = False
    for lineno, line in enumerate(text.splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        try:
            rows.append(_numbers(line, "wrench", n, ranges))
        except InputError as exc:
            # a header line is allowed as the first non-empty line
            if not seen_data and not any(ch.isdigit() for ch in line.replace("Fx", "")):
                seen_data = True
                continue
            issues.append(Issue(f"line {lineno}", str(exc)))
        seen_data = True
        if len(issues) >= 100:
            issues.append(Issue("...", "more bad lines not shown (stopped after 100)"))
            break
    if issues:
        raise InputFileError(str(path), issues)
    if not rows:
        raise InputError(f"{path}: no wrenches (expected one wrench of {n} numbers per line)")
    return np.array(rows)


@app.command()
def search(
    file: FileArg = None,
    motion: Annotated[
        str,
        typer.Option(
            "--motion", help="Desired acceleration of the body origin: ax,ay,az,αx,αy,αz (2D: ax,ay,α) [m/s², rad/s²]."
        ),
    ] = "",
    contacts: ContactsOpt = None,
    at: AtOpt = None,
    pose: PoseOpt = "start",
    objective: Annotated[
        str,
        typer.Option(
            "--objective",
            help="margin: the largest least normal force; effort: the least push keeping each contact pressed by ≥ --min-margin.",
        ),
    ] = "margin",
    min_margin: Annotated[
        float | None,
        typer.Option(
            "--min-margin",
            help="Target least normal force [N]: kept by --objective effort (default: the part's weight); "
            "exit 1 when even the best margin falls short of it.",
        ),
    ] = None,
    json_out: JsonOpt = False,
) -> None:
    """Find the non-jamming push for a desired motion (exit 1 when none exists or --min-margin is not met)."""
    from fixplan.jamming import search_wrench

    fixture = _load(file)
    if not motion:
        raise InputError("--motion is required (the desired acceleration, e.g. 0.1,0,0,0,0,0)")
    m = _numbers(motion, "--motion", fixture.ndof, limits.ACCELERATION)
    at_p = None if at is None else _numbers(at, "--at", fixture.dimension, limits.COORDINATE)
    if objective not in ("margin", "effort"):
        raise InputError(f"--objective must be margin or effort, got {objective!r}")
    if min_margin is not None and not (0.0 <= min_margin <= limits.FORCE_MAX_N):
        raise InputError(f"--min-margin is {min_margin:g} (expected a force [N] in [0, {limits.FORCE_MAX_N:g}])")
    result = search_wrench(
        fixture, m, _names(contacts), pose=_pose(fixture, pose), at=at_p, objective=objective, min_margin_N=min_margin
    )
    if json_out:
        _emit_json(result.to_json())
    else:
        if result.found and result.wrench is not None:
            typer.echo(f"wrench: {','.join(f'{x:.6g}' for x in result.wrench)}")
            margin = "none (no kept contact)" if result.margin_N is None else f"{result.margin_N:.4g} N"
            typer.echo(f"margin: least normal force {margin}; check: {result.check.mode if result.check else '-'}")
            typer.echo("contacts: " + ", ".join(f"{k} {v}" for k, v in result.contact_roles.items()))
            if result.binding:
                typer.echo("binding limits: " + ", ".join(result.binding))
        typer.echo(result.reason)
    if not result.found or result.margin_target_met is False:
        raise typer.Exit(1)


AXES_3D = ("Fx", "Fy", "Fz", "Tx", "Ty", "Tz")
AXES_2D = ("Fx", "Fy", "Mz")


@app.command("map")
def map_(
    file: FileArg = None,
    axes: Annotated[
        str | None,
        typer.Option(
            "--axes",
            help="Two wrench components: 3D Fx,Fy,Fz,Tx,Ty,Tz (Mx,My,Mz also name the moments); 2D Fx,Fy,Mz. "
            "Default: Fx,Tz in 3D, Fx,Mz in 2D.",
            show_default=False,
        ),
    ] = None,
    range_: Annotated[str, typer.Option("--range", help="min:max for each axis, e.g. -20:20,-2:2.")] = "-10:10,-1:1",
    n: Annotated[int, typer.Option("--n", help="Grid points per axis.", min=2, max=1000)] = 100,
    wrench: Annotated[
        str | None, typer.Option("--wrench", help="Base wrench for the other components (default 0).")
    ] = None,
    contacts: ContactsOpt = None,
    at: AtOpt = None,
    pose: PoseOpt = "start",
    out: Annotated[
        Path,
        typer.Option(
            "--out", help="Image to write (.png, .svg or .pdf); a CSV with the same stem is written beside it."
        ),
    ] = Path("map.png"),
    force: Annotated[bool, typer.Option("--force", help="Overwrite existing output files.")] = False,
    json_out: JsonOpt = False,
) -> None:
    """Classify a grid of pushes over two wrench components and draw the jamming diagram."""
    from fixplan.mapping import jamming_map
    from fixplan.present.maps import save_map

    fixture = _load(file)
    names_all = AXES_3D if fixture.dimension == 3 else AXES_2D
    aliases = {"Mx": "Tx", "My": "Ty", "Mz": "Tz"} if fixture.dimension == 3 else {"Tz": "Mz"}
    if axes is None:
        axes = "Fx,Tz" if fixture.dimension == 3 else "Fx,Mz"
    ax = [aliases.get(a.strip(), a.strip()) for a in axes.split(",")]
    if len(ax) != 2 or any(a not in names_all for a in ax) or ax[0] == ax[1]:
        raise InputError(
            f"--axes expects two different names from {','.join(names_all)} for a {fixture.dimension}D fixture, "
            f"got {_shown(axes)}"
        )
    parts = range_.split(",")
    if len(parts) != 2:
        raise InputError(f"--range expects min:max,min:max, got {_shown(range_)}")
    bounds = []
    for part, name in zip(parts, ax, strict=True):
        rng = limits.wrench_ranges(fixture.ndof)[names_all.index(name)]
        lo_hi = _numbers(part.replace(":", ","), f"--range of {name}", 2, rng)
        if lo_hi[0] >= lo_hi[1]:
            raise InputError(f"--range {_shown(part)}: min must be below max")
        bounds.append((float(lo_hi[0]), float(lo_hi[1])))
    base = np.zeros(fixture.ndof) if wrench is None else _wrench(wrench, "--wrench", fixture.ndof)
    at_p = None if at is None else _numbers(at, "--at", fixture.dimension, limits.COORDINATE)
    if out.suffix.lower() not in (".png", ".svg", ".pdf"):
        raise InputError(
            f"--out {out}: expected an image file ending in .png, .svg or .pdf (the CSV is written beside it "
            "with the same stem)"
        )
    check_distinct([("FILE", file), ("--out", out), ("the CSV beside --out", out.with_suffix(".csv"))])
    png = _writable(out, force)
    csv_path = _writable(out.with_suffix(".csv"), force, "the CSV beside --out")
    result = jamming_map(
        fixture,
        (names_all.index(ax[0]), names_all.index(ax[1])),
        bounds,
        n,
        base=base,
        contacts=_names(contacts),
        at=at_p,
        pose=_pose(fixture, pose),
        progress=not json_out,
        axis_names=(ax[0], ax[1]),
    )
    write_output(png, lambda p: save_map(result, p, csv_path))
    counts = result.counts()
    summary: dict[str, Any] = {
        "png": str(png),
        "csv": str(csv_path),
        "axes": ax,
        "base_wrench": base,
        "counts": counts,
        "time_s": result.time_s,
        "per_classification_s": result.time_s / result.modes.size,
    }
    if json_out:
        _emit_json(summary)
    else:
        if wrench is not None:
            typer.echo(f"base wrench {','.join(f'{x:g}' for x in base)} (the components other than {ax[0]}, {ax[1]})")
        typer.echo(
            f"wrote {png} and {csv_path}: {result.modes.size} pushes in {result.time_s:.2f} s; "
            + ", ".join(f"{k} {v}" for k, v in counts.items())
        )


@app.command()
def simulate(
    file: FileArg = None,
    duration: Annotated[float, typer.Option("--duration", help="Simulated time [s].")] = 1.0,
    dt: Annotated[float | None, typer.Option("--dt", help="Time step [s] (default: [simulation] timestep).")] = None,
    wrench: Annotated[
        str | None, typer.Option("--wrench", help="Constant applied wrench about the body origin (default 0).")
    ] = None,
    tolerance: Annotated[
        float | None, typer.Option("--tolerance", help="NSGS residual (default: [simulation] tolerance).")
    ] = None,
    pose: PoseOpt = "start",
    out: Annotated[Path | None, typer.Option("--out", help="Write the trajectory as CSV.")] = None,
    every: Annotated[int, typer.Option("--every", help="Record every N-th step in --out.", min=1)] = 1,
    force: Annotated[
        bool,
        typer.Option("--force", help="Overwrite --out if it exists; run more than 10^7 steps."),
    ] = False,
    json_out: JsonOpt = False,
) -> None:
    """Simulate the workpiece among its locators (Moreau–Jean, exact Coulomb and soft-finger friction).

    A run longer than 10^7 steps (--duration / --dt) is refused unless --force.
    """
    from fixplan.engine.simulator import Simulator

    fixture = _load(file)
    if not limits.DURATION.contains(duration):
        raise InputError(f"--duration is {duration:g} (expected {limits.DURATION.expected()})")
    if dt is not None and not limits.TIMESTEP.contains(dt):
        raise InputError(f"--dt is {dt:g} (expected {limits.TIMESTEP.expected()})")
    if tolerance is not None and not limits.SOLVER_TOLERANCE.contains(tolerance):
        raise InputError(f"--tolerance is {tolerance:g} (expected {limits.SOLVER_TOLERANCE.expected()})")
    h = dt if dt is not None else fixture.simulation.timestep_s
    if duration > 0 and h > duration:
        raise InputError(f"--dt {h:g} s is longer than --duration {duration:g} s (expected a time step ≤ the duration)")
    n_steps = int(round(duration / h))
    if n_steps > limits.MAX_SIM_STEPS and not force:
        raise InputError(
            f"--duration {duration:g} s at a time step of {h:g} s is {n_steps:.3g} steps, more than the limit of "
            f"{limits.MAX_SIM_STEPS:.0e} (use --force to run it anyway)"
        )
    w = None if wrench is None else _wrench(wrench, "--wrench", fixture.ndof)
    check_distinct([("FILE", file), ("--out", out)])
    target = None if out is None else _writable(out, force)
    sim = Simulator(fixture, dt=dt, tolerance=tolerance)
    if _pose(fixture, pose) == "goal":
        sim.set_state(fixture.goal)
    bar: Any = None
    callback = None
    if n_steps >= 20000 and not json_out:
        import time

        started, done = 0.0, 0

        def callback(k: int) -> None:
            # the bar appears once the stepping has lasted 0.5 s (counted from the first report, after
            # the process loaded its compiled code): a shorter run (10^5 steps take about a second)
            # pays neither for it nor for importing rich.progress (~50 ms)
            nonlocal bar, done, started
            done += k
            if not started:
                started = time.perf_counter()
            elif bar is None and time.perf_counter() - started >= 0.5:
                from rich.console import Console
                from rich.progress import Progress

                bar = Progress(transient=True, console=Console(file=sys.stderr))
                bar.start()
                bar.add_task("simulating", total=n_steps, completed=done)
            elif bar is not None:
                bar.update(bar.task_ids[0], advance=k)

    try:
        traj = sim.run(duration, w, record_every=every, progress=callback)
    finally:
        if bar is not None:
            bar.stop()
    if target is not None:
        write_output(target, traj.to_csv)
    twist = sim.twist
    d = fixture.dimension
    result: dict[str, Any] = {
        "steps": sim.steps,
        "time": sim.time_s,
        "pose": sim.pose.to_json(),
        "velocity": {"linear": [float(x) for x in twist[:d]], "angular": [float(x) for x in twist[d:]]},
        "max_penetration": float(traj.max_penetration_m),
        "contacts": [c.to_json() for c in sim.contacts()],
        "solver": {
            "max_error": float(max(traj.error, default=0.0)),
            "mean_iterations": float(np.mean(traj.iterations)) if len(traj.iterations) else 0.0,
            "converged": bool(max(traj.error, default=0.0) <= sim.tolerance),
            "tolerance": sim.tolerance,
        },
        "wall_time_s": traj.wall_time_s,
    }
    if json_out:
        _emit_json(result)
        return
    typer.echo(
        f"{fixture.name}: {sim.steps} steps of {sim.dt:g} s in {traj.wall_time_s:.3f} s ({sim.steps / max(traj.wall_time_s, 1e-9):,.0f} steps/s)"
    )
    typer.echo(f"pose: {json.dumps(result['pose'])}")
    typer.echo(f"velocity: linear {result['velocity']['linear']} angular {result['velocity']['angular']}")
    typer.echo(
        f"max penetration: {traj.max_penetration_m:.3g} m; solver: max residual {result['solver']['max_error']:.3g}, mean sweeps {result['solver']['mean_iterations']:.2f}"
    )
    for c in sim.contacts():
        typer.echo(f"  {c.name:6s} {c.mode:9s} gap {c.gap_m: .3e} m  normal force {c.normal_force_N:.4g} N")
    if target is not None:
        typer.echo(f"wrote {target}")


# -- the perturbed world of `fixplan robust` (and `solve --perturb-seed`) -------------------------
SeedOpt = Annotated[int, typer.Option("--seed", help="Base seed of the perturbed worlds (sample k: rng([seed, k])).")]
MuSpreadOpt = Annotated[float, typer.Option("--mu-spread", help="Friction per locator μ(1 + u), u uniform in ±SPREAD.")]
PoseSigmaOpt = Annotated[
    str,
    typer.Option("--pose-sigma", help="Start-pose noise M,DEG: translation [m] in the resting plane, turn [deg]."),
]
LocatorSigmaOpt = Annotated[float, typer.Option("--locator-sigma", help="Locator position noise per axis [m].")]
ForceNoiseOpt = Annotated[
    float, typer.Option("--force-noise", help="Operator force noise, relative, per control period.")
]
LatencyOpt = Annotated[float, typer.Option("--latency-ms", help="Operator reaction delay [ms].")]
SchedulerOpt = Annotated[
    str | None,
    typer.Option("--scheduler", help="Dask scheduler address tcp://HOST:8786 (default: local worker processes)."),
]


def _robust_settings(
    *,
    samples: int = 20,
    seed: int,
    mu_spread: float,
    pose_sigma: str,
    locator_sigma: float,
    force_noise: float,
    latency_ms: float,
    accel: float = 1.0,
    margin: float | None = None,
    friction_margin: float = 0.1,
):  # type: ignore[no-untyped-def]
    from fixplan.robust import RobustSettings

    sigma = _numbers(pose_sigma, "--pose-sigma", 2)
    settings = RobustSettings(
        samples=samples,
        seed=seed,
        mu_spread=mu_spread,
        pose_sigma_m=float(sigma[0]),
        pose_sigma_deg=float(sigma[1]),
        locator_sigma_m=locator_sigma,
        force_noise=force_noise,
        latency_s=latency_ms * 1e-3,
        acceleration_mps2=accel,
        margin_N=margin,
        friction_margin=friction_margin,
    )
    settings.check()
    return settings


@app.command()
def solve(
    file: FileArg = None,
    order: Annotated[
        str | None, typer.Option("--order", help="Impose the order in which locators are added, e.g. S1,S2,E1.")
    ] = None,
    out: Annotated[Path | None, typer.Option("--out", help="Write the plan as JSON.")] = None,
    report: Annotated[
        Path | None,
        typer.Option(
            "--report",
            help="Write a Markdown report of the plan, and its figure beside it (plan.md -> plan.png).",
        ),
    ] = None,
    force: Annotated[
        bool, typer.Option("--force", help="Overwrite --out/--report (and the report's figure) if they exist.")
    ] = False,
    no_verify: Annotated[
        bool, typer.Option("--no-verify", help="Skip the simulated haptic verification (status: unverified).")
    ] = False,
    accel: Annotated[
        float,
        typer.Option("--accel", help="Acceleration each push asks for [m/s², mass-weighted].", min=1e-3, max=100.0),
    ] = 1.0,
    margin: Annotated[
        float | None,
        typer.Option(
            "--margin",
            help="Least normal force on the kept contacts [N] (default: the part's weight).",
            min=0.0,
            max=limits.FORCE_MAX_N,
        ),
    ] = None,
    friction_margin: Annotated[
        float,
        typer.Option(
            "--friction-margin", help="δ: pushes must work with friction anywhere in μ(1 ± δ).", min=0.0, max=1.0
        ),
    ] = 0.1,
    perturb_seed: Annotated[
        int | None,
        typer.Option(
            "--perturb-seed",
            help="Verify the nominal plan on perturbed world K of 'fixplan robust' (same --seed and options).",
            min=0,
        ),
    ] = None,
    seed: SeedOpt = 0,
    mu_spread: MuSpreadOpt = 0.2,
    pose_sigma: PoseSigmaOpt = "1e-3,1",
    locator_sigma: LocatorSigmaOpt = DEFAULT.robust.locator_sigma_m,
    force_noise: ForceNoiseOpt = 0.05,
    latency_ms: LatencyOpt = 2.0,
    batch: Annotated[
        Path | None,
        typer.Option("--batch", help='Solve every *.toml in DIR as Dask tasks: one table (or {"fixtures": [...]}).'),
    ] = None,
    scheduler: SchedulerOpt = None,
    json_out: JsonOpt = False,
) -> None:
    """Plan the loading of a full fixture and verify it in the simulated haptic loop.

    Status planned: a sequence was found and the feedback executor loaded the part in the loop
    (exit 0). unverified: a sequence was found but the loop did not confirm it, or --no-verify
    (exit 1). infeasible: no sequence, with the reason (exit 1). Bad input: exit 2.
    With --perturb-seed K the loop runs on perturbed world K of 'fixplan robust' instead of the
    nominal one. With --batch DIR: exit 0 only if every file is planned.
    """
    from fixplan.planner.solve import solve as run_solve
    from fixplan.present.plots import figure_path, save_plan_figure
    from fixplan.present.report import report_markdown

    if batch is not None:
        if file is not None or out is not None or report is not None or order is not None or perturb_seed is not None:
            raise InputError("--batch DIR takes no FILE, --out, --report, --order or --perturb-seed")
        _solve_batch(batch, not no_verify, accel, margin, friction_margin, scheduler, json_out)
        return
    if scheduler is not None:
        raise InputError("--scheduler is used with --batch (solve one file in-process)")
    perturb = None
    if perturb_seed is not None:
        if no_verify:
            raise InputError("--perturb-seed verifies the plan on a perturbed world: it cannot go with --no-verify")
        perturb = _robust_settings(
            seed=seed, mu_spread=mu_spread, pose_sigma=pose_sigma, locator_sigma=locator_sigma,
            force_noise=force_noise, latency_ms=latency_ms, accel=accel, margin=margin,
            friction_margin=friction_margin,
        )  # fmt: skip
    fixture = _load(file)
    figure = None if report is None else figure_path(report)
    # every output is checked before any is created (or any work done), and no two are one file
    check_distinct([("FILE", file), ("--out", out), ("--report", report), ("the report's figure", figure)])
    for option, path in (("--out", out), ("--report", report), ("the report's figure", figure)):
        if path is not None:
            _writable(path, force, option)
    target, report_path = out, report
    names = _names(order, "--order")
    if fixture.is_full:
        from fixplan.locating import contact_set

        cs = contact_set(fixture, "goal", [loc.name for loc in fixture.locators])
        rank = int(np.linalg.matrix_rank(cs.G, tol=DEFAULT.numerics.rank_tol))
        if rank < fixture.ndof:
            _err(
                f"warning: {fixture.source}: the locators do not determine the pose (rank G = {rank} < "
                f"{fixture.ndof}): a plan loads the part against them, but it can still move while touching all"
            )
    progress = None
    if not json_out:

        def progress(a) -> None:  # type: ignore[no-untyped-def]
            verdict = "ok" if a.success else f"fails: {a.reason}"
            typer.echo(f"  tried {{{', '.join(a.established)}}} + {a.target}: {verdict}", err=True)

    result = run_solve(
        fixture,
        order=names,
        run_verification=not no_verify and perturb is None,
        progress=progress,
        acceleration_mps2=accel,
        margin_N=margin,
        friction_margin=friction_margin,
    )
    perturbation = None
    if perturb is not None and perturb_seed is not None:
        from fixplan.robust import verify_on_world

        result, perturbation = verify_on_world(fixture, result, perturb_seed, perturb)
    payload = result.to_json()
    if perturbation is not None:
        payload["perturbation"] = perturbation
    if target is not None:
        write_text(target, _json_text(payload) + "\n")
    written = [] if target is None else [target]
    if report_path is not None:
        figures = []
        if figure is not None and result.status != "infeasible":
            # the figure first, so the report never links to a missing file
            write_output(figure, lambda p: save_plan_figure(result, fixture, p))
            figures.append(figure.name)  # beside the report: a relative link
            written.append(figure)
        write_text(report_path, report_markdown(result, fixture, figures=figures))
        written.append(report_path)
    if json_out:
        _emit_json(payload)
    else:
        if perturbation is not None:
            mu = ", ".join(f"{n} {x:.3g}" for n, x in perturbation["friction"].items())
            typer.echo(
                f"perturbed world {perturb_seed} (seed {seed}): friction {mu}; start {json.dumps(perturbation['start'])}"
            )
        _print_plan(result, payload, fixture)
        if written:
            typer.echo("wrote " + ", ".join(str(p) for p in written))
    if not result.ok:
        raise typer.Exit(1)


def _print_plan(result, payload: dict[str, Any], fixture) -> None:  # type: ignore[no-untyped-def]
    from rich.table import Table

    if payload["transitions"]:
        table = Table(title=f"{fixture.name}: loading plan")
        for col in ("#", "from + added", "motion", "push (mean)", "least margin [N]", "friction δ", "time [s]"):
            table.add_column(col)
        for i, tr in enumerate(payload["transitions"], 1):
            w = "-" if tr["wrench"] is None else ",".join(f"{x:.3g}" for x in tr["wrench"])
            margin = "-" if tr["margin"] is None else f"{tr['margin']:.3g}"
            rob = "-" if tr["friction_robustness"] is None else f"±{tr['friction_robustness']:.2g}"
            table.add_row(
                str(i),
                f"{{{','.join(tr['from'])}}} + {tr['added']}",
                tr["motion"],
                w,
                margin,
                rob,
                f"{tr['time_s']:.2f}",
            )
        _console().print(table)
    if not payload["transitions"] and result.status != "infeasible":
        typer.echo(f"{fixture.name}: the part starts located (every locator touches): there is nothing to plan")
    typer.echo(f"status: {result.status}" + (f" — {result.reason}" if result.reason else ""))
    v = result.verification
    if v is not None:
        ex = v.execution
        if ex is not None:
            c = ex.counts
            typer.echo(
                f"executed as a contact-state feedback policy: {c['solves']} wrench solves, {c['replans']} re-plans "
                f"({c['lost_contact']} lost, {c['unplanned_contact']} unplanned contacts), {c['stalls']} stalls"
            )
        gaps = [abs(g) for g in v.final_gaps_m.values()]
        parts = []
        if gaps:
            parts.append(f"final gaps ≤ {max(gaps):.2e} m")
        parts.append(f"max penetration {v.max_penetration_m:.2e} m")
        if v.max_push_force_N is not None:
            parts.append(f"push on the part ≤ {v.max_push_force_N:.3g} N, {v.max_push_torque_Nm:.3g} N·m")
        if v.tick_mean_us is not None:
            parts.append(
                f"tick compute mean {v.tick_mean_us:.0f} µs; {v.deadline_misses} ticks took longer than the 1 ms "
                "period to compute on this machine (simulated time does not slip, so this measures speed, not the verdict)"
            )
        typer.echo("; ".join(parts))
    typer.echo(f"time: {result.timings.get('total_s', 0.0):.2f} s")


def _solve_batch(directory: Path, verify: bool, accel: float, margin: float | None, friction_margin: float,
                 scheduler: str | None, json_out: bool) -> None:  # fmt: skip
    from rich.table import Table

    from fixplan.batch import fixture_files, solve_batch
    from fixplan.cluster import progress_bar

    files = fixture_files(directory)
    options = {"run_verification": verify, "acceleration_mps2": accel, "margin_N": margin,
               "friction_margin": friction_margin}  # fmt: skip
    with progress_bar("solving", len(files), enabled=not json_out) as progress:
        rows = solve_batch(files, options, scheduler=scheduler, progress=progress)
    if json_out:
        _emit_json({"fixtures": rows})
    else:
        table = Table(title=f"{directory}: {len(rows)} fixtures")
        for col in ("file", "status", "sequence", "reason", "time [s]"):
            table.add_column(col)
        for r in rows:
            seq = " → ".join("{" + ",".join(s) + "}" for s in r["sequence"]) or "-"
            table.add_row(Path(r["file"]).name, r["status"], seq, r["reason"] or "", f"{r['time_s']:.1f}")
        _console().print(table)
        planned = sum(r["status"] == "planned" for r in rows)
        typer.echo(f"{planned} of {len(rows)} planned")
    if any(r["status"] != "planned" for r in rows):
        raise typer.Exit(1)


@app.command()
def robust(
    file: FileArg = None,
    samples: Annotated[
        int, typer.Option("--samples", help="Perturbed worlds to verify the plan on (at most 10000).", min=1, max=10000)
    ] = 20,
    seed: SeedOpt = 0,
    mu_spread: MuSpreadOpt = 0.2,
    pose_sigma: PoseSigmaOpt = "1e-3,1",
    locator_sigma: LocatorSigmaOpt = DEFAULT.robust.locator_sigma_m,
    force_noise: ForceNoiseOpt = 0.05,
    latency_ms: LatencyOpt = 2.0,
    scheduler: SchedulerOpt = None,
    json_out: JsonOpt = False,
) -> None:
    """Verify one nominal plan on N perturbed worlds (friction, start pose, locators, operator).

    Prints the success rate with its 95 % Wilson interval, the failures by transition and cause,
    and for each failure the 'fixplan solve --perturb-seed K' command that replays it. Samples
    run as Dask tasks: local worker processes, or the cluster at --scheduler. Exit 0 when the
    run completed (whatever the rate), 1 when the nominal plan is infeasible, 2 bad input.
    """
    from fixplan.cluster import progress_bar
    from fixplan.robust import robust as run

    settings = _robust_settings(
        samples=samples, seed=seed, mu_spread=mu_spread, pose_sigma=pose_sigma, locator_sigma=locator_sigma,
        force_noise=force_noise, latency_ms=latency_ms,
    )  # fmt: skip
    fixture = _load(file)
    with progress_bar("perturbed worlds", samples, enabled=not json_out) as progress:
        result = run(fixture, settings, scheduler=scheduler, progress=progress)
    if json_out:
        _emit_json(result.to_json())
    else:
        _print_robust(result, fixture, file)
    if result.plan_status == "infeasible":
        raise typer.Exit(1)


def _print_robust(result, fixture, file: Path | None) -> None:  # type: ignore[no-untyped-def]
    import shlex

    from rich.table import Table

    from fixplan.robust import group_failures

    if result.plan_status == "infeasible":
        typer.echo(f"{fixture.name}: the nominal plan is infeasible — {result.plan_reason}; no samples run")
        return
    seq = " → ".join("{" + ", ".join(s) + "}" for s in result.sequence)
    typer.echo(f"{fixture.name}: nominal plan {seq or '(already located)'}")
    lo, hi = result.interval
    typer.echo(
        f"success rate {result.succeeded}/{result.samples} = {100 * result.success_rate:.0f} % "
        f"(95 % Wilson interval {100 * lo:.0f}–{100 * hi:.0f} %) in {result.wall_time_s:.1f} s"
    )
    if not result.failures:
        return
    table = Table(title="failures by transition and cause")
    for col in ("transition", "cause", "count", "seeds"):
        table.add_column(col)
    for tr, cause, seeds in group_failures(result.failures):
        table.add_row("-" if tr is None else str(tr), cause, str(len(seeds)), ", ".join(map(str, seeds)))
    _console().print(table)
    base = ["fixplan", "solve", *([] if file is None else [str(file)])]
    for f in result.failures:
        typer.echo(f"seed {f['seed']}: {f['cause']} — {f['reason']}")
        cmd = [*base, "--perturb-seed", str(f["seed"]), *result.settings.replay_options()]
        typer.echo(f"  replay: {shlex.join(cmd)}")


@app.command()
def view(
    file: FileArg = None,
    plan: Annotated[
        Path | None, typer.Option("--plan", help="A plan JSON from 'fixplan solve --out' to replay (for this FILE).")
    ] = None,
    out: Annotated[Path, typer.Option("--out", help="HTML page to write (self-contained).")] = Path("scene.html"),
    frames: Annotated[
        int, typer.Option("--frames", help="Most frames in the replay (a longer trace is subsampled).", min=2, max=2000)
    ] = 150,
    force: Annotated[bool, typer.Option("--force", help="Overwrite --out if it exists.")] = False,
    json_out: JsonOpt = False,
) -> None:
    """Write the scene as a self-contained HTML page: workpiece, locators, normals, forces, plan replay.

    With --plan the page replays the plan's simulated verification (or its knot poses); without
    it, the start pose at rest under gravity. The page embeds plotly.js and fetches nothing.
    """
    from fixplan.present.page import write_scene
    from fixplan.present.replay import read_plan, rest_replay
    from fixplan.present.scene import scene_figure, scene_info

    fixture = _load(file)
    check_distinct([("FILE", file), ("--plan", plan), ("--out", out)])
    target = _writable(out, force)
    replay = rest_replay(fixture) if plan is None else read_plan(plan, fixture)
    fig = scene_figure(fixture, replay, max_frames=frames)
    size = write_output(target, lambda p: write_scene(fig, p))
    info = scene_info(fig)
    if json_out:
        _emit_json(
            {"html": str(target), "bytes": size, "source": info.source, "frames": info.frames, "samples": info.samples}
        )
    else:
        what = f"{info.frames} frames of {info.samples} samples ({info.source})" if info.frames else "a still scene"
        typer.echo(f"wrote {target} ({size / 1e6:.1f} MB): {fixture.name}, {what}")


def _count(n: int, noun: str) -> str:
    """``1 contact``, ``3 contacts``."""
    return f"{n} {noun}" if n == 1 else f"{n} {noun}s"


@app.command()
def fclib(
    file: Annotated[Path, typer.Argument(help="An FCLib HDF5 problem (local or global, 3D or 2D).")],
    tol: Annotated[
        float, typer.Option("--tol", help="Target FCLib residual (natural map, relative).")
    ] = DEFAULT.engine.fclib_tolerance,
    max_iter: Annotated[
        int | None,
        typer.Option(
            "--max-iter",
            help="Iteration cap (sweeps for nsgs, rounds for socp/prox, steps for nsn; for auto: of every stage).",
            min=1,
        ),
    ] = None,
    time_limit: Annotated[
        float,
        typer.Option(
            "--time-limit",
            help="Seconds for reading and solving; at the limit the best answer so far is printed (exit 1).",
        ),
    ] = 60.0,
    solver: Annotated[str, typer.Option("--solver", help="auto, nsgs, socp, nsn, prox or nsgs-numpy.")] = "auto",
    json_out: JsonOpt = False,
) -> None:
    """Solve an FCLib frictional-contact problem; exit 0 converged, 1 not converged, 2 bad input.

    auto runs NSGS, then the SOCP fixed point, nonsmooth Newton and PROX, each when the one before
    stalls, and answers with the best reaction found, always within --time-limit.
    """
    from fixplan.engine.fclib import solve_fclib_file

    if not (tol > 0 and np.isfinite(tol)):
        raise InputError(f"--tol must be a positive number, got {tol}")
    if not time_limit > 0:
        raise InputError(f"--time-limit must be a positive number of seconds, got {time_limit}")
    result = solve_fclib_file(file, tol=tol, max_iter=max_iter, solver=solver, time_limit=time_limit)
    if json_out:
        _emit_json(
            {
                "file": str(file),
                "kind": result.kind,
                "contacts": result.n_contacts,
                "solver": result.solver,
                "error": float(result.error),
                "iterations": int(result.iterations),
                "converged": bool(result.converged),
                "time_s": float(result.time_s),
                "reason": result.extras.get("reason", ""),
                "stages": list(result.stages),
                "reaction": [float(x) for x in result.reaction],
                "velocity": [float(x) for x in result.velocity],
            },
            compact=True,
        )
    else:
        verdict = "converged" if result.converged else "NOT converged"
        typer.echo(
            f"{file}: {result.kind} problem, {_count(result.n_contacts, 'contact')}; {result.solver}: error "
            f"{result.error:.3g} after {_count(result.iterations, 'iteration')} in {result.time_s * 1e3:.1f} ms "
            f"({verdict}, tol {tol:g})"
        )
        for stage in result.stages:
            typer.echo(
                f"  {stage['method']}: {stage['start_error']:.3g} -> {stage['error']:.3g} in "
                f"{_count(stage['iterations'], 'iteration')}, {stage['time_s'] * 1e3:.1f} ms ({stage['status']})"
            )
        if not result.converged:
            typer.echo(f"  best answer kept: {result.extras.get('reason', '')}")
    if not result.converged:
        raise typer.Exit(1)


@app.command()
def generate(
    family: Annotated[str | None, typer.Argument(help="Fixture family (see --list).", show_default=False)] = None,
    count: Annotated[
        int, typer.Option("--count", help="How many fixtures (index 0 .. N-1), at most 10000.", min=1, max=10000)
    ] = 10,
    seed: Annotated[
        int, typer.Option("--seed", help="Seed ≥ 0; fixture k of a seed is the same whatever --count.", min=0)
    ] = 0,
    out: Annotated[
        Path | None, typer.Option("--out", help="Directory for FAMILY-sSEED-NNN.toml (created if absent).")
    ] = None,
    force: Annotated[bool, typer.Option("--force", help="Overwrite existing files.")] = False,
    list_: Annotated[bool, typer.Option("--list", help="List the families and exit.")] = False,
    json_out: JsonOpt = False,
) -> None:
    """Write seeded random fixtures of a family (box-321, plate-2d), each checked before it is written."""
    from fixplan.generate import FAMILIES, check_family, fixture_name
    from fixplan.generate import generate as run

    if list_:
        if json_out:
            _emit_json({"families": FAMILIES})
        else:
            for name, description in FAMILIES.items():
                typer.echo(f"{name}: {description}")
        return
    if family is None:
        raise InputError("give a FAMILY (one of: " + ", ".join(FAMILIES) + ") or --list")
    check_family(family)
    if out is None:
        raise InputError("--out DIR is required (the directory to write the fixtures into)")
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {out} is a file (expected a directory)")
    targets = [out / f"{fixture_name(family, seed, i)}.toml" for i in range(count)]
    for target in targets:
        _writable(target, force)
    fixtures = run(family, count, seed)
    for target, fx in zip(targets, fixtures, strict=True):
        write_text(target, fx.toml_text)
    if json_out:
        files = [
            {"name": fx.name, "path": str(t), "params": fx.params} for t, fx in zip(targets, fixtures, strict=True)
        ]
        _emit_json({"family": family, "seed": seed, "count": count, "out": str(out), "files": files})
    else:
        typer.echo(f"wrote {count} {family} fixtures (seed {seed}) to {out}: {targets[0].name} .. {targets[-1].name}")


@app.command()
def haptic(
    file: FileArg = None,
    device: Annotated[
        str,
        typer.Option(
            "--device", help="mouse (the viser gizmo), spacemouse, or udp[:PORT] (the bridge, docs/haptic.md)."
        ),
    ] = "mouse",
    port: Annotated[int, typer.Option("--port", help="Web app port (0: any free port).")] = 8080,
    record: Annotated[Path | None, typer.Option("--record", help="Write the session as a plan file.")] = None,
    force: Annotated[bool, typer.Option("--force", help="Overwrite --record if it exists.")] = False,
    no_browser: Annotated[bool, typer.Option("--no-browser", help="Do not open a browser.")] = False,
    host: Annotated[
        str, typer.Option("--host", help="Interface to serve on (not 127.0.0.1: needs --token).")
    ] = "127.0.0.1",
    token: Annotated[str | None, typer.Option("--token", help="Token a browser must present (--host).")] = None,
    until: Annotated[
        str | None, typer.Option("--until", help="End at the 'goal' or after SECONDS (default: at Ctrl-C).")
    ] = None,
    clock: Annotated[
        str, typer.Option("--clock", help="wall: 1 kHz real time; device: one tick per UDP pose (reproducible).")
    ] = "wall",
    json_out: JsonOpt = False,
) -> None:
    """Drive the part yourself: a live web app (viser) around the 1 kHz haptic loop, with the planner's guidance.

    Exit 0 when the session reached the goal (every locator pressed, at rest), 1 otherwise, 2 on bad input.
    """
    from fixplan.interactive.commands import run_haptic

    code = run_haptic(file, device=device, port=port, record=record, force=force, no_browser=no_browser,
                      host=host, token=token, until=until, json_out=json_out, clock=clock)  # fmt: skip
    if code:
        raise typer.Exit(code)


@app.command("device-sim")
def device_sim(
    host: Annotated[str, typer.Option("--host", help="Where 'fixplan haptic --device udp:PORT' runs.")] = "127.0.0.1",
    port: Annotated[int, typer.Option("--port", help="Its UDP port.")] = 7777,
    noise: Annotated[float, typer.Option("--noise", help="Relative force noise of the operator (every 10 ms).")] = 0.05,
    delay_ms: Annotated[float, typer.Option("--delay-ms", help="The operator's reaction delay [ms].")] = 50.0,
    duration: Annotated[float | None, typer.Option("--duration", help="Stop after S seconds.")] = None,
    push: Annotated[
        str | None, typer.Option("--push", help="Push this constant wrench instead of following the guidance.")
    ] = None,
    seed: Annotated[int, typer.Option("--seed", help="Noise seed.", min=0)] = 0,
    lockstep: Annotated[
        bool, typer.Option("--lockstep", help="One period per answer, no wall clock (with 'haptic --clock device').")
    ] = False,
    wait: Annotated[float, typer.Option("--wait", help="Seconds to wait for 'fixplan haptic' to answer.")] = 60.0,
    token: Annotated[
        str | None, typer.Option("--token", help="The token of 'fixplan haptic --host H --token T'.")
    ] = None,
    json_out: JsonOpt = False,
) -> None:
    """A simulated haptic device with a human-like operator, over the UDP bridge (exit 0 when fixplan reports the goal)."""
    from fixplan.interactive.commands import run_device_sim

    code = run_device_sim(host=host, port=port, noise=noise, delay_ms=delay_ms, duration=duration, push=push,
                          seed=seed, json_out=json_out, lockstep=lockstep, wait_s=wait, token=token)  # fmt: skip
    if code:
        raise typer.Exit(code)


@app.command("verify")
def verify_plan(
    plan: Annotated[Path, typer.Argument(help="A plan file ('fixplan solve --out' or 'fixplan haptic --record').")],
    fixture: Annotated[
        Path | None,
        typer.Option("--fixture", help="The fixture (default: the one the plan names, else the bundled box)."),
    ] = None,
    json_out: JsonOpt = False,
) -> None:
    """Re-run a plan in the simulated haptic loop: a recorded session's pushes, or a solved plan's executor.

    Exit 0 when the part reaches the goal without jamming, 1 when not, 2 on bad input.
    """
    from fixplan.interactive.commands import run_verify

    code = run_verify(plan, fixture, json_out)
    if code:
        raise typer.Exit(code)


def main(argv: list[str] | None = None) -> int:
    """Entry point: run the app and turn every expected failure into one line and exit 2."""
    import warnings

    args = sys.argv[1:] if argv is None else list(argv)
    if not args:  # bare `fixplan`: the help, on stdout, as `fixplan --help` prints it
        args = ["--help"]
    try:
        # numpy's RuntimeWarnings (overflow, invalid value) are not messages for users: results are
        # checked for finiteness where they leave fixplan (strict JSON, the solvers' own checks)
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore", RuntimeWarning)
            rv = app(args=args, prog_name="fixplan", standalone_mode=False)
    except (FixtureError, InputFileError) as exc:
        for issue in exc.issues:
            typer.echo(issue.format(exc.source), err=True)
        return 2
    except FixplanError as exc:
        _err(str(exc))
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


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
