"""Figures of a loading plan: contact forces, gaps, the applied wrench and the contact states over time.

``fixplan solve --report plan.md`` writes ``plan.png`` beside the report (:func:`figure_path`)
and links it from the Markdown. The figure (:func:`plan_figure`) has one panel per quantity,
sharing the time axis [s]; dashed vertical lines mark the planned transitions' boundaries
(``cumsum(PlanResult.durations_s)``) in every panel.

With a verification trace (``PlanResult.verification.trace``), the panels are

1. ``normal_forces`` — the normal force per locator [N];
2. ``gaps`` — the gap per locator [m], symlog (linear within ±1 µm, the touch tolerance);
3. ``force`` and 4. ``moment`` — the wrench the virtual coupling applied to the workpiece (about
   the body origin, world axes), solid, with the plan's wrench per segment dashed;
5. ``states`` — a timeline of which locators press on the part: the planned states as wide
   light bars, the observed ones (the trace's ``pressed``) as narrow coloured bars. Sample ``k``
   stands for the times nearer to it than to its neighbours (:func:`pressed_intervals`).

Without a trace (``--no-verify``, or a verification that diverged before recording), the
panels show the plan alone: the gap per locator at the knot poses (computed with the exact
locator queries, the knots spread evenly over each transition as the verification's reference
spreads them), the planned wrench per segment, and the planned states.

matplotlib is imported inside the functions; figures are plain ``Figure`` objects (no pyplot, no
backend switch), so they draw headless and leave a notebook's backend alone.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from fixplan.errors import InputError

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from fixplan.model import Fixture
    from fixplan.planner.plan import Plan
    from fixplan.planner.solve import PlanResult

FloatArray = NDArray[np.float64]
Intervals = dict[str, list[tuple[float, float]]]

GAP_LINTHRESH_M = 1e-6  # symlog: linear within ±1 µm (the touch tolerance)


def figure_path(report: Path) -> Path:
    """The PNG written beside a report: ``plan.md`` → ``plan.png``."""
    png = report.with_suffix(".png")
    if png == report:
        raise InputError(f"figure_path.report {report}: the report is Markdown; the figure {png} would overwrite it")
    return png


def boundaries_s(durations_s: Sequence[float]) -> FloatArray:
    """Planned transition boundaries [s]: the end of each transition, ``cumsum(durations)``."""
    return np.cumsum(np.asarray(durations_s, dtype=float))


def _runs(mask: NDArray[np.bool_]) -> list[tuple[int, int]]:
    """Maximal runs ``[i, j]`` (inclusive) of True in ``mask``."""
    runs: list[tuple[int, int]] = []
    i = 0
    n = len(mask)
    while i < n:
        if mask[i]:
            j = i
            while j + 1 < n and mask[j + 1]:
                j += 1
            runs.append((i, j))
            i = j + 1
        else:
            i += 1
    return runs


def pressed_intervals(
    time_s: Sequence[float] | FloatArray, pressed: Sequence[Sequence[str]], names: Sequence[str]
) -> Intervals:
    """Time intervals in which each locator is pressed, from samples.

    Sample ``k`` covers the times nearer to it than to its neighbours: from the midpoint with the
    previous sample (``time_s[0]`` for the first) to the midpoint with the next (``time_s[-1]``
    for the last). A run of pressed samples ``i..j`` becomes one interval, so a sample lies inside
    a locator's interval exactly when the locator is pressed there.
    """
    t = np.asarray(time_s, dtype=float)
    if len(t) == 0:
        return {name: [] for name in names}
    mid = 0.5 * (t[:-1] + t[1:])
    lo = np.concatenate([[t[0]], mid])
    hi = np.concatenate([mid, [t[-1]]])
    out: Intervals = {}
    for name in names:
        mask = np.array([name in s for s in pressed], dtype=bool)
        out[name] = [(float(lo[i]), float(hi[j])) for i, j in _runs(mask)]
    return out


def planned_intervals(
    sequence: Sequence[Sequence[str]], durations_s: Sequence[float], names: Sequence[str], end_s: float
) -> Intervals:
    """When each locator is pressed according to the plan.

    ``sequence[0]`` holds from 0; transition ``i`` (from ``sequence[i]`` to ``sequence[i + 1]``)
    ends at ``boundaries_s(durations_s)[i]``, where the added locator starts pressing; every state
    then holds until ``end_s``.
    """
    starts = np.concatenate([[0.0], boundaries_s(durations_s)])
    out: Intervals = {name: [] for name in names}
    for name in names:
        first = next((k for k, s in enumerate(sequence) if name in s), None)
        if first is not None and first < len(starts):
            out[name] = [(float(starts[first]), float(max(end_s, starts[first])))]
    return out


def _bars(intervals: list[tuple[float, float]]) -> list[tuple[float, float]]:
    return [(a, b - a) for a, b in intervals]


def bar_intervals(ax: Axes, gid: str) -> list[tuple[float, float]]:
    """Read back the ``(start, stop)`` of the bars drawn with ``gid`` (tests and checks)."""
    out: list[tuple[float, float]] = []
    for coll in ax.collections:
        if coll.get_gid() == gid:
            for path in coll.get_paths():
                xs = np.asarray(path.vertices, dtype=float)[:, 0]
                out.append((float(xs.min()), float(xs.max())))
    return sorted(out)


def as_plan(result: Plan | PlanResult) -> Plan:
    """The :class:`~fixplan.planner.plan.Plan` of a solve's result (a plan is returned as it is)."""
    from fixplan.planner.plan import Plan

    return result if isinstance(result, Plan) else result.plan


def _planned_wrench_steps(plan: Plan) -> tuple[FloatArray, FloatArray]:
    """The plan's wrench per segment as a step function: times (S+1,) and values (S+1, ndof).

    A plan read from a file has no per-segment wrenches: its transition's mean wrench holds over it.
    """
    times: list[float] = []
    rows: list[FloatArray] = []
    t0 = 0.0
    for tr in plan.transitions:
        T = tr.time_s
        if tr.segment_wrenches is not None:
            W = tr.segment_wrenches
        elif tr.wrench is not None:
            W = np.atleast_2d(tr.wrench)
        else:
            W = np.zeros((0, 0))
        K = W.shape[0]
        for k in range(K):
            times.append(t0 + T * k / K)
            rows.append(W[k])
        t0 += T
    if not rows:
        return np.zeros(0), np.zeros((0, 0))
    times.append(t0)
    rows.append(rows[-1])
    return np.array(times), np.array(rows)


def _mark_boundaries(ax: Axes, bounds: FloatArray) -> None:
    for b in bounds:
        ax.axvline(float(b), color="0.35", linestyle="--", linewidth=0.8, zorder=0, gid="boundary")


def plan_figure(result: Plan | PlanResult, fixture: Fixture, *, dpi: float = 100.0) -> Figure:
    """Draw a plan (and its verification trace when there is one); see the module docstring.

    Every axes is named (``Axes.get_label()``): ``normal_forces``, ``gaps``, ``force``,
    ``moment``, ``states``. Lines carry the locator or component name as their label; the plan's
    own curves have the gid ``planned``; bars have the gid ``pressed:NAME`` or ``planned:NAME``;
    boundaries the gid ``boundary``.
    """
    # a Figure of its own (no pyplot, no backend switch): safe headless and inside a notebook
    from matplotlib import colormaps
    from matplotlib.figure import Figure

    from fixplan.planner.plan import STATUS_WORDS, knot_timeline

    plan = as_plan(result)
    names = [loc.name for loc in fixture.locators]
    d = fixture.dimension
    comp = ("Fx", "Fy", "Fz", "Tx", "Ty", "Tz") if d == 3 else ("Fx", "Fy", "Mz")
    tab10 = colormaps["tab10"]
    colors = {name: tab10(i % 10) for i, name in enumerate(names)}
    comp_colors = {c: tab10(i % 3) for i, c in enumerate(comp)}
    trace = plan.verification.trace if plan.verification is not None else None
    bounds = boundaries_s(plan.durations_s)
    planned_end = float(bounds[-1]) if len(bounds) else 0.0
    # without a trace, show the final planned state a little past the last boundary
    end_s = float(trace.time_s[-1]) if trace is not None and len(trace.time_s) else 1.08 * planned_end
    if end_s <= 0.0:
        end_s = 1.0  # nothing to show over time: a unit axis for the states

    panels = (["normal_forces"] if trace is not None else []) + ["gaps", "force", "moment", "states"]
    heights = {"normal_forces": 2.0, "gaps": 2.0, "force": 1.6, "moment": 1.6, "states": 0.35 * len(names) + 0.6}
    fig = Figure(figsize=(8.0, sum(heights[p] for p in panels) + 0.8), dpi=dpi)
    axes_arr = fig.subplots(
        len(panels),
        1,
        sharex=True,
        gridspec_kw={"height_ratios": [heights[p] for p in panels]},
        squeeze=False,
    )
    axes: dict[str, Any] = {}
    for p, ax in zip(panels, axes_arr[:, 0], strict=True):
        ax.set_label(p)
        axes[p] = ax

    if trace is not None:
        unknown = np.full((len(trace), max(len(trace.names), fixture.ndof)), np.nan)  # a file may leave one out
        normal_forces = trace.normal_forces_N if trace.normal_forces_N is not None else unknown
        trace_gaps = trace.gaps_m if trace.gaps_m is not None else unknown
        coupling = trace.coupling_wrench if trace.coupling_wrench is not None else unknown
        v = plan.verification
        verdict = "passed" if v is not None and v.passed else "failed"
        title = f"{fixture.name}: {STATUS_WORDS.get(plan.status, plan.status)}, verification {verdict} (simulated haptic loop, 1 kHz)"
        ax = axes["normal_forces"]
        for i, name in enumerate(trace.names):
            ax.plot(trace.time_s, normal_forces[:, i], color=colors.get(name), label=name, linewidth=1.2)
        ax.set_ylabel("normal force [N]")
        ax.legend(loc="best", fontsize=7, ncol=min(len(names), 6), framealpha=0.85)
        ax = axes["gaps"]
        for i, name in enumerate(trace.names):
            ax.plot(trace.time_s, trace_gaps[:, i], color=colors.get(name), label=name, linewidth=1.2)
        ax.set_ylabel("gap [m]")
    else:
        why = "not run" if plan.verification is None else "no trace"
        title = f"{fixture.name}: {STATUS_WORDS.get(plan.status, plan.status)} (verification {why}: the plan's knots)"
        ax = axes["gaps"]
        knots = knot_timeline(plan, fixture)
        t_knots = knots.time_s
        g_knots = knots.gaps_m if knots.gaps_m is not None else np.zeros((0, len(names)))
        for i, name in enumerate(names):
            ax.plot(
                t_knots,
                g_knots[:, i],
                "o-",
                color=colors[name],
                label=name,
                markersize=2.5,
                linewidth=1.0,
                gid="planned",
            )
        ax.set_ylabel("gap at knots [m]")
        ax.legend(loc="best", fontsize=7, ncol=min(len(names), 6), framealpha=0.85)
    axes["gaps"].set_yscale("symlog", linthresh=GAP_LINTHRESH_M)
    axes["gaps"].axhline(0.0, color="0.6", linewidth=0.6, zorder=0)

    t_plan, w_plan = _planned_wrench_steps(plan)
    for panel, idx, unit in (("force", range(d), "N"), ("moment", range(d, len(comp)), "N·m")):
        ax = axes[panel]
        for j in idx:
            c = comp[j]
            if trace is not None:
                ax.plot(trace.time_s, coupling[:, j], color=comp_colors[c], label=c, linewidth=1.2)
            if len(t_plan):
                ax.step(
                    t_plan,
                    w_plan[:, j],
                    where="post",
                    color=comp_colors[c],
                    linestyle="--",
                    linewidth=0.9,
                    label=f"{c} planned" if trace is None else None,
                    gid="planned",
                )
        kind = "applied" if trace is not None else "planned"
        note = "\n(dashed: plan)" if trace is not None and len(t_plan) else ""
        ax.set_ylabel(f"{kind} {panel} [{unit}]{note}")
        ax.legend(loc="best", fontsize=7, ncol=len(idx), framealpha=0.85)

    ax = axes["states"]
    planned = planned_intervals(plan.sequence, plan.durations_s, names, end_s)
    observed = pressed_intervals(trace.time_s, trace.pressed, names) if trace is not None else None
    for row, name in enumerate(names):
        y = len(names) - 1 - row  # first locator on top
        ax.broken_barh(
            _bars(planned[name]), (y - 0.4, 0.8), facecolors="0.85", edgecolors="none", gid=f"planned:{name}"
        )
        if observed is not None:
            ax.broken_barh(
                _bars(observed[name]),
                (y - 0.22, 0.44),
                facecolors=colors[name],
                edgecolors="none",
                gid=f"pressed:{name}",
            )
    ax.set_yticks(range(len(names)), list(reversed(names)))
    ax.set_ylim(-0.6, len(names) - 0.4)
    ax.set_ylabel("pressed")
    starts = np.concatenate([[0.0], bounds])
    for i, tr in enumerate(plan.transitions):
        ax.text(
            0.5 * (starts[i] + starts[i + 1]),
            len(names) - 0.45,
            f"+{tr.added_label} ({tr.planned_kind})",
            ha="center",
            va="bottom",
            fontsize=7,
            clip_on=False,
        )
    ax.set_xlabel("time [s]" + ("  (grey: planned states, colour: observed)" if trace is not None else ""))
    ax.set_xlim(0.0, end_s)
    for ax in axes.values():
        _mark_boundaries(ax, bounds)
        ax.grid(True, axis="x", color="0.92", linewidth=0.6)
        ax.tick_params(labelsize=7)
        ax.yaxis.label.set_size(8)
    axes["states"].xaxis.label.set_size(8)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    return fig


def save_plan_figure(result: Plan | PlanResult, fixture: Fixture, png: Path, *, dpi: float = 100.0) -> Path:
    """Draw :func:`plan_figure` and write it as a PNG; returns ``png``."""
    from fixplan.files import write_output

    fig = plan_figure(result, fixture, dpi=dpi)
    write_output(png, lambda path: fig.savefig(path, dpi=dpi))
    return png
