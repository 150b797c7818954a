"""``fixplan solve``: plan the loading of a full fixture, then verify the plan in the haptic loop.

1. The start state is the set of locators touching at the start pose.
2. The coarse search (:mod:`.coarse`) adds one locator per transition, pricing each with a fine
   plan (:mod:`.fine`: CasADi path + non-jamming wrench per segment); the cost is the
   mass-weighted path length plus a penalty on thin margins.
3. Unless ``verify=False``, the chosen plan is run through the simulated haptic loop
   (:mod:`.verify`): contact states, stalls, final gaps and penetration are checked.

Transition durations for the verification are ``T = 0.15 s + 2 √(L / a)`` for a path of length
``L`` at the planned acceleration ``a`` (accelerate half-way, decelerate half-way).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fixplan.fixture import Fixture
from fixplan.locating import contact_set, require_full
from fixplan.planner.coarse import Attempt, search
from fixplan.planner.fine import Transition, plan_transition
from fixplan.planner.verify import Verification, verify


@dataclass
class PlanResult:
    """A plan (or the reason there is none), its verification and timings."""

    status: str  # "planned" | "infeasible"
    reason: str
    sequence: list[tuple[str, ...]]
    transitions: list[Transition]
    attempts: list[Attempt]
    verification: Verification | None
    durations_s: list[float]
    timings: dict[str, float] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.status == "planned" and (self.verification is None or self.verification.passed)

    def to_json(self) -> dict[str, Any]:
        transitions = []
        for tr, T in zip(self.transitions, self.durations_s, strict=True):
            w = np.nanmean(tr.wrenches, axis=0) if len(tr.wrenches) else np.zeros(0)
            transitions.append(
                {
                    "from": list(tr.established),
                    "to": sorted([*tr.established, tr.target]),
                    "added": tr.target,
                    "motion": tr.kind,
                    "wrench": [float(x) for x in w],
                    "margin": float(np.min(tr.margins)) if len(tr.margins) else None,
                    "time_s": T,
                    "path_length_m": float(tr.cost),
                    "max_constraint_violation_m": float(tr.max_constraint_violation_m),
                    "solve_time_s": float(tr.solve_time_s),
                    "poses": [p.to_json() for p in tr.poses],
                }
            )
        return {
            "status": self.status,
            "reason": self.reason,
            "sequence": [list(s) for s in self.sequence],
            "transitions": transitions,
            "tried": [
                {"from": list(a.established), "add": a.target, "ok": a.success, "reason": a.reason}
                for a in self.attempts
            ],
            "verification": None if self.verification is None else self.verification.to_json(),
            "timings": self.timings,
        }


def report_markdown(result: PlanResult, fixture: Fixture, figures: Sequence[str] = ()) -> str:
    """A Markdown report of a plan: the sequence, figures, the transitions, what was tried, the verification.

    ``figures`` are image links (paths relative to the report, e.g. ``plan.png`` from
    :func:`fixplan.plots.save_plan_figure`), shown in a ``## Figures`` section.
    """
    payload = result.to_json()
    lines = [f"# Loading plan: {fixture.name}", "", f"- file: `{fixture.source}`", f"- status: **{result.status}**"]
    if payload["reason"]:
        lines.append(f"- reason: {payload['reason']}")
    lines += [f"- sequence: {' → '.join('{' + ', '.join(s) + '}' for s in result.sequence) or '(none)'}", ""]
    if figures:
        if result.verification is not None and result.verification.trace is not None:
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
            "| # | from | added | motion | mean wrench [N, N·m] | least margin [N] | time [s] | path [m] | max gap violation [m] |",
            "|---:|---|---|---|---|---:|---:|---:|---:|",
        ]
        for i, tr in enumerate(payload["transitions"], 1):
            w = ", ".join(f"{x:.3g}" for x in tr["wrench"])
            margin = "–" if tr["margin"] is None else f"{tr['margin']:.3g}"
            lines.append(
                f"| {i} | {{{', '.join(tr['from'])}}} | {tr['added']} | {tr['motion']} | {w} | {margin} | "
                f"{tr['time_s']:.2f} | {tr['path_length_m']:.4g} | {tr['max_constraint_violation_m']:.1e} |"
            )
        lines.append("")
    failed = [a for a in payload["tried"] if not a["ok"]]
    lines += ["## Transitions tried", "", f"{len(payload['tried'])} priced, {len(failed)} failed.", ""]
    for a in failed:
        lines.append(f"- {{{', '.join(a['from'])}}} + {a['add']}: {a['reason']}")
    v = payload["verification"]
    lines += ["", "## Verification (simulated haptic loop, 1 kHz)", ""]
    if v is None:
        lines.append("Not run (`--no-verify`).")
    else:
        worst = max((abs(g) for g in v["final_gaps"].values()), default=float("nan"))
        lines += [
            f"- result: **{'passed' if v['passed'] else 'failed'}** — {v['reason']}",
            f"- observed states: {' → '.join('{' + ', '.join(s) + '}' for s in v['observed_sequence'])}",
            f"- final gaps ≤ {worst:.2e} m; max penetration {v['max_penetration']:.2e} m",
            f"- tick compute: mean {v['tick_mean_us']:.0f} µs, max {v['tick_max_us']:.0f} µs; deadline misses {v['deadline_misses']}",
            f"- largest force felt by the user: {v['felt_force_max']:.3g} N",
        ]
    t = payload["timings"]
    lines += ["", "## Timings", "", ", ".join(f"{k} {x:.2f} s" for k, x in t.items()), ""]
    return "\n".join(lines)


def _duration(tr: Transition, acceleration_mps2: float) -> float:
    length = float(tr.cost) if math.isfinite(tr.cost) else 0.0
    return 0.15 + 2.0 * math.sqrt(max(length, 0.0) / acceleration_mps2)


def solve(
    fixture: Fixture,
    *,
    order: Sequence[str] | None = None,
    run_verification: bool = True,
    acceleration_mps2: float = 1.0,
    knots: int = 10,
    progress: Callable[[Attempt], None] | None = None,
    verify_options: dict[str, Any] | None = None,
) -> PlanResult:
    """Plan (and by default verify) the loading of ``fixture``.

    ``knots`` per transition: 10 by default — on the default box the exact gaps between knots
    stay within 1e-17 m at 10 as at 20 (``benchmarks/bench_planner.py``) for half the time.
    ``verify_options`` are passed to :func:`~fixplan.planner.verify.verify` (e.g. ``max_sweeps``).
    """
    vopts = dict(verify_options or {})
    require_full(fixture, "planning")
    t0 = time.perf_counter()
    names = [loc.name for loc in fixture.locators]
    touching = contact_set(fixture, "start")
    start_state = frozenset(c.name for c in touching.contacts if c.kind == "locator")
    if start_state == frozenset(names):
        # already located: nothing to plan; verification checks that the part stays there
        verification = verify(fixture, [], [], [], [], **vopts) if run_verification else None
        timings = {"plan_s": 0.0, "fine_s": 0.0, "total_s": time.perf_counter() - t0}
        reason = "" if verification is None or verification.passed else f"verification failed: {verification.reason}"
        return PlanResult(
            "planned",
            reason or "already located at the start pose",
            [tuple(sorted(names))],
            [],
            [],
            verification,
            [],
            timings,
        )
    cache: dict[tuple[tuple[str, ...], str], Transition] = {}
    fine_time = 0.0

    def evaluate(pose, state, target):
        nonlocal fine_time
        key = (tuple(sorted(state)), target)
        if key not in cache:
            t = time.perf_counter()
            cache[key] = plan_transition(
                fixture, pose, sorted(state), target, knots=knots, acceleration_mps2=acceleration_mps2
            )
            fine_time += time.perf_counter() - t
        return cache[key]

    coarse = search(start_state, names, fixture.start, evaluate, order=order, progress=progress)
    t_plan = time.perf_counter() - t0
    timings = {"plan_s": t_plan, "fine_s": fine_time}
    if not coarse.found:
        timings["total_s"] = time.perf_counter() - t0
        return PlanResult("infeasible", coarse.reason, [], [], coarse.attempts, None, [], timings)
    transitions = list(coarse.transitions)
    durations = [_duration(tr, acceleration_mps2) for tr in transitions]
    verification = None
    if run_verification:
        t1 = time.perf_counter()
        # per-segment feedforward; a segment without a wrench (NaN row) borrows the transition's mean
        wrenches = []
        for tr in transitions:
            W = np.array(tr.wrenches, dtype=float)
            mean = np.nanmean(W, axis=0)
            W[~np.isfinite(W).all(axis=1)] = mean
            wrenches.append(W)
        sequence = (
            [tuple(sorted(start_state))] + [tuple(s) for s in coarse.sequence[1:]] if start_state else coarse.sequence
        )
        verification = verify(fixture, sequence, [tr.poses for tr in transitions], wrenches, durations, **vopts)
        timings["verify_s"] = time.perf_counter() - t1
    timings["total_s"] = time.perf_counter() - t0
    reason = "" if verification is None or verification.passed else f"verification failed: {verification.reason}"
    return PlanResult(
        "planned", reason, coarse.sequence, transitions, coarse.attempts, verification, durations, timings
    )
