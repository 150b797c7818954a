"""A haptic session as a plan file, and its re-run in the loop (``fixplan verify PLAN``).

The file is the JSON that ``fixplan solve --out`` writes (``status``, ``sequence``,
``transitions``, ``verification.trace``), so ``fixplan view --plan`` replays it, with:

- ``source: "haptic session"``, ``fixture`` (the file's path) and ``status``: ``reached``,
  ``jammed`` or ``short`` (or ``diverged``), ``reason`` and ``where`` (time, contact state, pose,
  and for a jam the push and its margin);
- per transition (between consecutive observed contact states) the part's poses and the
  *pushes* used: the coupling wrench on the part every ``every_s`` (``pushes.time_s`` from the
  transition's start, ``pushes.wrench``), and their mean as ``wrench``;
- ``verification``: the session itself as the loop ran it (``passed`` when the goal was
  reached), with its trace (part poses, gaps, contact forces, coupling and felt wrenches);
- ``session``: the device (its trajectory in device coordinates, every ``every_s``), the loop's
  timing, the bridge's counters, and the check that the felt wrench is the coupling's reaction.

:func:`verify_recording` re-runs the recording in the simulated haptic loop (device, virtual
coupling and engine at 1 kHz, :func:`~fixplan.haptics.rig.haptic_rig`'s gains): a contact-state
policy (:class:`RecordedPushes`) plays, from each observed state, the pushes the session used from
the time it entered that state; an ideal operator places the handle where the coupling transmits
each push at once (``x_d = x_part + w / K``). It passes when the part reaches the goal (every
locator in contact, at rest) within the time limit without jamming (at rest short of the goal,
after the recorded pushes, under a push ``classify`` calls ``jammed``) and without penetrating.

Through the rig's operator model instead (a PD hand, about 15 ms of lag), re-runs of sessions
whose last transitions took a few milliseconds (carried by momentum) ended with the part turned
the other way; the placed handle reproduces the recorded pushes' timing.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, cast, get_args

import numpy as np
from numpy.typing import NDArray

from fixplan.contact_state import format_state
from fixplan.errors import InputError, SolverError
from fixplan.haptics import SimulatedDevice
from fixplan.interactive.session import SessionResult
from fixplan.model import Fixture
from fixplan.settings import DEFAULT, HAPTIC

FloatArray = NDArray[np.float64]

SOURCE = "haptic session"
KNOTS = 10  # poses kept per transition (for the knot replay and the planner's executor)
MAX_SAMPLES = (
    1200  # about 730 bytes each: a longer session is recorded at a coarser step (within the 1 MiB plan-file limit)
)
DIGITS = 6  # significant digits kept in the file


def _round(obj: Any) -> Any:
    """``obj`` with every float rounded to :data:`DIGITS` significant digits (the file stays small)."""
    if isinstance(obj, float):
        return float(f"{obj:.{DIGITS}g}") if math.isfinite(obj) else obj
    if isinstance(obj, dict):
        return {k: _round(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_round(v) for v in obj]
    return obj


def coarsen(res: SessionResult, max_samples: int = MAX_SAMPLES) -> SessionResult:
    """The session with its trace kept every ``k``-th sample (wrenches averaged over each block of ``k``)."""
    from dataclasses import replace

    from fixplan.interactive.session import Trace

    tr = res.trace
    n = len(tr.time_s)
    k = max(1, math.ceil(n / max_samples))
    if k == 1:
        return res
    last = [min(i + k - 1, n - 1) for i in range(0, n, k)]

    def mean(a: list[FloatArray]) -> list[FloatArray]:
        return [np.mean(a[i : i + k], axis=0) for i in range(0, n, k)]

    def pick(a: list[Any]) -> list[Any]:
        return [a[j] for j in last]

    out = Trace(
        time_s=pick(tr.time_s), poses=pick(tr.poses), device_x=pick(tr.device_x), gaps_m=pick(tr.gaps_m),
        normal_forces_N=pick(tr.normal_forces_N), forces_world_N=pick(tr.forces_world_N),
        coupling_wrench=mean(tr.coupling_wrench), felt_wrench=mean(tr.felt_wrench), pressed=pick(tr.pressed),
        suggested=pick(tr.suggested), verdict=pick(tr.verdict), auto=pick(tr.auto),
    )  # fmt: skip
    return replace(res, trace=out, every_s=res.every_s * k)


def _rows(a: Sequence[Any] | FloatArray) -> list[list[float]]:
    return [[float(x) for x in np.asarray(r, dtype=float).reshape(-1)] for r in a]


def _transitions(res: SessionResult) -> list[dict[str, Any]]:
    """Per change of the observed contact state: from, to, added, the poses and the pushes."""
    tr = res.trace
    times = np.asarray(tr.time_s)
    states = list(res.states)
    out: list[dict[str, Any]] = []
    for (t0, s0), (t1, s1) in zip(states[:-1], states[1:], strict=True):
        eps = DEFAULT.numerics.same_time_s
        idx = np.nonzero((times >= t0 - eps) & (times < t1 + eps))[0]
        if len(idx) == 0:
            continue
        added = sorted(set(s1) - set(s0))
        lost = sorted(set(s0) - set(s1))
        W = np.asarray([tr.coupling_wrench[k] for k in idx])
        keep = np.linspace(0, len(idx) - 1, min(KNOTS, len(idx))).round().astype(int)
        entry: dict[str, Any] = {
            "from": list(s0),
            "to": list(s1),
            "motion": "slide" if s0 else "free",
            "wrench": [float(x) for x in W.mean(axis=0)],
            "margin": None,
            "friction_robustness": None,
            "time_s": float(t1 - t0),
            "path_length_m": float(
                sum(
                    np.linalg.norm(tr.poses[b].p_world - tr.poses[a].p_world)
                    for a, b in zip(idx[:-1], idx[1:], strict=True)
                )
            ),
            "max_constraint_violation_m": 0.0,
            "solve_time_s": 0.0,
            "poses": [tr.poses[idx[k]].to_json() for k in keep],
            "t_start_s": float(t0),
            "pushes": {"time_s": [float(times[k] - t0) for k in idx], "wrench": _rows(W)},
        }
        if len(added) == 1:
            entry["added"] = added[0]
        if lost:
            entry["lost"] = lost
        out.append(entry)
    return out


def plan_json(res: SessionResult, fixture: Fixture) -> dict[str, Any]:
    """The recording of a session (see the module's docstring)."""
    return _round(_plan_json(coarsen(res), fixture))


def _plan_json(res: SessionResult, fixture: Fixture) -> dict[str, Any]:
    tr = res.trace
    names = list(res.names)
    T = len(tr.time_s)
    d = fixture.dimension
    trace = {
        "every_s": res.every_s,
        "names": names,
        "time_s": [float(t) for t in tr.time_s],
        "poses": [p.to_json() for p in tr.poses],
        "gaps_m": {n: [float(g[i]) for g in tr.gaps_m] for i, n in enumerate(names)},
        "normal_forces_N": {n: [float(f[i]) for f in tr.normal_forces_N] for i, n in enumerate(names)},
        "forces_world_N": {n: [[float(x) for x in f[i]] for f in tr.forces_world_N] for i, n in enumerate(names)},
        "coupling_wrench": _rows(tr.coupling_wrench),
        "felt_wrench": _rows(tr.felt_wrench),
        "pressed": [list(s) for s in tr.pressed],
    }
    if T == 0:  # nothing ran: one sample at the start, so the file still replays
        trace.update(
            time_s=[0.0], poses=[fixture.start.to_json()], gaps_m={n: [0.0] for n in names},
            normal_forces_N={n: [0.0] for n in names}, forces_world_N={n: [[0.0] * d] for n in names},
            coupling_wrench=[[0.0] * fixture.ndof], felt_wrench=[[0.0] * fixture.ndof], pressed=[[]],
        )  # fmt: skip
    sequence = [list(s) for _, s in res.states]
    reached = res.status == "reached"
    return {
        "source": SOURCE,
        "fixture": str(fixture.source),
        "status": res.status,
        "reason": res.reason,
        "where": res.where,
        "sequence": sequence,
        "transitions": _transitions(res),
        "tried": [],
        "verification": {
            "kind": "session",
            "passed": reached,
            "reason": res.reason,
            "observed_sequence": sequence,
            "final_gaps": res.final_gaps_m,
            "max_penetration": res.max_penetration_m,
            "duration_s": res.duration_s,
            "saturated_ticks": res.saturated_ticks,
            "trace": trace,
        },
        "session": {
            "device": res.device,
            "every_s": res.every_s,
            "device_trajectory": {"time_s": [float(t) for t in tr.time_s], "x": _rows(tr.device_x)},
            "auto": [bool(a) for a in tr.auto],
            "suggested_push": [None if w is None else [float(x) for x in w] for w in tr.suggested],
            "verdict": list(tr.verdict),
            "states": [{"time_s": float(t), "state": list(s)} for t, s in res.states],
            "loop": {**res.stats.to_json(), **res.rates},
            "bridge": res.bridge,
            "felt_equals_coupling_max_N": res.felt_equals_coupling_max_N,
        },
        "timings": {"session_s": res.duration_s},
    }


# -- the re-run ------------------------------------------------------------------------------------
class RecordedPushes:
    """A contact-state policy that plays the session's pushes from where each state was entered.

    Entering a state the session went through, the policy plays the session's push series from the
    time the session entered that state (onward through the following states: a transition the
    person made in a few milliseconds, carried by momentum, is followed by the pushes that came
    next); after the series, its last push is held.
    """

    def __init__(self, fixture: Fixture, transitions: list[dict[str, Any]], times: FloatArray, pushes: FloatArray,
                 *, dwell_s: float = 0.01):  # fmt: skip
        self.fixture = fixture
        self.names = frozenset(loc.name for loc in fixture.locators)
        self.entries = [(frozenset(tr["from"]), float(tr.get("t_start_s", 0.0))) for tr in transitions]
        self.times = np.asarray(times, dtype=float)
        self.pushes = np.asarray(pushes, dtype=float)
        self.dwell_s = dwell_s
        self.index = 0  # the transition being played
        self.offset = float(self.entries[0][1]) if self.entries else 0.0  # session time at entry
        self.entered = 0.0  # replay time at entry
        self._observed: frozenset[str] | None = None
        self._candidate: frozenset[str] | None = None
        self._since = 0.0
        self.observed: list[tuple[str, ...]] = []

    def _entry_for(self, state: frozenset[str]) -> int | None:
        order = list(range(self.index, len(self.entries))) + list(range(self.index))
        return next((j for j in order if self.entries[j][0] == state), None)

    def exhausted(self, t: float) -> bool:
        """The session's pushes are used up (its last push is being held)."""
        return not len(self.times) or self.offset + (t - self.entered) > float(self.times[-1])

    def command(self, t: float, pressed: frozenset[str]) -> FloatArray:
        if pressed != self._observed:
            if pressed != self._candidate:
                self._candidate, self._since = pressed, t
            elif t - self._since >= self.dwell_s:
                self._observed, self._candidate = pressed, None
                self.observed.append(tuple(sorted(pressed)))
                j = self._entry_for(pressed)
                if j is not None:
                    self.index, self.offset, self.entered = j, self.entries[j][1], t
        if not len(self.times):
            return np.zeros(self.fixture.ndof)
        k = int(np.searchsorted(self.times, self.offset + (t - self.entered), side="right")) - 1
        return self.pushes[min(max(k, 0), len(self.pushes) - 1)]


def recorded_pushes(data: dict[str, Any]) -> tuple[FloatArray, FloatArray, int]:
    """The pushes a recording claims, as one series: session times [s], wrenches (T, ndof), and ndof.

    Each transition's ``pushes`` (sampled from its ``t_start_s``) placed at ``t_start_s + time_s``,
    in time order (a transition's first sample can be the previous one's last); then, for a
    session that ended jammed, the push it jammed under (``where.push`` at ``where.time_s``).
    """
    times: list[float] = []
    rows: list[list[float]] = []
    for tr in data["transitions"]:
        t0 = float(tr["t_start_s"])
        times += [t0 + float(t) for t in tr["pushes"]["time_s"]]
        rows += [[float(x) for x in w] for w in tr["pushes"]["wrench"]]
    where = data.get("where") or {}
    if data.get("status") == "jammed" and where.get("push") is not None:
        t = float(where.get("time_s") or 0.0)
        times.append(max([t, *times]))
        rows.append([float(x) for x in where["push"]])
    order = np.argsort(np.asarray(times), kind="stable")
    ndof = len(rows[0]) if rows else 0
    return np.asarray(times)[order], np.asarray(rows, dtype=float).reshape(len(rows), ndof)[order], ndof


def push_disagreement(data: dict[str, Any], fixture: Fixture) -> str | None:
    """Where a recording's claimed pushes contradict its trace (the coupling wrench measured then); None when they agree.

    Every push ``transitions[i].pushes.wrench[k]`` must be the trace's ``coupling_wrench`` at the
    sample of the same session time (within half a sampling step), component by component within
    ``push_match_abs + push_match_rel × limit`` (the hand's force or torque limit).
    """
    from fixplan.settings import DEFAULT

    trace = data["verification"]["trace"]
    times = np.asarray(trace["time_s"], dtype=float)
    measured = np.asarray(trace["coupling_wrench"], dtype=float)
    step = float(trace.get("every_s") or (np.min(np.diff(times)) if len(times) > 1 else 0.0))
    F_max, T_max, _ = fixture.hand_limits()
    d = fixture.dimension
    s = DEFAULT.plan_file
    tol = np.array([s.push_match_abs + s.push_match_rel * (F_max if j < d else T_max) for j in range(fixture.ndof)])
    bad = 0
    first = None
    for i, tr in enumerate(data["transitions"]):
        t0 = float(tr["t_start_s"])
        for k, (t, w) in enumerate(zip(tr["pushes"]["time_s"], tr["pushes"]["wrench"], strict=True)):
            at = t0 + float(t)
            j = int(np.clip(np.searchsorted(times, at), 1, len(times) - 1)) if len(times) > 1 else 0
            if len(times) > 1 and abs(times[j - 1] - at) <= abs(times[j] - at):
                j -= 1
            where = f"transitions[{i}].pushes.wrench[{k}]"
            if abs(times[j] - at) > 0.5 * step + DEFAULT.numerics.same_time_s:
                bad += 1
                first = first or f"{where}: no trace sample at t = {at:.6g} s"
                continue
            diff = np.abs(np.asarray(w, dtype=float) - measured[j])
            if np.any(diff > tol):
                bad += 1
                shown = ", ".join(f"{x:.4g}" for x in w)
                there = ", ".join(f"{x:.4g}" for x in measured[j])
                first = first or f"{where} ({shown}) is not the push measured at t = {times[j]:.6g} s ({there})"
    if first is None:
        return None
    return f"the recorded pushes contradict the session's trace at {bad} samples: {first}"


class _PlacedHandle(SimulatedDevice):
    """A device handle placed by the operator each tick (a position-controlled, ideal hand)."""

    def __init__(self, like: SimulatedDevice):
        super().__init__(like.ndof, specs=like.specs, x0=like.position())
        self._x_cmd = like.position()
        self._v_cmd = np.zeros(like.ndof)

    def command(self, x: FloatArray, v: FloatArray) -> None:
        self._x_cmd, self._v_cmd = np.array(x, dtype=float), np.array(v, dtype=float)

    def position(self) -> FloatArray:
        return self._x_cmd.copy()

    def velocity(self) -> FloatArray:
        return self._v_cmd.copy()

    def advance(self, dt: float, operator_wrench: Any) -> None:
        """The handle is placed, not integrated."""


def verify_recording(
    fixture: Fixture,
    data: dict[str, Any],
    *,
    source: str = "plan",
    time_limit_s: float | None = None,
    max_penetration_m: float = HAPTIC.verification.max_penetration_m,
    settle_s: float = 0.2,
) -> Any:
    """Re-run a session's recorded pushes in the haptic loop; a :class:`~fixplan.planner.verify.Verification`."""
    from fixplan.engine.simulator import Simulator
    from fixplan.haptics.coordinates import coordinates_from_pose
    from fixplan.haptics.rig import haptic_rig
    from fixplan.jamming import classify
    from fixplan.planner.execute import ExecutionSettings
    from fixplan.planner.plan import Verification, plan_for_fixture
    from fixplan.planner.verify import loop_measures

    if fixture.has_pins:  # the replay's goal is every locator pressed: it says nothing of pins (a bore has none)
        raise InputError(
            f"{source}: a recording on a fixture with pins or bores ({fixture.source}) is not re-run yet: its goal, "
            "every locator pressed, says nothing of the pins (expected a plan from 'fixplan solve --out', whose "
            "staged insertion verify re-runs)"
        )
    plan_for_fixture(data, fixture, source)  # the format, the fixture's locators and start, pushes within limits
    transitions = data["transitions"]
    contradiction = push_disagreement(data, fixture)  # the trace is the evidence of what was pushed
    push_times, pushes, _ = recorded_pushes(data)
    if not len(push_times):
        return Verification(
            passed=False, reason="the recording has no transitions: no recorded pushes to re-run", final_pose=None,
            max_penetration_m=None, deadline_misses=None, tick_mean_us=None, tick_max_us=None, observed_sequence=[],
            final_gaps_m={}, duration_s=0.0, felt_force_max_N=None, failed_checks=["no pushes"],
        )  # fmt: skip
    sim = Simulator(fixture, settings=HAPTIC.engine)
    R0 = fixture.start.R_world_body.copy()
    F_max, T_max, _ = fixture.hand_limits()
    rig = haptic_rig(fixture, sim, coordinates_from_pose(fixture.start, R0), F_max, T_max, HAPTIC.haptic)
    settings = ExecutionSettings()
    wp = fixture.workpiece
    weight = fixture.weight_N
    threshold = max(settings.press_fraction * weight, 1e-6)
    r_gyr = math.sqrt(float(np.max(np.linalg.eigvalsh(np.atleast_2d(wp.inertia_body)))) / wp.mass_kg)
    # what the file claims was pushed: the transitions' pushes (not the trace, which is only compared)
    policy = RecordedPushes(fixture, transitions, push_times, pushes)
    names = frozenset(policy.names)
    d = fixture.dimension
    rest = settings.stall_speed_mps * 10
    state: dict[str, Any] = {"settled": None, "still": None, "outcome": None, "reason": ""}

    def speed() -> float:
        tw = sim.twist
        return math.hypot(float(np.linalg.norm(tw[:d])), float(np.linalg.norm(tw[d:])) * r_gyr)

    def operator(t: float, device: Any) -> FloatArray:
        pressed = frozenset(sim.in_contact(threshold, settings.contact_gap_m))
        w = policy.command(t, pressed)
        at_rest = speed() < rest
        if policy._observed == names and at_rest:
            state["settled"] = state["settled"] if state["settled"] is not None else t
            if t - state["settled"] >= settle_s:
                state["outcome"], state["reason"] = "reached", f"every locator pressed, at rest at t = {t:.3f} s"
        else:
            state["settled"] = None
        # a rest while the recorded pushes of this state still play is the person's own pause; at rest
        # after them, short of the goal, under a push classify calls jammed: the recording jams here
        if at_rest and policy._observed != names and policy.exhausted(t):
            state["still"] = state["still"] if state["still"] is not None else t
            if t - state["still"] >= 0.3:
                state["still"] = t  # look again in 0.3 s
                obs = sorted(policy._observed or ())
                if obs:
                    c = classify(fixture, w, obs, pose=sim.pose, jobs=1)[0]
                    if c.mode == "jammed":
                        state["outcome"] = "jammed"
                        state["reason"] = (
                            f"jammed at t = {t:.3f} s in {{{', '.join(obs)}}}: the recorded push "
                            f"({', '.join(f'{x:.3g}' for x in w)}) is held by friction (margin {c.balance_residual:.3g})"
                        )
        else:
            state["still"] = None
        # the ideal operator: the handle is put where the coupling transmits w at once
        x_w, v_w = rig.loop.workpiece_coordinates()
        handle.command(x_w + w / rig.K, v_w)
        return np.zeros(fixture.ndof)

    handle = _PlacedHandle(rig.loop.device)
    rig.loop.device = handle
    recorded = (
        float(data.get("verification", {}).get("duration_s") or 0.0)
        if isinstance(data.get("verification"), dict)
        else 0.0
    )
    limit = time_limit_s if time_limit_s is not None else min(max(1.5 * recorded + 2.0, 3.0), 120.0)
    every = 10
    try:
        rec = rig.loop.run(limit, operator, trace_every=every, until=lambda: state["outcome"] is not None)
    except SolverError as exc:
        why = f"the re-run diverged at t = {sim.time_s:.3f} s: {exc}"
        return Verification(
            passed=False, reason=why if contradiction is None else f"{contradiction}; {why}", final_pose=sim.pose,
            max_penetration_m=sim.max_penetration_m, deadline_misses=None, tick_mean_us=None, tick_max_us=None,
            observed_sequence=list(policy.observed), final_gaps_m={}, duration_s=sim.time_s, felt_force_max_N=None,
            failed_checks=["diverged"] if contradiction is None else ["evidence", "diverged"],
        )  # fmt: skip
    reasons, checks = [], []
    if contradiction is not None:
        checks.append("evidence")
        reasons.append(contradiction)
    if not transitions:  # only the push it jammed under: a recording that loads nothing cannot pass
        checks.append("no transitions")
        reasons.append("the recording has no transitions (no change of contact state to re-run)")
    if state["outcome"] != "reached":
        checks.append("jammed" if state["outcome"] == "jammed" else "goal")
        reasons.append(
            state["reason"]
            if state["outcome"] == "jammed"
            else f"did not reach the goal in {limit:.3g} s: ended in {format_state(policy._observed or (), empty='{}')}"
        )
    pen = sim.max_penetration_m
    if pen > max_penetration_m:
        checks.append("penetration")
        reasons.append(f"penetration reached {pen:.3g} m (expected ≤ {max_penetration_m:g} m)")
    W = np.asarray(rec.coupling_wrench) if rec.coupling_wrench else np.zeros((1, fixture.ndof))
    return Verification(
        passed=not reasons,
        reason="; ".join(reasons) if reasons else "the recorded pushes load the part: every locator pressed, at rest",
        failed_checks=checks,
        **loop_measures(rec, sim, every),
        observed_sequence=list(policy.observed),
        final_gaps_m={c.name: float(c.gap_m) for c in sim.contacts()},
        max_push_force_N=float(np.max(np.linalg.norm(W[:, :d], axis=1))),
        max_push_torque_Nm=float(np.max(np.linalg.norm(W[:, d:], axis=1))),
        saturated_ticks=rig.loop.saturated_ticks,
    )


def verify_plan_file(fixture: Fixture, data: dict[str, Any], *, source: str = "plan") -> Any:
    """``fixplan verify``: a session's recorded pushes, or a solved plan's transitions through the executor.

    A plan for a fixture with pins or bores re-runs its staged insertion (:mod:`fixplan.planner.insertion_file`).
    """
    from fixplan.locating import start_state as locating_start_state
    from fixplan.planner.execute import Step, TransitionKind
    from fixplan.planner.plan import plan_for_fixture
    from fixplan.planner.solve import Planner
    from fixplan.planner.verify import verify

    if isinstance(data, dict) and data.get("source") == SOURCE:
        return verify_recording(fixture, data, source=source)
    plan = plan_for_fixture(data, fixture, source)
    if plan.status == "infeasible":
        raise InputError(f"{source}: the plan is infeasible (no transitions to run): {plan.reason}")
    if fixture.has_pins:  # the staged insertion the file holds, in the loop as solve verified it
        from fixplan.planner.insertion_file import verify_insertion_file

        return verify_insertion_file(fixture, plan)
    steps = []
    for i, tr in enumerate(plan.transitions):
        if tr.added is None:
            raise InputError(
                f"{source}: transitions[{i}]: no 'added' locator (expected a plan from 'fixplan solve --out')"
            )
        if tr.motion not in get_args(TransitionKind):
            raise InputError(
                f"{source}: transitions[{i}].motion: expected one of {', '.join(get_args(TransitionKind))}, got {tr.motion!r}"
            )
        steps.append(Step(tr.from_state, tr.added, cast(TransitionKind, tr.motion), tr.poses, tr.together))
    start_state = locating_start_state(fixture)
    # the plan's policy (solve --json's "policy"), as solve verified it: the executor takes it from
    # a state the plan does not expect before it re-plans
    v = verify(fixture, start_state, steps, replan=Planner(fixture).replan, policy=plan.policy)
    replans = v.execution.counts.get("replans", 0) if v.execution is not None else 0
    if replans:
        # the executor planned anew on the way (as solve's own verification may, and says so):
        # the plan's claims were checked against the fixture before the run, so a re-plan here is
        # the executor's last resort from a state the policy did not cover, never hidden
        note = (
            f"the executor re-planned {replans} time{'s' if replans > 1 else ''} on the way (from states the plan's"
            " policy does not cover)"
        )
        v.reason = note if v.reason in ("", "every check passed") else f"{v.reason}; {note}"
    return v
