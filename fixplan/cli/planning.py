"""Commands that plan a load and show it: solve, robust, view."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from fixplan import limits
from fixplan.cli._app import (
    FileArg,
    JsonOpt,
    _console,
    _emit_json,
    _err,
    _json_text,
    _load,
    _names,
    _numbers,
    _writable,
    app,
)
from fixplan.cli.flags import with_flags, with_flags_in
from fixplan.errors import FixplanError, InputError, one_line
from fixplan.files import check_distinct, write_text
from fixplan.settings import DEFAULT, Settings

if TYPE_CHECKING:
    from fixplan.model import Fixture
    from fixplan.planner.plan import Plan, Verification
    from fixplan.robust import RobustSettings

# -- the perturbed world of `fixplan robust` (and `solve --perturb-seed`) -------------------------
SeedOpt = Annotated[int, typer.Option("--seed", help="Base seed of the perturbed worlds (sample k: rng([seed, k])).")]
MuSpreadOpt = Annotated[float, typer.Option("--mu-spread", help="Friction per locator μ(1 + u), u uniform in ±SPREAD.")]
PoseSigmaOpt = Annotated[
    str | None,
    typer.Option(
        "--pose-sigma",
        help="Start-pose noise M,DEG: translation [m] in the resting plane, turn [deg] "
        "(default 1e-3,1; with [robot] repeatability R: R,1).",
    ),
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


def _solve_settings(accel: float, margin: float | None, friction_margin: float) -> Settings:
    """The settings ``fixplan solve`` plans and verifies with: the ``haptic`` profile with the pushes' options."""
    from fixplan.settings import HAPTIC, ExecutionSettings

    return HAPTIC.with_(execution=ExecutionSettings(accel_mps2=accel, friction_margin=friction_margin, margin_N=margin))


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
    pose_sigma: PoseSigmaOpt = None,
    locator_sigma: LocatorSigmaOpt = DEFAULT.robust.locator_sigma_m,
    force_noise: ForceNoiseOpt = 0.05,
    latency_ms: LatencyOpt = 2.0,
    batch: Annotated[
        Path | None,
        typer.Option("--batch", help='Solve every *.toml in DIR as Dask tasks: one table (or {"fixtures": [...]}).'),
    ] = None,
    scheduler: SchedulerOpt = None,
    clamp: Annotated[
        bool,
        typer.Option(
            "--clamp",
            help="Continue with the clamping stage (the fixture's [[clamp]] and [[load]]: fixplan clamp) once loaded.",
        ),
    ] = False,
    json_out: JsonOpt = False,
) -> None:
    """Plan the loading of a full fixture and verify it in the simulated haptic loop.

    Status planned: a sequence was found and the feedback executor loaded the part in the loop
    (exit 0). unverified: a sequence was found but the loop did not confirm it, or --no-verify
    (exit 1). infeasible: no sequence, with the reason (exit 1). Bad input: exit 2.
    With --perturb-seed K the loop runs on perturbed world K of 'fixplan robust' instead of the
    nominal one. With --batch DIR: exit 0 only if every file is planned. With --clamp the plan
    goes on with the clamping stage (its least forces, order and engine check; exit 1 unless it holds).
    """
    from fixplan.fixture import default_fixture_path, fixture_stamp
    from fixplan.planner.solve import solve as run_solve
    from fixplan.present.plots import figure_path, save_plan_figure
    from fixplan.present.report import report_markdown

    if batch is not None:
        if (
            file is not None
            or out is not None
            or report is not None
            or order is not None
            or perturb_seed is not None
            or clamp
        ):
            raise InputError("--batch DIR takes no FILE, --out, --report, --order, --perturb-seed or --clamp")
        _solve_batch(batch, not no_verify, accel, margin, friction_margin, scheduler, json_out)
        return
    if scheduler is not None:
        raise InputError("--scheduler is used with --batch (solve one file in-process)")
    perturb = None
    if perturb_seed is not None:
        if no_verify:
            raise InputError("--perturb-seed verifies the plan on a perturbed world: it cannot go with --no-verify")
    fixture = _load(file)
    if fixture.has_pins and order:
        raise InputError(
            f"{fixture.source}: --order is not supported with pins or bores yet "
            "(expected 'fixplan solve FILE': the insertion's order is the pins' engagement heights)"
        )
    if perturb_seed is not None:
        perturb = _robust_settings(
            seed=seed, mu_spread=mu_spread, pose_sigma=_pose_sigma(pose_sigma, fixture), locator_sigma=locator_sigma,
            force_noise=force_noise, latency_ms=latency_ms, accel=accel, margin=margin,
            friction_margin=friction_margin,
        )  # fmt: skip
    if clamp and not fixture.clamps:
        raise InputError(
            f"{fixture.source}: --clamp: no [[clamp]] entries (expected the clamps to apply after loading)"
        )
    # the plan names its fixture (path and hash of the bytes read) so that 'fixplan verify PLAN' finds it
    stamp = fixture_stamp(file if file is not None else default_fixture_path())
    figure = None if report is None else figure_path(report)
    # every output is checked before any is created (or any work done), and no two are one file
    check_distinct([("FILE", file), ("--out", out), ("--report", report), ("the report's figure", figure)])
    for option, path in (("--out", out), ("--report", report), ("the report's figure", figure)):
        if path is not None:
            _writable(path, force, option)
    target, report_path = out, report
    names = _names(order, "--order")
    if fixture.is_full and not fixture.has_pins:
        from fixplan.summary import goal_rank

        rank = goal_rank(fixture)
        if rank < fixture.ndof - len(fixture.free_motions):  # a symmetric part's spin is free by design
            _err(
                f"warning: {fixture.source}: the locators do not determine the pose (rank G = {rank} < "
                f"{fixture.ndof}): a plan loads the part against them, but it can still move while touching all"
            )
    progress = None
    if not json_out:

        def progress(a) -> None:  # type: ignore[no-untyped-def]
            verdict = "ok" if a.success else f"fails: {with_flags(a.reason)}"
            if a.stage == "precheck":
                verdict = f"cheap check fails, tried after the others: {with_flags(a.reason)}"
            elif a.stage == "path":
                verdict = "a path (its pushes are searched if its sequence is chosen)"
            added = "{" + ",".join(a.added) + "}" if a.together else a.target
            typer.echo(f"  tried {{{', '.join(a.established)}}} + {added}: {verdict}", err=True)

    result = run_solve(
        fixture,
        order=names,
        run_verification=not no_verify,  # with --perturb-seed: the plan solve delivers, as robust studies it
        progress=progress,
        settings=_solve_settings(accel, margin, friction_margin),
    )
    perturbation = None
    if perturb is not None and perturb_seed is not None:
        from fixplan.robust import verify_on_world

        result, perturbation = verify_on_world(fixture, result, perturb_seed, perturb)
    plan = result.plan.with_extras(**stamp)
    if fixture.pins:
        plan = plan.with_extras(clearance_pose_range=_clearance_json(fixture))
    if perturbation is not None:
        plan = plan.with_extras(perturbation=perturbation)
    clamped = None
    if clamp:
        from fixplan.clamping import analyse_clamping

        if plan.status == "infeasible":  # nothing loaded: no clamping stage
            plan = plan.with_extras(clamping=None)
        else:  # the part at its located pose, where the plan ends
            clamped = analyse_clamping(fixture, verify=not no_verify)
            plan = plan.with_extras(clamping=clamped.to_json())
    payload = with_flags_in(plan.to_json())  # the reasons name the flags this command was given
    if target is not None:
        write_text(target, _json_text(payload) + "\n")
    written = [] if target is None else [target]
    if report_path is not None:
        figures = []
        if figure is not None and plan.status != "infeasible":
            # the figure first, so the report never links to a missing file
            save_plan_figure(plan, fixture, figure)  # through files.write_output
            figures.append(figure.name)  # beside the report: a relative link
            written.append(figure)
        write_text(report_path, with_flags(report_markdown(plan, fixture, figures=figures)))
        written.append(report_path)
    if json_out:
        _emit_json(payload)
    else:
        if perturbation is not None:
            mu = ", ".join(f"{n} {x:.3g}" for n, x in perturbation["friction"].items())
            typer.echo(
                f"perturbed world {perturb_seed} (seed {seed}): friction {mu}; start {json.dumps(perturbation['start'])}"
            )
        _print_plan(plan, fixture, {"accel": accel, "friction_margin": friction_margin})
        if clamped is not None:
            typer.echo(one_line(f"clamping: {clamped.reason}"))
        if written:
            typer.echo("wrote " + ", ".join(str(p) for p in written))
    if not plan.ok or (clamp and (clamped is None or not clamped.holds)):
        raise typer.Exit(1)


def _print_plan(plan: Plan, fixture: Fixture, options: dict[str, float] | None = None) -> None:
    from rich.table import Table

    if plan.transitions:
        # the push gets a line of its own below the table: six numbers in a cell were cut at 80 columns;
        # narrow terminals wrap the other cells instead of cutting them
        table = Table(title=f"{fixture.name}: loading plan")
        for col in ("#", "from + added", "motion", "least margin [N]", "friction δ", "peak push [%]", "time [s]"):
            table.add_column(col, overflow="fold")
        for i, tr in enumerate(plan.transitions, 1):
            margin = "-" if tr.margin_N is None else f"{tr.margin_N:.3g}"
            rob = "-" if tr.friction_robustness is None else f"±{tr.friction_robustness:.2g}"
            # the largest planned push as a fraction of the hand's limits: force, torque
            peak = (
                "-"
                if tr.peak_force_fraction is None or tr.peak_torque_fraction is None
                else f"{100 * tr.peak_force_fraction:.0f}, {100 * tr.peak_torque_fraction:.0f}"
            )
            table.add_row(
                str(i),
                f"{{{','.join(tr.from_state)}}} + {tr.added_label}",
                tr.motion,
                margin,
                rob,
                peak,
                f"{tr.time_s:.2f}",
            )
        _console().print(table)
        axes = "Fx, Fy, Fz, Tx, Ty, Tz" if fixture.dimension == 3 else "Fx, Fy, Mz"
        typer.echo(f"push (mean over the transition) [{axes}; N, N·m]:")
        for i, tr in enumerate(plan.transitions, 1):
            w = "none (no contact to push against)" if tr.wrench is None else ", ".join(f"{x:.3g}" for x in tr.wrench)
            typer.echo(f"  {i}: {w}")
    if not plan.transitions and plan.status != "infeasible":
        typer.echo(f"{fixture.name}: the part starts located (every locator touches): there is nothing to plan")
    typer.echo(f"status: {plan.status}" + (f" — {with_flags(plan.reason)}" if plan.reason else ""))
    if plan.status == "infeasible" and "too weak" in plan.reason and options is not None:
        # the force named is the push the planner asked for, not the least that moves the part
        typer.echo(
            f"note: that force is for a push that accelerates the part at {options['accel']:g} m/s² (--accel) and "
            f"works for friction in μ(1 ± {options['friction_margin']:g}) (--friction-margin); a slower, less robust "
            "push needs less: '--accel 0.01 --friction-margin 0' shows the least"
        )
    v = plan.verification
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
        if v.peak_force_fraction is not None:
            parts.append(_headroom_line(v))
        if v.tick_mean_us is not None:
            parts.append(
                f"tick compute mean {v.tick_mean_us:.0f} µs; {v.deadline_misses} ticks took longer than the 1 ms "
                "period to compute on this machine (simulated time does not slip, so this measures speed, not the verdict)"
            )
        typer.echo("; ".join(parts))
    typer.echo(f"time: {plan.timings.get('total_s', 0.0):.2f} s")


def _headroom_line(v: Verification) -> str:
    """The executor's peak push as fractions of the hand's limits, and the ticks above the headroom."""
    frac = v.limit_fraction if v.limit_fraction is not None else 1.0
    text = (
        f"commanded push peaks at {v.peak_force_fraction:.0%} of max_force, {v.peak_torque_fraction:.0%} of max_torque "
        f"(headroom: within {frac:.0%}; {v.ticks_above_fraction} ticks above it"
    )
    ex = v.execution
    if ex is not None and ex.beyond_fraction_solves:
        text += f", {ex.beyond_fraction_solves} solves found no push inside it"
    return text + ")"


def _solve_batch(directory: Path, verify: bool, accel: float, margin: float | None, friction_margin: float,
                 scheduler: str | None, json_out: bool) -> None:  # fmt: skip
    from rich.table import Table

    from fixplan.batch import fixture_files, solve_batch
    from fixplan.cluster import progress_bar

    files = fixture_files(directory)
    options = {"run_verification": verify, "settings": _solve_settings(accel, margin, friction_margin)}
    with progress_bar("solving", len(files), enabled=not json_out) as progress:
        rows = with_flags_in(solve_batch(files, options, scheduler=scheduler, progress=progress))
    if json_out:
        _emit_json({"fixtures": rows})
    else:
        table = Table(title=f"{directory}: {len(rows)} fixtures")
        # file names stay whole (the rows must be told apart); the other cells wrap, never cut; the
        # reasons, long sentences, follow the table, one line each
        names = [Path(r["file"]).name for r in rows]
        table.add_column("file", no_wrap=True, min_width=max(map(len, names), default=4))
        for col in ("status", "sequence", "time [s]"):
            table.add_column(col, overflow="fold")
        for name, r in zip(names, rows, strict=True):
            seq = " → ".join("{" + ",".join(s) + "}" for s in r["sequence"]) or "-"
            table.add_row(name, r["status"], seq, f"{r['time_s']:.1f}")
        _console().print(table)
        for name, r in zip(names, rows, strict=True):
            if r["reason"]:
                typer.echo(one_line(f"{name}: {r['reason']}"))
        planned = sum(r["status"] == "planned" for r in rows)
        typer.echo(f"{planned} of {len(rows)} planned")
    if any(r["status"] != "planned" for r in rows):
        raise typer.Exit(1)


def _clearance_json(fixture: Fixture) -> dict[str, Any]:
    """``solve``'s ``clearance_pose_range``: the located poses the pins' clearances allow, or why not."""
    from fixplan.clearance import clearance_pose_range

    try:
        return clearance_pose_range(fixture).to_json()
    except FixplanError as exc:
        return {"error": str(exc)}


def _pose_sigma(given: str | None, fixture: Any) -> str:
    """``--pose-sigma`` as given, else the robot's repeatability with 1 degree, else 1 mm and 1 degree."""
    if given is not None:
        return given
    if fixture.has_pins:  # pins: three times the largest radial play (errors beyond the clearance), 0.1 degree
        from fixplan.locating import inserts

        return f"{3.0 * max(i.play_m for i in inserts(fixture))!r},0.1"
    robot = fixture.robot
    if robot is not None and robot.repeatability_m is not None:
        return f"{robot.repeatability_m!r},1"
    return "1e-3,1"


@app.command()
def robust(
    file: FileArg = None,
    samples: Annotated[
        int, typer.Option("--samples", help="Perturbed worlds to verify the plan on (at most 10000).", min=1, max=10000)
    ] = 20,
    seed: SeedOpt = 0,
    mu_spread: MuSpreadOpt = 0.2,
    pose_sigma: PoseSigmaOpt = None,
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

    fixture = _load(file)
    settings = _robust_settings(
        samples=samples, seed=seed, mu_spread=mu_spread, pose_sigma=_pose_sigma(pose_sigma, fixture),
        locator_sigma=locator_sigma, force_noise=force_noise, latency_ms=latency_ms,
    )  # fmt: skip
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
        cmd = [*base, "--perturb-seed", str(f["seed"]), *_replay_options(result.settings)]
        typer.echo(f"  replay: {shlex.join(cmd)}")


def _replay_options(settings: RobustSettings) -> list[str]:
    """The command-line options that reproduce ``settings`` (those not at their defaults)."""
    from fixplan.robust import RobustSettings

    d = RobustSettings()
    s = settings
    out: list[str] = []
    if s.seed != d.seed:
        out += ["--seed", str(s.seed)]
    if s.mu_spread != d.mu_spread:
        out += ["--mu-spread", f"{s.mu_spread:g}"]
    if (s.pose_sigma_m, s.pose_sigma_deg) != (d.pose_sigma_m, d.pose_sigma_deg):
        out += ["--pose-sigma", f"{s.pose_sigma_m:g},{s.pose_sigma_deg:g}"]
    if s.locator_sigma_m != d.locator_sigma_m:
        out += ["--locator-sigma", f"{s.locator_sigma_m:g}"]
    if s.force_noise != d.force_noise:
        out += ["--force-noise", f"{s.force_noise:g}"]
    if s.latency_s != d.latency_s:
        out += ["--latency-ms", f"{s.latency_s * 1e3:g}"]
    if s.acceleration_mps2 != d.acceleration_mps2:
        out += ["--accel", f"{s.acceleration_mps2:g}"]
    if s.margin_N is not None:
        out += ["--margin", f"{s.margin_N:g}"]
    if s.friction_margin != d.friction_margin:
        out += ["--friction-margin", f"{s.friction_margin:g}"]
    return out


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
    clamp_forces = None
    if fixture.clamps:  # the clamps at their least forces (fixplan clamp's program), drawn at the located pose
        from fixplan.clamping import analyse_clamping

        try:
            clamp_forces = analyse_clamping(fixture, verify=False).forces_N or None
        except FixplanError:  # too many clamps for the order search: drawn without their forces
            clamp_forces = None
    fig = scene_figure(fixture, replay, max_frames=frames, clamp_forces_N=clamp_forces)
    size = write_scene(fig, target)  # through files.write_output
    info = scene_info(fig)
    if json_out:
        _emit_json(
            {"html": str(target), "bytes": size, "source": info.source, "frames": info.frames, "samples": info.samples}
        )
    else:
        what = f"{info.frames} frames of {info.samples} samples ({info.source})" if info.frames else "a still scene"
        typer.echo(f"wrote {target} ({size / 1e6:.1f} MB): {fixture.name}, {what}")
