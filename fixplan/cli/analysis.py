"""Commands that analyse a fixture: validate, classify, search, map, simulate."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import Annotated, Any, Literal, cast

import numpy as np
import typer

from fixplan import limits
from fixplan.cli._app import (
    AtOpt,
    ContactsOpt,
    FileArg,
    JsonOpt,
    PoseOpt,
    _console,
    _emit_json,
    _err,
    _json_text,
    _load,
    _names,
    _numbers,
    _pose,
    _shown,
    _wrench,
    _writable,
    app,
)
from fixplan.cli.flags import with_flags, with_flags_in
from fixplan.errors import FixtureError, InputError, one_line, quote_number
from fixplan.files import check_distinct, document_stream, write_output


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
    from fixplan.summary import summarize

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
        summary = summarize(fixture)
        for issue in summary.warnings:
            typer.echo(issue.format(str(path)), err=True)
        typer.echo(one_line(f"{path}: ok ({summary.kind}{summary.note})"))
        if verbose:
            for line in summary.details:
                typer.echo(one_line(f"  {line}"))
            if fixture.pins and fixture.is_full:
                for line in _clearance_lines(fixture):
                    typer.echo(one_line(f"  {line}"))
    if bad:
        raise typer.Exit(2)


def _clearance_lines(fixture) -> list[str]:  # type: ignore[no-untyped-def]
    """The range of located poses the pins' clearances allow, or why it is not there."""
    from fixplan.clearance import clearance_pose_range
    from fixplan.errors import FixplanError

    try:
        return clearance_pose_range(fixture).lines()
    except FixplanError as exc:
        return [f"clearance: not computed ({exc})"]


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
        margin = f"{r.balance_residual:.3g}" if math.isfinite(r.balance_residual) else "-"
        mode = f"{r.mode} (by wedging)" if r.certificate == "wedging" else r.mode
        table.add_row(str(i), ",".join(f"{x:g}" for x in r.wrench), mode, margin, r.certificate)
    _console().print(table)
    for i, r in enumerate(results, 1):
        if r.certificate == "wedging":
            typer.echo(one_line(f"{i}: {r.reason}"))


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
    from fixplan.files import read_wrench_csv
    from fixplan.jamming import classify as run
    from fixplan.locating import contact_set

    fixture = _load(file)
    if (wrench is None) == (wrenches is None):
        raise InputError("give exactly one of --wrench or --wrenches")
    n = fixture.ndof
    if wrench is not None:
        W = _wrench(wrench, "--wrench", n)[None, :]
    else:
        W = read_wrench_csv(wrenches, n)  # type: ignore[arg-type]
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
            document_stream().write(head[:-2] + ",".join(texts) + "]}\n")  # head ends with "results":[]}
            return
        results = [json.loads(r) if isinstance(r, str) else r for r in results]  # a non-finite number: reported below
    if target is not None:
        rows: list[dict[str, Any]] = [r if isinstance(r, dict) else r.to_json() for r in results]
        _write_classify_csv(target, rows, n)
    wedging = _pin_wedging(cs) if fixture.has_pins else None
    if json_out:
        doc = {"file": fixture.source, "pose": pose, "contacts": cs.names, "results": results}
        if wedging is not None:
            doc["wedging"] = wedging
        _emit_json(doc, compact=len(results) > 100)
    else:
        if len(results) > CLASSIFY_TABLE_ROWS:
            _classify_summary(fixture, results, cs.names, target)
        else:
            _classify_table(fixture, results, cs.names)
        if wedging is not None and wedging["wedges"]:
            typer.echo(
                f"wedged: {', '.join(wedging['contacts'])} can hold forces that balance each other with no push "
                "(the friction cones overlap along the line joining them, Whitney 1982): pressed in, the part "
                "stays stuck whatever the push"
            )
        if target is not None:
            typer.echo(f"wrote {target}")


def _pin_wedging(cs: Any) -> dict[str, Any] | None:
    """Whether a pin's or bore's contacts can wedge (:func:`fixplan.jamming.wedge.wedge_force`): two or more of one owner.

    None when no pin or bore touches at two places (one contact cannot wedge on its own).
    """
    from collections import Counter

    from fixplan.jamming.wedge import wedge_force
    from fixplan.settings import DEFAULT_TOLERANCES

    owners = Counter(c.owner for c in cs.contacts if c.kind in ("pin", "bore"))
    several = sorted(o for o, k in owners.items() if k >= 2)
    if not several:
        return None
    force = wedge_force(cs)
    wedges = force is not None and force > DEFAULT_TOLERANCES.wedge_force
    touching = [c.name for c in cs.contacts if c.owner in several]
    return {"wedges": wedges, "force": force, "contacts": touching}


AXES_3D = ("Fx", "Fy", "Fz", "Tx", "Ty", "Tz")
AXES_2D = ("Fx", "Fy", "Mz")


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
            help="effort (default): the least push keeping each kept contact pressed by ≥ --min-margin; "
            "margin: the largest least normal force (presses as hard as the hand's headroom allows).",
        ),
    ] = "effort",
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
        raise InputError(
            f"--min-margin is {quote_number(min_margin)} (expected a force [N] in [0, {limits.FORCE_MAX_N:g}])"
        )
    result = search_wrench(
        fixture,
        m,
        _names(contacts),
        pose=_pose(fixture, pose),
        at=at_p,
        objective=cast(Literal["margin", "effort"], objective),  # checked above
        min_margin_N=min_margin,
    )
    if json_out:
        _emit_json(with_flags_in(result.to_json()))
    else:
        if result.found and result.wrench is not None:
            typer.echo(f"wrench: {','.join(f'{x:.6g}' for x in result.wrench)}")
            margin = "none (no kept contact)" if result.margin_N is None else f"{result.margin_N:.4g} N"
            typer.echo(f"margin: least normal force {margin}; check: {result.check.mode if result.check else '-'}")
            typer.echo("contacts: " + ", ".join(f"{k} {v}" for k, v in result.contact_roles.items()))
            if result.binding:
                typer.echo("binding limits: " + ", ".join(result.binding))
            if result.force_fraction is not None and result.torque_fraction is not None:
                head = f"{result.limit_fraction:.0%} headroom"
                where = f"within the {head}" if result.within_fraction else f"beyond the {head}: none exists inside it"
                typer.echo(
                    f"push: {result.force_fraction:.0%} of max_force, {result.torque_fraction:.0%} of max_torque ({where})"
                )
        typer.echo(with_flags(result.reason))
    if not result.found or result.margin_target_met is False:
        raise typer.Exit(1)


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
    from fixplan.present.maps import save_map, save_map_csv

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
    save_map(result, png)  # each through files.write_output
    save_map_csv(result, csv_path)
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
    from fixplan.engine.outcome import RunOutcome
    from fixplan.engine.simulator import Simulator

    fixture = _load(file)
    if not limits.DURATION.contains(duration):
        raise InputError(f"--duration is {quote_number(duration)} (expected {limits.DURATION.expected()})")
    if dt is not None and not limits.TIMESTEP.contains(dt):
        raise InputError(f"--dt is {quote_number(dt)} (expected {limits.TIMESTEP.expected()})")
    if tolerance is not None and not limits.SOLVER_TOLERANCE.contains(tolerance):
        raise InputError(f"--tolerance is {quote_number(tolerance)} (expected {limits.SOLVER_TOLERANCE.expected()})")
    h = dt if dt is not None else fixture.simulation.timestep_s
    if duration > 0 and h > duration:
        raise InputError(
            f"--dt {quote_number(h)} s is longer than --duration {quote_number(duration)} s (expected a time step ≤ the duration)"
        )
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
        traj.to_csv(target)  # through files.write_output
    outcome = RunOutcome.of(sim, traj)
    if json_out:
        _emit_json(outcome.to_json())
        return
    typer.echo(
        f"{fixture.name}: {outcome.steps} steps of {outcome.dt:g} s in {outcome.wall_time_s:.3f} s "
        f"({outcome.steps / max(outcome.wall_time_s, 1e-9):,.0f} steps/s)"
    )
    velocity = outcome.to_json()["velocity"]
    typer.echo(f"pose: {json.dumps(outcome.pose.to_json())}")
    typer.echo(f"velocity: linear {velocity['linear']} angular {velocity['angular']}")
    typer.echo(
        f"max penetration: {outcome.max_penetration_m:.3g} m; solver: max residual {outcome.max_error:.3g}, "
        f"mean sweeps {outcome.mean_iterations:.2f}"
    )
    for c in outcome.contacts:
        typer.echo(f"  {c.name:6s} {c.mode:9s} gap {c.gap_m: .3e} m  normal force {c.normal_force_N:.4g} N")
    for o in outcome.obstacles:
        push_N = float(np.linalg.norm(o.force_world))
        typer.echo(f"  {o.name:6s} obstacle  gap {o.gap_m: .3e} m  force {push_N:.4g} N (collision only)")
    if target is not None:
        typer.echo(f"wrote {target}")
