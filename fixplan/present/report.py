"""The Markdown report of a loading plan (``fixplan solve --report``): sequence, figures, transitions, verification."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from fixplan.model import Fixture
    from fixplan.planner.plan import Plan
    from fixplan.planner.solve import PlanResult


def report_markdown(result: Plan | PlanResult, fixture: Fixture, figures: Sequence[str] = ()) -> str:
    """A Markdown report of a plan: the sequence, figures, the transitions, what was tried, the verification.

    ``figures`` are image links (paths relative to the report, e.g. ``plan.png`` from
    :func:`fixplan.present.plots.save_plan_figure`), shown in a ``## Figures`` section.
    """
    from fixplan.present.plots import as_plan

    plan = as_plan(result)
    payload = plan.to_json()
    lines = [f"# Loading plan: {fixture.name}", "", f"- file: `{fixture.source}`", f"- status: **{plan.status}**"]
    if payload["reason"]:
        lines.append(f"- reason: {payload['reason']}")
    lines += [f"- sequence: {' → '.join('{' + ', '.join(s) + '}' for s in plan.sequence) or '(none)'}", ""]
    if figures:
        if plan.verification is not None and plan.verification.trace is not None:
            what = (
                "Over time, in the simulated haptic loop: normal force and gap per locator, the wrench the"
                " coupling applied (dashed: the plan's), and which locators press (grey: planned, colour: observed)."
            )
        else:
            what = (
                "The plan alone (no verification trace): gap per locator at the knot poses, the planned wrench"
                " per segment, and the planned contact states."
            )
        lines += ["## Figures", "", what + " Dashed vertical lines mark the ends of the planned transitions.", ""]
        lines += [f"![{fixture.name}: loading plan over time]({link})" for link in figures] + [""]
    if payload["transitions"]:
        lines += [
            "## Transitions",
            "",
            "| # | from | added | motion | mean wrench [N, N·m] | least margin [N] | friction δ | peak push [% of max_force, max_torque] | time [s] | path [m] | max gap violation [m] |",
            "|---:|---|---|---|---|---:|---:|---:|---:|---:|---:|",
        ]
        for i, tr in enumerate(payload["transitions"], 1):
            # a group closing together is a list of names: {E1, E2}
            added = "{" + ", ".join(tr["added"]) + "}" if isinstance(tr["added"], list) else tr["added"]
            w = "–" if tr["wrench"] is None else ", ".join(f"{x:.3g}" for x in tr["wrench"])
            margin = "–" if tr["margin"] is None else f"{tr['margin']:.3g}"
            rob = "–" if tr["friction_robustness"] is None else f"±{tr['friction_robustness']:.2g}"
            peak = (
                "–"
                if tr.get("peak_force_fraction") is None
                else f"{tr['peak_force_fraction']:.0%}, {tr['peak_torque_fraction']:.0%}"
            )
            lines.append(
                f"| {i} | {{{', '.join(tr['from'])}}} | {added} | {tr['motion']} | {w} | {margin} | {rob} | {peak} | "
                f"{tr['time_s']:.2f} | {tr['path_length_m']:.4g} | {tr['max_constraint_violation_m']:.1e} |"
            )
        lines += [
            "",
            "Least margin: the least normal force on the kept contacts along the transition (– from no contact). "
            "Friction δ: the largest δ (of 0.05, 0.1, 0.2, 0.3, 0.5) for which the first push still moves the part "
            "with friction anywhere in μ(1 ± δ) within the hand's limits. "
            "Peak push: the largest planned push over the transition's segments, as percentages of max_force and "
            "max_torque; the pushes are sought within 80 % of them first (`settings.search.limit_fraction`) and "
            "exceed it only where no non-jamming push exists inside.",
        ]
        lines.append("")
    failed = [a for a in payload["tried"] if not a["ok"]]
    # a transition priced twice (the cheap check, then the path) is listed once, with its last reason:
    # the same "too weak" six times over three transitions told the reader nothing more
    last: dict[tuple[tuple[str, ...], str], str] = {}
    for a in failed:
        last[(tuple(a["from"]), a["add"])] = a["reason"]
    lines += [
        "## Transitions tried",
        "",
        f"{len(payload['tried'])} priced, {len(failed)} failed ({len(last)} distinct transitions).",
        "",
    ]
    lines += [f"- {{{', '.join(frm)}}} + {add}: {reason}" for (frm, add), reason in last.items()]
    v = payload["verification"]
    lines += ["", "## Verification (simulated haptic loop, 1 kHz, contact-state feedback executor)", ""]
    if v is None and plan.status == "infeasible":
        lines.append("Not run: there is no plan to run in the loop.")
    elif v is None:
        lines.append("Not run (`solve.run_verification=False`).")
    else:

        def num(x: float | None, fmt: str) -> str:
            return "–" if x is None else format(x, fmt)

        def pct(x: float | None) -> str:
            return "–" if x is None else f"{x:.0%}"

        gaps = [abs(g) for g in v["final_gaps"].values()]
        lines += [
            f"- result: **{'passed' if v['passed'] else 'failed'}** — {v['reason']}",
            f"- observed states: {' → '.join('{' + ', '.join(s) + '}' for s in v['observed_sequence']) or '(none)'}",
            f"- final gaps ≤ {num(max(gaps) if gaps else None, '.2e')} m; max penetration {v['max_penetration']:.2e} m",
            f"- push on the part ≤ {num(v['max_push_force'], '.3g')} N, {num(v['max_push_torque'], '.3g')} N·m "
            f"(10 ms mean; {num(v.get('saturated_ticks'), 'd')} ticks capped at the hand's limits)",
            f"- commanded push (the executor's, every tick) peaks at {pct(v.get('peak_force_fraction'))} of max_force "
            f"and {pct(v.get('peak_torque_fraction'))} of max_torque; headroom kept: within "
            f"{pct(v.get('limit_fraction'))} of the limits, {num(v.get('ticks_above_fraction'), 'd')} ticks above it",
            f"- tick compute (the executor's command, any re-plan inside it, and the engine step): mean "
            f"{num(v['tick_mean_us'], '.0f')} µs, max {num(v['tick_max_us'], '.0f')} µs; "
            f"{num(v['deadline_misses'], 'd')} ticks over the 1 ms period; re-planning inside the loop "
            f"{num(v.get('planner_wall_time_in_loop_s'), '.3g')} s",
            f"- largest force felt by the user: {num(v['felt_force_max'], '.3g')} N",
        ]
        ex = v.get("execution")
        if ex:
            c = ex["counts"]
            lines.append(
                f"- executor: {c['solves']} wrench solves, {c['replans']} re-plans ({c['lost_contact']} lost, "
                f"{c['unplanned_contact']} unplanned contacts), {c['stalls']} stalls, {c['retries']} re-searches"
            )
            lines += [f"  - t = {e['time_s']:.3f} s, {e['kind']}: {e['message']}" for e in ex["events"]]
    t = payload["timings"]
    lines += ["", "## Timings", "", ", ".join(f"{k} {x:.2f} s" for k, x in t.items()), ""]
    return "\n".join(lines)
