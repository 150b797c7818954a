"""Planning and verifying the insertion of a part onto locating pins, or of a shaft into a bore.

The contact-state graph of a pin fixture has two kinds of elements: a rest locator pressed (as
for every fixture), and a pin *engaged*: its tip past its hole's mouth (along the hole's axis) with
the tip's centre within the capture ``(D − d)/2 + c_hole + c_pin`` of the hole's axis, so that the
pin can only go on into the hole (:func:`~fixplan.locating.engagement`). A bore is the same with the part as the
pin: the shaft's leading end past the bore's mouth, then its end face on the bore's bottom
(``"<bore>.bottom"``).

The plan (:func:`plan_insertion`) is staged along the insertion axis ``u`` (the pins' common
axis, or the bore's; the part moves along ``−u``), from the located pose ``G`` lifted by heights
``h`` along ``u``:

1. **approach** (a pose target, not a contact target): from the start to the staging pose
   ``G + u (h₁ + lead_m)``, lifting first when the start is lower, so that every hole's axis lies
   on its pin's axis ``lead_m`` above the first tip; where the straight move would bring the
   part's lowest point below the pins' tips or the stops' tops (a tilted start), it moves sideways
   at a height that clears them and comes down along the axis (:func:`_over_staging`); it ends
   once every hole's mouth (a shaft's leading end) is within ``align_capture_share`` of its
   capture of where the staging pose puts it. A part whose every pin (or the shaft) starts in past
   the chamfers (:func:`started_in`: a shaft cocked in its bore) has no approach and no insertion:
   its holes are where its pose says, and the plan is the seating from the start, on the line
   re-centred on them;
2. **one insertion per pin**, in the order the tips meet their mouths on the way down (the pin
   whose engagement height ``h_i`` — its tip's depth in its hole at ``G`` — is largest first; pins
   engaging at the same height are one transition, round before diamond): down to
   ``h_i − (c_hole + c_pin + engage_margin_m)``, past both chamfers;
3. **seating**: down to ``G``, where the rests (or the bore's bottom) close together, then the
   seating push: ``seat_press`` weights along ``−u``, ``seat_side`` weights toward the round
   pin's contact at ``G`` (the side the part is located against) and as much into every *stop*
   (a locator facing across ``u``, which the descent does not close: the flange's rotational
   stop), each part balanced by the contacts it presses. With stops and one round pin the part
   goes down turned away from them about the pin's axis (:func:`seat_turn`: a face sliding down
   along a stop catches the stop's tip on its lower edge), and once on its rests turns into them.

Each step's push is searched on the contacts its motion slides on (the pins touching their walls
along the planned path, e.g. the round pin on the seated side) with the jamming search
(:func:`~fixplan.jamming.search.search_wrench_in`: a push that moves the part along ``−u``
without jamming, pressing the seated side by ``seat_side`` weights), and the same contacts'
wedging (:func:`~fixplan.jamming.wedge.wedge_force`: forces that balance with no push). A step
with no push, or whose contacts wedge, makes the plan ``infeasible`` with the pin named. The
seating push is classified on the rests and the pins at ``G``: it must hold the part there.

The verification (:func:`verify_insertion`) runs the plan in the simulated haptic loop of
:mod:`.verify` (the same rig, engine with the pins' closed-form contacts, and checks): the hand
servos the part along the plan's guide — stiff along the axis (its push capped at the step's
planned push), soft across it as a remote-centre compliance, so that a chamfer's push moves the
part sideways onto its pin — and, at the goal state, switches to the seating push. With stops,
once the descent has closed what it closes (the rests, the pins) the hand, still carrying the
part so that the rests are lightly loaded, presses the round pin's seated side and turns the part
about the pin's axis into the stops at a set speed (a velocity loop, up to the stops' part of the
seating push; a stop met fast knocks the hole around its pin), or presses the stops when there
is no turn; the stops close and the seating push holds the part. It observes
the state every tick (engaged pins from the pose, pressed rests from the engine's forces), and
passes when the goal state is reached and held at rest, the rests within ``final_gap_m``, every
hole's axis within the radial play of its pin's (for a diamond pin: along its lands), penetration
and the solver's residual within the profile's bounds, the push within the hand's limits. An
insertion that does not move along the axis for ``stall_s``, or loses a pin it had engaged,
consults the plan's policy (:mod:`.insertion_policy`, built with the plan): it backs off along
the axis to the end of an earlier stage, re-centres the guide on where the holes of the pins past
their chamfers were seen and goes on from the state it sees there, within the policy's budget
(retries, time); then it fails, naming the pin that did not enter (or is wedged), the stage, by
how much it missed and the retries it spent. A plan without a policy (a file written before it)
fails at the first such stage.

The plan is nominal: the guide lies on the nominal pins. ``robust`` runs it in worlds whose pins
and rests are displaced (pose errors larger than the play): the chamfers must capture the part.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fixplan.contact_state import Debounce, State, format_state
from fixplan.locating import (
    Insert,
    axis_offsets_m,
    bottom_gap_m,
    contact_set,
    engagement,
    insertion_axis,
    inserts,
    located_pose,
    locator_gaps,
    peg_body,
    seat_at,
    seat_gaps_m,
    seated,
)
from fixplan.model import Fixture
from fixplan.planner.execute import ExecutionLog, ExecutionNoise
from fixplan.planner.insertion_policy import InsertionPolicy, Recentring, deep_m, insertion_policy
from fixplan.planner.plan_types import Verification
from fixplan.settings import DEFAULT, HAPTIC, ExecutionSettings, InsertionSettings, Settings
from fixplan.spatial import Pose, exp_so3, log_so3, pose_between, shift_wrench

FloatArray = NDArray[np.float64]


# -- the plan --------------------------------------------------------------------------------------
@dataclass
class Stage:
    """One transition of an insertion plan."""

    target: str  # the state element it adds ("" for the approach)
    together: tuple[str, ...]  # elements added with it
    kind: str  # "free" (approach), "insert", "seat"
    poses: list[Pose]  # the guide, start to end
    wrench: FloatArray  # the planned push (about the body origin, world axes)
    contacts: tuple[str, ...]  # the contacts the push is searched on
    reason: str
    wedge_force: float | None = None  # the contacts' wedging force (of 1); None: fewer than two contacts
    margin_N: float | None = None

    @property
    def added(self) -> tuple[str, ...]:
        return (self.target, *self.together) if self.target else ()


@dataclass
class InsertionPlan:
    """The staged plan, or why there is none."""

    ok: bool
    reason: str
    axis_world: FloatArray
    goal: Pose
    stages: list[Stage] = field(default_factory=list)
    order: list[tuple[str, ...]] = field(default_factory=list)  # the pins in engagement order, ties together
    heights_m: dict[str, float] = field(default_factory=dict)  # each insert's engagement height above the goal
    seat_wrench: FloatArray | None = None  # the seating push (about the body origin at the goal, world axes)
    seat_wrench_com: FloatArray | None = None  # the same about the centre of mass (what the hand adds to carrying)
    start_state: State = frozenset()  # the goal state when the part starts located
    # the stops (locators facing across the axis, seat_at) and the seating's turn into them (None: the
    # part goes down to the located pose); with_seating fills them and the two parts below
    stops: tuple[str, ...] = ()
    turn: SeatTurn | None = None
    # the seating push's parts across the axis, about the centre of mass: toward the round pin's
    # seated side and into the stops (seat_parts); what the seating stage presses once the rests are
    seat_side_com: FloatArray | None = None
    seat_stops_com: FloatArray | None = None
    plan_s: float = 0.0
    # what the run does from every observable state, and how it recovers (None: a failed stage is the end)
    policy: InsertionPolicy | None = None

    @property
    def descent_pose(self) -> Pose:
        """Where the insertion goes down to before the seating pushes it to the located pose."""
        return self.goal if self.turn is None else self.turn.descent

    @property
    def states(self) -> list[State]:
        out: list[State] = [self.start_state]
        for st in self.stages:
            out.append(out[-1] | set(st.added))
        return out


def goal_state(fixture: Fixture) -> State:
    """Every pin engaged, every rest pressed (a bore: engaged and on its bottom)."""
    names = {loc.name for loc in fixture.locators} | {p.name for p in fixture.pins}
    for b in fixture.bores:
        names |= {b.name, f"{b.name}.bottom"}
    return frozenset(names)


def _push(fixture: Fixture, pose: Pose, names: list[str], u: FloatArray, settings: Settings) -> tuple[
    bool, FloatArray, str, tuple[str, ...], float | None, float | None
]:  # fmt: skip
    """The non-jamming push moving the part along ``−u`` at ``pose`` on the touching contacts of ``names``.

    ``(found, wrench about the body origin, reason, contacts, wedging force, margin)``. No contact
    touching: the free push ``M a − w_g``. The search runs with ``settings`` (its ``insertion``
    group sets the acceleration and the margin).
    """
    from fixplan.jamming.push import push_at

    s = settings.insertion
    a = np.concatenate([-s.push_accel_mps2 * u, np.zeros(3)])
    p = push_at(fixture, pose, names, a, min_margin_N=s.seat_side * fixture.weight_N, settings=settings)
    return p.found, p.wrench, p.reason, p.contacts, p.wedge_force, p.margin_N


def plan_insertion(fixture: Fixture, settings: Settings = DEFAULT) -> InsertionPlan:
    """The staged insertion of ``fixture``'s part (module text); ``ok`` false with the reason when there is none.

    ``settings`` give the insertion's numbers (``insertion``) and every push's wrench search (``search``,
    ``witness``, ``numerics``).
    """
    t0 = time.perf_counter()
    s = settings.insertion
    G = located_pose(fixture)
    u = insertion_axis(fixture)
    plan = InsertionPlan(False, "", u, G)
    with_seating(plan, fixture, s)
    ins = inserts(fixture)
    # every hole over its pin at the located pose: the capture, and the heights the tips meet the mouths
    for i in ins:
        e = engagement(fixture, G, i)
        if e.offset_m > i.capture_m or e.depth_m <= 0.0:
            where = (
                f"its hole {i.hole}'s axis is {e.offset_m * 1e3:.3g} mm from its tip (capture {i.capture_m * 1e3:.3g} mm)"
                if e.offset_m > i.capture_m
                else f"its tip stays {-e.depth_m * 1e3:.3g} mm outside {i.hole}'s mouth"
            )
            plan.reason = f"{i.name} cannot enter {i.hole} at the located pose: {where}"
            plan.plan_s = time.perf_counter() - t0
            return plan
        plan.heights_m[i.name] = e.depth_m
    # the engagement order: the largest height first; equal heights together (round before diamond)
    tol = fixture.tolerances.touch_m
    groups: list[list[Insert]] = []
    for i in sorted(ins, key=lambda i: -plan.heights_m[i.name]):
        if groups and abs(plan.heights_m[groups[-1][0].name] - plan.heights_m[i.name]) <= tol:
            groups[-1].append(i)
        else:
            groups.append([i])
    plan.order = [tuple(i.name for i in g) for g in groups]
    # the start: above every tip (nothing engaged), or the plan cannot begin with the approach
    start = fixture.start
    inside = [i for i in ins if engagement(fixture, start, i).engaged]
    if inside and len(inside) == len(ins) and seated(fixture, start):
        # already located: nothing to insert; the run only holds the part with the seating push
        plan.start_state = goal_state(fixture)
        plan.seat_wrench, plan.seat_wrench_com, held = seat_push(fixture, G, u, s)
        plan.ok = held is None
        plan.reason = held or "already located at the start pose: every pin in its hole, every rest touching"
        plan.plan_s = time.perf_counter() - t0
        return plan
    # a part whose every pin (or the shaft) is already in past the chamfers (a shaft cocked in its
    # bore) stays in: its holes are where the pose says, and lifting it out would lose them. It is
    # seated from where it is, upright, on the line the run re-centres on them (InsertionRun).
    D = plan.descent_pose
    in_bore = started_in(fixture)
    if in_bore:
        plan.start_state = frozenset(i.name for i in ins)
        groups = []
        prev = start
    else:
        # a part partly in (a shaft dropped tilted into the chamfer) is lifted straight out first:
        # the approach below rises along the axis before it turns and moves sideways
        h_top = plan.heights_m[groups[0][0].name]
        staging = D.translated((h_top + s.lead_m) * u)
        poses = [start]
        rise = float((staging.p_world - start.p_world) @ u)
        if rise > 0.0:  # lift first: the part never moves sideways lower than the staging height
            poses.append(start.translated(rise * u))
        poses += _over_staging(fixture, poses.pop(), staging, u, settings)
        guide = poses[:1]
        for a, b in zip([*poses], [*poses[1:], staging], strict=True):
            guide += [pose_between(a, b, k / 4) for k in range(1, 5)]
        ok, w, why, _, _, _ = _push(fixture, staging, [], u, settings)
        plan.stages.append(Stage("", (), "free", guide, w, (), f"approach to the staging pose: {why}"))
        if not ok:
            plan.reason = f"the approach to the staging pose is beyond the hand: {why}"
            plan.plan_s = time.perf_counter() - t0
            return plan
        prev = staging
    # the insertions, down the axis
    engaged: list[str] = []
    for k, g in enumerate(groups):
        h = plan.heights_m[g[0].name]
        nxt = plan.heights_m[groups[k + 1][0].name] if k + 1 < len(groups) else 0.0
        past = max(i.capture_m - i.play_m for i in g) + s.engage_margin_m
        end_h = max(h - past, 0.5 * (h + nxt))
        end = D.translated(end_h * u)
        names = [*engaged, *(i.name for i in g if i.kind != "bore")]
        pin_names = [n for n in names if n in {p.name for p in fixture.pins}] + [i.name for i in g if i.kind == "bore"]
        ok, w, why, touching, wedge, margin = _push(fixture, end, pin_names, u, settings)
        label = ", ".join(i.name for i in g)
        st = Stage(g[0].name, tuple(i.name for i in g[1:]), "insert", [prev, end], w, touching,
                   f"insert {label} along the axis: {why}", wedge, margin)  # fmt: skip
        plan.stages.append(st)
        if not ok:
            plan.reason = f"no push inserts {label} without jamming: {why}"
            plan.plan_s = time.perf_counter() - t0
            return plan
        if wedge is not None and wedge > fixture.tolerances.wedge_force:
            plan.reason = (
                f"{label} wedges on the way in: {', '.join(touching)} hold forces that balance with no push "
                f"({wedge:.3g} of the total normal force), whatever the push"
            )
            plan.plan_s = time.perf_counter() - t0
            return plan
        engaged += [i.name for i in g]
        prev = end
    # the seating: down to the located pose (or turned away from its stops), the rests (or the bore's
    # bottom) closing together, then into the stops; the push slides down the pins, and the stops
    # where they touch on the way down (no turn opens them)
    rests = [loc.name for loc in fixture.locators] + [f"{b.name}.bottom" for b in fixture.bores]
    slide_on = [p.name for p in fixture.pins] + [b.name for b in fixture.bores]
    slide_on += list(seat_at(fixture, G, u).stop_names)
    just_above = D.translated(min(s.engage_margin_m, 0.5 * float((prev.p_world - G.p_world) @ u)) * u)
    ok, w, why, touching, wedge, margin = _push(fixture, just_above, slide_on, u, settings)
    why = why if plan.turn is None else f"{plan.turn.reason}; {why}"
    seat = Stage(rests[0], tuple(rests[1:]), "seat", [prev, G] if plan.turn is None else [prev, D, G], w, touching,
                 f"seat on {', '.join(rests)}: {why}", wedge, margin)  # fmt: skip
    plan.stages.append(seat)
    if not ok:
        plan.reason = f"no push seats the part on {', '.join(rests)} without jamming: {why}"
        plan.plan_s = time.perf_counter() - t0
        return plan
    plan.seat_wrench, plan.seat_wrench_com, held = seat_push(fixture, G, u, s)
    if held is not None:
        plan.reason = held
        plan.plan_s = time.perf_counter() - t0
        return plan
    plan.ok = True
    seq = " → ".join(",".join(g) for g in plan.order)
    plan.reason = f"approach, insert {seq} along the axis, seat on {', '.join(rests)}"
    ends = [float((st.poses[-1].p_world - G.p_world) @ u) for st in plan.stages[:-1]]
    if in_bore:
        plan.reason = f"already in past the chamfers: seat on {', '.join(rests)} from the start, upright"
        ends = [float((start.p_world - G.p_world) @ u)]  # a back-off rises to where the part started
    plan.policy = insertion_policy(fixture, plan.states, [st.kind for st in plan.stages], ends, s)
    plan.plan_s = time.perf_counter() - t0
    return plan


def started_in(fixture: Fixture) -> bool:
    """Whether every pin (or the shaft) starts in its hole past both chamfers, without the part located.

    Then the plan seats the part from its start (:func:`plan_insertion`): the pins are in their
    holes' bores, each hole's place known to within the play from the pose.
    """
    start = fixture.start
    ins = inserts(fixture)
    if not ins or seated(fixture, start):
        return False
    for i in ins:
        e = engagement(fixture, start, i)
        if not e.engaged or e.depth_m < deep_m(fixture, i):
            return False
    return True


@dataclass(frozen=True)
class SeatTurn:
    """The seating's turn into the stops about the round pin's axis (:func:`seat_turn`)."""

    pin: str
    descent: Pose  # the located pose turned away from the stops: where the insertion goes down to
    angle_rad: float  # that turn
    axis_world: FloatArray  # unit, ±u: the turn toward the stops (right-handed)
    point_world: FloatArray  # on the pin's axis
    # the push about the centre of mass (at the located pose) that turns the part about the pin's axis
    # by 1 N·m there with no force on the pin: ``[m (a × r), I_a a] / (I_a + m |a × r|²)``, r from the axis
    unit_com: FloatArray
    inertia_kgm2: float  # about the pin's axis
    max_torque_Nm: float  # the stops' part of the seating push about the pin's axis: the turn's push at most
    speed_radps: float  # the turn's speed toward the stops (``seat_turn_speed_mps`` at the farthest stop)
    reason: str


def _over_staging(fixture: Fixture, top: Pose, staging: Pose, u: FloatArray, settings: Settings) -> list[Pose]:
    """The approach's waypoints from ``top`` (the start, lifted to the staging height when lower) before the staging pose: ``[top]``, or the sideways move at a clear height.

    The straight move from ``top`` to ``staging`` turns and moves the part sideways as it comes
    down: a part tilted at the start, or a staging pose below a stop's top, brings its lowest
    point onto a pin's tip or against a stop before it is over its pins. Where the straight move's
    lowest point (the part's collision points, sampled along it) comes below the clear level, every
    pin's tip and every stop's top ``lead_m`` down, the part instead rises (if need be), moves
    sideways and turns at a height where it clears them all the way, and comes down to the staging
    pose along the axis: ``[top, top raised, staging raised]``.
    """
    from fixplan.geometry.collision import collision_points

    tops = [float((p.p_world + p.length_m * p.axis_world) @ u) for p in fixture.pins]
    seat = seat_at(fixture, located_pose(fixture), u)
    radius = {loc.name: loc.radius_m for loc in fixture.locators}
    tops += [float(c.point_world @ u) + radius[c.owner] for c in seat.stops]
    if not tops:
        return [top]
    clear = max(tops) + settings.insertion.lead_m
    pts, radii = collision_points(fixture.workpiece.shape, settings.engine.rim_points)

    def lowest(pose: Pose) -> float:
        return float(np.min((pts @ pose.R_world_body.T + pose.p_world) @ u - radii))

    def deficit(a: Pose, b: Pose) -> float:
        """How far the part's lowest point comes below the clear level on the way from ``a`` to ``b`` (``b`` excluded).

        The hand's turn lags the guide's: the part is taken as turned as the guide or still as at ``top``.
        """
        poses = [pose_between(a, b, k / 8) for k in range(8)]
        return clear - min(min(lowest(p), lowest(Pose(top.R_world_body, p.p_world))) for p in poses)

    if deficit(top, staging) <= 0.0:
        return [top]
    h = max(float((staging.p_world - top.p_world) @ u), 0.0)
    for _ in range(8):  # raise the sideways move until it clears (each time by what it lacked)
        a, b = top.translated(h * u), staging.translated(float((top.p_world - staging.p_world) @ u + h) * u)
        lack = max(deficit(a, b), clear - lowest(b))
        if lack <= 0.0:
            break
        h += lack
    return [top, a, b] if h > 0.0 else [top, b]


def seat_turn(fixture: Fixture, G: Pose, u: FloatArray, s: InsertionSettings) -> SeatTurn | None:
    """The turn into the stops: the part goes down turned away from them about its round pin's axis, then turns into them on the rests; None when there is no such turn.

    A face sliding down along a stop that touches it at ``G`` meets the stop's tip with the face's
    lower edge wherever the pin's play puts it on the stop's side, and catches there. With one
    round pin (no other pin or bore: those fix the turn about it) the part is free to turn about
    the pin's axis: the descent is ``G`` turned by the least angle that opens every stop's gap by
    ``stop_clearance_m`` (at most ``stop_turn_max_rad``), when one direction opens them all (a
    stop's gap opens at ``n·(a × (p − c))`` per radian about ``a``, ``n`` its normal into the part,
    ``p`` its contact, ``c`` on the pin's axis) and the rests still touch there.
    """
    seat = seat_at(fixture, G, u)
    ins = inserts(fixture)
    if not seat.stops or s.stop_clearance_m <= 0.0 or len(ins) != 1 or ins[0].kind != "round":
        return None
    pin = next(p for p in fixture.pins if p.name == ins[0].name)
    c = pin.p_world
    rates = np.array([float(k.normal_world @ np.cross(u, k.point_world - c)) for k in seat.stops])
    if not (np.all(rates > 0.0) or np.all(rates < 0.0)):
        return None  # no turn about the pin opens them all
    a = -u if rates[0] > 0.0 else u  # the turn toward the stops closes their gaps
    angle = min(s.stop_clearance_m / float(np.min(np.abs(rates))), s.stop_turn_max_rad)
    R = exp_so3(-angle * a)
    D = Pose(R @ G.R_world_body, c + R @ (G.p_world - c))
    closing = [loc for loc in fixture.locators if loc.name not in seat.stop_names]
    if np.any(np.abs(locator_gaps(fixture.workpiece, D, closing)) > fixture.tolerances.touch_m):
        return None  # turned, the part would leave a rest
    wp = fixture.workpiece
    com = G.point_world_from_body(wp.com_body)
    lever = np.cross(a, com - c)
    I_a = float(a @ (G.R_world_body @ wp.inertia_body @ G.R_world_body.T) @ a)
    I_pin = I_a + wp.mass_kg * float(lever @ lever)
    unit = np.concatenate([wp.mass_kg * lever, I_a * a]) / I_pin
    _, _, stops = seat_parts(fixture, G, u, s)
    torque = float(a @ (stops[3:] + np.cross(com - c, stops[:3])))
    reach = max(float(np.linalg.norm(np.cross(u, k.point_world - c))) for k in seat.stops)
    names = ", ".join(seat.stop_names)
    why = f"down turned {np.degrees(angle):.3g}° about {pin.name} away from {names}, then into {names} on the rests"
    return SeatTurn(pin.name, D, angle, a, c.copy(), unit, I_pin, torque, s.seat_turn_speed_mps / reach, why)


def with_seating(plan: InsertionPlan, fixture: Fixture, s: InsertionSettings) -> None:
    """Fill ``plan``'s seating across the axis from ``fixture`` at its located pose: the stops, the turn into them, the seating push's side and stops parts."""
    G, u = plan.goal, plan.axis_world
    plan.stops = seat_at(fixture, G, u).stop_names
    plan.turn = seat_turn(fixture, G, u, s)
    _, plan.seat_side_com, plan.seat_stops_com = seat_parts(fixture, G, u, s)


def seat_parts(
    fixture: Fixture, pose: Pose, u: FloatArray, s: InsertionSettings
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The seating push's three parts about the centre of mass at ``pose``: the press along ``−u``, the round pin's seated side, the stops (:func:`seat_push`)."""
    seat = seat_at(fixture, pose, u)
    weight = fixture.weight_N
    com = pose.point_world_from_body(fixture.workpiece.com_body)
    press = np.concatenate([-s.seat_press * weight * u, np.zeros(3)])
    F_side = s.seat_side * weight * seat.side_world
    side = np.concatenate([F_side, np.cross(seat.at_world - com, F_side)])
    stops = np.zeros(6)
    for name in seat.stop_names:
        cs = [c for c in seat.stops if c.owner == name]
        n = sum((c.normal_world for c in cs), np.zeros(3))
        n = n - float(n @ u) * u  # across the axis: the rests take the press along it
        norm = float(np.linalg.norm(n))
        if norm == 0.0:
            continue
        F_stop = -s.seat_side * weight * n / norm
        stops += np.concatenate([F_stop, np.cross(np.mean([c.point_world for c in cs], axis=0) - com, F_stop)])
    return press, side, stops


def seat_push(
    fixture: Fixture, pose: Pose, u: FloatArray, s: InsertionSettings
) -> tuple[FloatArray, FloatArray, str | None]:
    """The seating push at the located pose, about the body origin and about the centre of mass, and why it does not hold the part there (None: it does).

    ``seat_press`` weights along ``−u`` through the centre of mass, ``seat_side`` weights toward
    the round pin's contact, along a line through that contact (no turn about the pin: the diamond
    pin, centred in its play, takes none), and ``seat_side`` weights into every stop (a locator
    facing across ``u``, :func:`~fixplan.locating.seat_at`), across ``u`` through its contact: each
    part of the push is balanced by the contacts it presses alone (the rests, the pin's seated
    side, the stop), so every contact of the located pose is loaded. Classified on the rests, the
    pins and the stops at ``pose``: ``held``.
    """
    from fixplan.jamming import classify

    seat = seat_at(fixture, pose, u)
    com = pose.point_world_from_body(fixture.workpiece.com_body)
    w_com = sum(seat_parts(fixture, pose, u, s), np.zeros(6))
    w = shift_wrench(w_com, com, pose.p_world)
    touching = sorted({c.owner for c in seat.contacts.contacts})
    if not touching:
        return w, w_com, "nothing touches the part at the located pose: no seat"
    res = classify(fixture, [w], touching, pose=pose, jobs=1)[0]
    if res.mode != "held":
        return w, w_com, f"the seating push does not hold the part at the located pose: it {res.mode} ({res.reason})"
    return w, w_com, None


# -- the plan as the planner's result ---------------------------------------------------------------
def transitions_of(fixture: Fixture, plan: InsertionPlan) -> list[Any]:
    """The stages as :class:`~fixplan.planner.fine.Transition` (what ``solve`` reports and writes)."""
    from fixplan.planner.execute import mass_speed
    from fixplan.planner.fine import Transition, twist_from_pose

    wp = fixture.workpiece
    out = []
    states = plan.states
    for k, st in enumerate(plan.stages):
        n = max(len(st.poses) - 1, 1)
        found = bool(np.all(np.isfinite(st.wrench)))
        length = 0.0
        for a, b in zip(st.poses[:-1], st.poses[1:], strict=True):
            M = contact_set(fixture, a, []).mass_matrix
            length += mass_speed(twist_from_pose(a, b, wp.com_body), M, wp.mass_kg)
        out.append(
            Transition(
                tuple(sorted(states[k])), st.target or "staging", "slide" if states[k] else "free", list(st.poses),
                np.tile(st.wrench, (n, 1)), np.full(n, np.nan if st.margin_N is None else st.margin_N),
                found, st.reason, 0.0, 0.0, "not run", found=np.full(n, found), segment_reasons=[st.reason] * n,
                cost=length, formulation="insertion", together=st.together,
            )
        )  # fmt: skip
    return out


# -- the verification ------------------------------------------------------------------------------
class InsertionRun:
    """The hand along an insertion plan, one :meth:`command` per tick (module text)."""

    def __init__(
        self,
        world: Fixture,
        plan: InsertionPlan,
        settings: InsertionSettings,
        noise: ExecutionNoise | None = None,
        tick_s: float = 1e-3,
        *,
        execution: ExecutionSettings = DEFAULT.execution,
        delay_s: float = 0.0,
    ):
        """The run of ``plan`` on ``world``.

        ``settings`` are the insertion's; ``execution`` say when a contact counts (``contact_gap_m``)
        and when the part is at rest (``stall_speed_mps``), as for the executor
        (:func:`verify_insertion` passes its profile's).

        ``delay_s``: how late the push this run asks for reaches the part (an operator who follows
        it in a haptic session: their reaction, and the guidance's update period). The hand's servo
        is a critically damped PD on the part's pose: without delay its phase margin is 76°, and a
        delay ``τ`` costs ``2.06 ω τ`` rad of it at crossover, all of it at ``ω τ ≈ 0.64`` (12 rad/s
        and 55 ms: a session whose operator reacts 50 ms late diverged). With a delay each
        frequency is held to ``delay_bandwidth / τ`` and the turn's gains act per principal axis
        (the inertia tensor, not the largest moment: about a slender shaft's own axis the largest
        moment made the servo 4× faster, 50 rad/s). 0 (the verification): the gains as set.
        """
        self.world = world
        self.plan = plan
        self.s = settings
        self.execution = execution
        self.u = plan.axis_world
        self.noise = noise or ExecutionNoise()
        self.rng = np.random.default_rng(self.noise.seed)
        wp = world.workpiece
        self.m = wp.mass_kg
        self.I_max = float(np.max(np.linalg.eigvalsh(np.atleast_2d(wp.inertia_body))))
        self.delay_s = delay_s
        cap = settings.delay_bandwidth / delay_s if delay_s > 0.0 else np.inf
        self.axial_omega = min(settings.axial_omega_radps, cap)  # the servo's frequencies [rad/s]
        self.lateral_omega = min(settings.lateral_omega_radps, cap)
        self.rot_omega = min(settings.rot_omega_radps, cap)
        self.weight_N = world.weight_N
        self.inserts = inserts(world)
        self.rests = tuple(loc.name for loc in world.locators)
        self.states = plan.states
        self.goal = self.states[-1]
        self.index = 0  # the current transition
        self.log = ExecutionLog()
        self.tick_s = tick_s
        self._debounced = Debounce(settings.dwell_s, initial=frozenset())
        self._t_stage = 0.0
        self._settled: float | None = None
        self._progress: tuple[float, float] | None = None  # (height, since)
        self._seating = len(self.states) == 1  # located at the start: the seating push from the first tick
        if self._seating:
            self.log.event(0.0, "hold", "located at the start: the seating push")
        # the hand's push along the axis is capped at the largest planned one (beyond carrying the part)
        planned = [
            float(abs(np.asarray(st.wrench[:3]) @ self.u + self.weight_N * _up(world) @ self.u))
            for st in plan.stages
            if np.all(np.isfinite(st.wrench))
        ]
        self.cap_N = max(planned, default=0.0) + self.s.seat_press * self.weight_N
        # the guide after the approach runs straight down the axis at the insertion speed
        self._h_stage_start = 0.0
        self._ref_h0 = 0.0
        # the recovery (module insertion_policy): the guide's located pose (re-centred at a back-off),
        # where the engaged holes were seen, the retries spent, the back-off under way
        self.policy = plan.policy
        self._goal = plan.descent_pose
        self._recentring = Recentring(world, plan.descent_pose, self.u, self.inserts)
        self._retries = 0
        self._recovery_t0: float | None = None
        self._backoff: tuple[float, float, float] | None = None  # (target height, since, height then)
        self._spent = ""  # why the recovery could not go on (the budget), for the failure's reason
        # the seating stage once what the descent closes is pressed (module text): the stops are not
        # closed by the descent; the hand presses the round pin's seated side and turns the part into
        # them (or presses them) while it still carries the part, on lightly loaded rests
        self._closed_by_descent = self.goal - set(plan.stops)
        self._across = False  # latched until a back-off
        self._turn_integral = 0.0  # [rad] the turn's speed error, integrated
        self._turned = 0.0  # [rad] the turn toward the stops so far (its progress)
        self._stops_pressed = False  # every stop pressed in the seating stage: the press along the axis too
        if plan.stages and plan.stages[0].kind != "free":  # started in its holes: down from where it is,
            self._in_from_start(world.start)  # on the line through the holes seen there

    @property
    def done(self) -> bool:
        return self.log.outcome != "running"

    def _turn(self, pose: Pose, rates: FloatArray) -> FloatArray:
        """The moment that gives the part the angular acceleration ``rates`` [rad/s²]: ``I rates``.

        With a delay the inertia tensor in world axes; without, the largest principal moment for
        every axis, as the verification has always done (stiffer about the lighter axes).
        """
        if self.delay_s <= 0.0:
            return self.I_max * rates
        R = pose.R_world_body
        return (R @ np.atleast_2d(self.world.workpiece.inertia_body) @ R.T) @ rates

    def height_m(self, pose: Pose) -> float:
        """The part's height above the nominal located pose along the axis."""
        return float((pose.p_world - self.plan.goal.p_world) @ self.u)

    def observe(self, pose: Pose, pressed: tuple[str, ...]) -> State:
        """The state: the engaged pins (from the pose) and the pressed rests (and a bore's bottom)."""
        state = {i.name for i in self.inserts if engagement(self.world, pose, i).engaged}
        state |= {n for n in pressed if n in self.rests}
        for b in self.world.bores:
            if b.name in state and b.name in pressed and self._bottom_touches(pose, b.name):
                state.add(f"{b.name}.bottom")
        return frozenset(state)

    def _bottom_touches(self, pose: Pose, bore: str) -> bool:
        b = next(x for x in self.world.bores if x.name == bore)
        tol = self.world.tolerances.touch_m + self.execution.contact_gap_m
        return bottom_gap_m(self.world, pose, b) <= tol

    def _reference(self, t: float) -> tuple[Pose, FloatArray, bool]:
        """The guide's pose and velocity now, and whether the hand pushes down the axis (stiff axial servo)."""
        st = self.plan.stages[min(self.index, len(self.plan.stages) - 1)]
        if st.kind == "free":
            poses = st.poses
            seg = [float(np.linalg.norm(b.p_world - a.p_world)) for a, b in zip(poses[:-1], poses[1:], strict=True)]
            total = sum(seg)
            dist = min(self.s.approach_speed_mps * (t - self._t_stage), total)
            k, acc = 0, 0.0
            while k < len(seg) - 1 and acc + seg[k] < dist:
                acc += seg[k]
                k += 1
            f = 0.0 if seg[k] <= 0.0 else min((dist - acc) / seg[k], 1.0)
            a, b = poses[k], poses[k + 1]
            ref = pose_between(a, b, f)
            v = np.zeros(6)
            if dist < total and seg[k] > 0.0:
                v[:3] = self.s.approach_speed_mps * (b.p_world - a.p_world) / seg[k]
            return ref, v, False
        if self._backoff is not None:  # a back-off: up the axis to its height, on the re-centred line
            target, since, h0 = self._backoff
            h = h0 + self.s.insert_speed_mps * (t - since)
            v = np.zeros(6)
            if h < target:
                v[:3] = self.s.insert_speed_mps * self.u
            return self._goal.translated(min(h, target) * self.u), v, True
        # down the axis from where the insertion began, on the located pose's line (re-centred by a back-off),
        # to lead_m below it: the servo's push at a stall (held to a delay: as deep as its gain is less)
        h = self._ref_h0 - self.s.insert_speed_mps * (t - self._t_stage)
        v = np.zeros(6)
        floor = self.s.lead_m * (self.s.axial_omega_radps / self.axial_omega) ** 2
        if h > -floor:
            v[:3] = -self.s.insert_speed_mps * self.u
        h = max(h, -floor)
        return self._goal.translated(h * self.u), v, True

    def command(self, t: float, pose: Pose, twist: FloatArray, pressed: tuple[str, ...]) -> FloatArray:
        """The push now (about the body origin, world axes)."""
        state = self.observe(pose, pressed)
        if self.policy is not None:
            self._see_holes(pose)
        self._debounce(t, state, pose)
        if self.done:
            return np.zeros(6)
        wp = self.world.workpiece
        com = pose.point_world_from_body(wp.com_body)
        carry = -self.world.gravity_wrench()
        v, w_ang = twist[:3], twist[3:]
        if self._seating:
            seat = self.plan.seat_wrench_com if self.plan.seat_wrench_com is not None else np.zeros(6)
            w_com = carry + seat
            if self.delay_s > 0.0:
                w_com[3:] += self._turn(pose, -2.0 * self.rot_omega * w_ang)
            else:  # the verification's arithmetic, as it always was
                w_com[3:] += -self.I_max * 2.0 * self.rot_omega * w_ang
            w_com[:3] += -self.m * 2.0 * self.lateral_omega * (v - float(v @ self.u) * self.u)
            self._check_settled(t, state, twist)
            return self._noisy(shift_wrench(w_com, com, pose.p_world))
        ref, v_ref, axial = self._reference(t)
        e = ref.p_world - pose.p_world
        ev = v_ref[:3] - v
        e_ax, ev_ax = float(e @ self.u), float(ev @ self.u)
        e_lat, ev_lat = e - e_ax * self.u, ev - ev_ax * self.u
        wa = self.axial_omega
        wl = self.lateral_omega if axial else self.axial_omega
        f_ax = self.m * (wa * wa * e_ax + 2.0 * wa * ev_ax)
        if axial:
            f_ax = min(max(f_ax, -self.cap_N), self.cap_N)
        F = f_ax * self.u + self.m * (wl * wl * e_lat + 2.0 * wl * ev_lat)
        wr = self.rot_omega
        T = self._turn(pose, wr * wr * log_so3(ref.R_world_body @ pose.R_world_body.T) - 2.0 * wr * w_ang)
        w_com = carry + np.concatenate([F, T])
        if self._press_across(state):
            w_com = self._across_push(carry, f_ax, v, w_ang, pressed)
        if self._backoff is not None:
            self._check_backoff(t, pose)
        elif axial:
            self._check_progress(t, pose)
        return self._noisy(shift_wrench(w_com, com, pose.p_world))

    def _press_across(self, state: State) -> bool:
        """Whether the seating stage presses across the axis now: once what the descent closes is pressed (latched until a back-off); never without stops."""
        p = self.plan
        if not p.stops or p.seat_side_com is None or self._backoff is not None or self.index >= len(p.stages):
            return False
        if p.stages[self.index].kind == "seat" and self._closed_by_descent <= state:
            self._across = True
        return self._across

    def _across_push(
        self, carry: FloatArray, f_ax: float, v: FloatArray, w_ang: FloatArray, pressed: tuple[str, ...]
    ) -> FloatArray:
        """The seating stage's push (about the centre of mass) once the rests are pressed: into the stops.

        Carrying the part and the axial servo's push keep the rests lightly loaded; damping across
        the axis and in turn; the seating push's part toward the round pin's seated side (through
        its contact: no turn about the pin). With a turn (:class:`SeatTurn`) a velocity loop turns
        the part about the pin's axis toward the stops at the turn's speed (its gain the stops'
        torque at rest, at most ``seat_turn_gain`` × the inertia about the pin per tick, and an
        integral at ``rot_omega_radps``), its push the turn's unit push (no force on the pin) times
        a torque up to the stops' part of the seating push; without one, that part itself (each
        stop's push through its contact). Once every stop is pressed the seating push's press along
        the axis is added (latched): a stop's friction would hold the lightly pressed part off its
        rests.
        """
        p = self.plan
        u, wl, wr = self.u, self.s.lateral_omega_radps, self.s.rot_omega_radps
        turn = p.turn
        spin = w_ang if turn is None else w_ang - float(w_ang @ turn.axis_world) * turn.axis_world
        F = f_ax * u - self.m * 2.0 * wl * (v - float(v @ u) * u)
        w = carry + np.concatenate([F, -self.I_max * 2.0 * wr * spin]) + np.asarray(p.seat_side_com)
        if self._stops_pressed or set(p.stops) <= set(pressed):
            self._stops_pressed = True
            w[:3] -= self.s.seat_press * self.weight_N * u
        if turn is None:
            return w + np.asarray(p.seat_stops_com)
        rate = float(w_ang @ turn.axis_world)
        self._turned += rate * self.tick_s
        gain = min(turn.max_torque_Nm / turn.speed_radps, self.s.seat_turn_gain * turn.inertia_kgm2 / self.tick_s)
        top = turn.max_torque_Nm / (gain * wr)  # the integral's bound: no wind-up past the stops' push
        self._turn_integral = min(max(self._turn_integral + (turn.speed_radps - rate) * self.tick_s, -top), top)
        torque = gain * (turn.speed_radps - rate + wr * self._turn_integral)
        torque = min(max(torque, -turn.max_torque_Nm), turn.max_torque_Nm)
        return w + torque * turn.unit_com

    def _noisy(self, w: FloatArray) -> FloatArray:
        if self.noise.force_noise <= 0.0:
            return w
        return w * (1.0 + self.noise.force_noise * self.rng.standard_normal(w.shape[0]))

    @property
    def _observed(self) -> State:
        """The debounced contact state."""
        return self._debounced.observed or frozenset()

    def _debounce(self, t: float, state: State, pose: Pose) -> None:
        if not self._debounced.observe(t, state):
            return
        key = tuple(sorted(state))
        if key and (not self.log.observed or self.log.observed[-1] != key):
            self.log.observed.append(key)
        if self.index < len(self.plan.stages) and self.plan.stages[self.index].kind == "free":
            return  # the approach is a pose target: it ends at the staging pose (step_time), whatever touches
        if self._backoff is not None:
            return  # backing off: pins come out on purpose; the state at the top says where to go on from
        later = [j for j in range(self.index + 1, len(self.states)) if self.states[j] <= state]
        if later:
            j = later[-1]
            if j > self.index + 1:
                self.log.counts["skipped_states"] += j - self.index - 1
                self.log.event(t, "skipped", f"reached {format_state(state)} directly")
            was_free = self.plan.stages[self.index].kind == "free"
            self.index = j
            self.log.event(t, "state", f"reached {format_state(state)}")
            if was_free:
                self._begin_insertion(t, pose)
            if j >= len(self.states) - 1:
                self._seating = True
                self.log.event(t, "hold", "every pin engaged and every rest pressed: the seating push")
        elif self.index > 0 and not (self.states[self.index] <= state):
            lost = sorted(self.states[self.index] - state)
            self.log.counts["lost_contact"] += 1
            what = f"lost {', '.join(lost)} in transition {self.index + 1} ({self._stage_label(self.index)})"
            if not self._reenter(t, pose, state, what):
                self._fail(t, what + self._spent, "lost contact")

    def _begin_insertion(self, t: float, pose: Pose) -> None:
        self._t_stage = t
        first = self.plan.stages[0]
        top = first.poses[-1] if first.kind == "free" else first.poses[0]  # the staging pose, or the start
        self._ref_h0 = min(self.height_m(pose), self.height_m(top))

    def _in_from_start(self, pose: Pose) -> None:
        """A part that starts with its pins in their holes (:func:`started_in`): the guide on the holes it sees there.

        Each hole's place is the pin's within the play (:class:`~.insertion_policy.Recentring`);
        the guide then runs down the axis from the start's height, upright.
        """
        for i in self.inserts:
            e = engagement(self.world, pose, i)
            self._recentring.observe(pose, i, e.depth_m)
        self._goal, how = self._recentring.guide()
        self.log.event(0.0, "state", f"started in: {how}")
        self._begin_insertion(0.0, pose)

    def step_time(self, t: float, pose: Pose) -> None:
        """Called every tick before :meth:`command`: the approach ends when its guide does (a pose target)."""
        st = self.plan.stages[self.index] if self.index < len(self.plan.stages) else None
        if st is None or st.kind != "free":
            return
        end = st.poses[-1]
        turn = float(np.linalg.norm(log_so3(end.R_world_body @ pose.R_world_body.T)))
        off = float(np.linalg.norm(pose.p_world - end.p_world))
        close = off <= self.s.align_tol_m and turn <= self.s.align_tol_rad and self._aimed(pose, end)
        total = sum(
            float(np.linalg.norm(b.p_world - a.p_world)) for a, b in zip(st.poses[:-1], st.poses[1:], strict=True)
        )
        if close and t - self._t_stage >= total / self.s.approach_speed_mps:
            self.index += 1
            self.log.event(t, "state", "at the staging pose: every hole over its pin")
            self._begin_insertion(t, pose)

    def _aimed(self, pose: Pose, staging: Pose) -> bool:
        """Every hole's mouth (a shaft's leading end) within ``align_capture_share`` of its capture of where ``staging`` puts it, across the axis."""
        for i in self.inserts:
            d = _entry_world(self.world, pose, i) - _entry_world(self.world, staging, i)
            d = d - float(d @ self.u) * self.u
            if float(np.linalg.norm(d)) > self.s.align_capture_share * i.capture_m:
                return False
        return True

    def _check_progress(self, t: float, pose: Pose) -> None:
        # down the axis, or (the seating's turn into the stops) along the farthest stop's path
        turn = self.plan.turn
        h = self.height_m(pose)
        if turn is not None:
            h -= self._turned * self.s.seat_turn_speed_mps / turn.speed_radps
        if self._progress is None or self._progress[0] - h >= self.s.stall_progress_m:
            self._progress = (h, t)
            return
        if t - self._progress[1] < self.s.stall_s:
            return
        self.log.counts["stalls"] += 1
        why = self.why_stuck(pose)
        if not self._recover(t, pose, why):
            self._fail(t, why + self._spent, "stall")

    # -- the recovery (module insertion_policy) ----------------------------------------------------
    def _stage_label(self, index: int) -> str:
        if index >= len(self.plan.stages):
            return "holding"
        st = self.plan.stages[index]
        return {"free": "the approach", "seat": "the seating"}.get(st.kind, f"inserting {', '.join(st.added)}")

    def _see_holes(self, pose: Pose) -> None:
        """Where the holes of the pins past both chamfers are (what a back-off re-centres the guide on)."""
        for i in self.inserts:
            e = engagement(self.world, pose, i)
            if e.engaged:
                self._recentring.observe(pose, i, e.depth_m)

    def _budget_left(self, t: float) -> bool:
        """Whether the policy allows one more retry now; else :attr:`_spent` says why not."""
        if self.policy is None:
            return False
        if self._retries >= self.policy.retries:
            self._spent = f"; {self._retries} retries spent (the policy's budget)"
            return False
        if self._recovery_t0 is not None and t - self._recovery_t0 > self.policy.time_s:
            self._spent = (
                f"; the recovery's {self.policy.time_s:g} s spent after {self._retries} "
                f"retr{'ies' if self._retries != 1 else 'y'}"
            )
            return False
        self._retries += 1
        self.log.counts["retries"] += 1
        if self._recovery_t0 is None:
            self._recovery_t0 = t
        return True

    def _recover(self, t: float, pose: Pose, why: str) -> bool:
        """A stalled stage: back off along the axis and re-centre the guide (False: no policy, or its budget is spent)."""
        if self.policy is None or not self._budget_left(t):
            return False
        h = self.height_m(pose)
        target = self.policy.backoff_height(h, self._retries - 1)
        self._goal, how = self._recentring.guide()
        self._backoff = (target, t, h)
        self._progress = None
        self._seating = False
        self._across = False
        self._turn_integral = 0.0
        self._stops_pressed = False
        self.log.event(
            t, "retry", f"{why}: back off to {target * 1e3:.3g} mm above the located pose, {how} "
            f"(retry {self._retries} of {self.policy.retries})",
        )  # fmt: skip
        return True

    def _check_backoff(self, t: float, pose: Pose) -> None:
        """Up the axis to the back-off's height; there, go on with the policy's entry of the state seen."""
        if self._backoff is None:  # pragma: no cover - called only while backing off
            return
        target = self._backoff[0]
        h = self.height_m(pose)
        if h >= target - self.s.stall_progress_m:
            self._backoff = None
            self._progress = None
            state = self.observe(pose, ())  # the rests are open up here: the engaged pins say the state
            self.index = max((j for j in range(1, len(self.states) - 1) if self.states[j] <= state), default=1)
            self._debounced.reset(state)
            self.log.event(t, "state", f"backed off to {h * 1e3:.3g} mm: {format_state(state)}, "
                                       f"{self._stage_label(self.index)} again")  # fmt: skip
            self._begin_insertion(t, pose)
            return
        if self._progress is None or h - self._progress[0] >= self.s.stall_progress_m:
            self._progress = (h, t)
        elif t - self._progress[1] >= self.s.stall_s:
            self.log.counts["stalls"] += 1
            wedged = self._wedged(pose)
            why = (
                f"could not back off in transition {self.index + 1} ({self._stage_label(self.index)}): the part "
                f"stays {h * 1e3:.3g} mm above the located pose, {(target - h) * 1e3:.3g} mm short of the back-off's "
                f"height (retry {self._retries})"
            )
            self._fail(t, why + (f"; {wedged}" if wedged else ""), "stall")

    def _reenter(self, t: float, pose: Pose, state: State, what: str) -> bool:
        """A pin the run had engaged is lost: go on with the policy's entry of the state seen (False: none, or no budget)."""
        if self.policy is None:
            return False
        engaged = frozenset(i.name for i in self.inserts) & state
        entry = self.policy.entry(engaged, False)
        if entry is None or entry.transition is None or not self._budget_left(t):
            return False
        self.index = entry.transition
        self._seating = False
        self._progress = None
        self._goal, how = self._recentring.guide()
        self.log.counts["policy_switches"] += 1
        self.log.event(
            t, "retry", f"{what}: the policy's {entry.action} from {format_state(state)} on to "
            f"{format_state(entry.next)}, {how} (retry {self._retries} of {self.policy.retries})",
        )  # fmt: skip
        self._begin_insertion(t, pose)
        return True

    def why_stuck(self, pose: Pose) -> str:
        """One line: the first pin the plan expects next that is not in its hole, and by how much it missed."""
        expect = self.states[min(self.index + 1, len(self.states) - 1)]
        for i in self.inserts:
            if i.name not in expect:
                continue
            e = engagement(self.world, pose, i)
            if e.engaged:
                continue
            miss = (
                f"its tip {-e.depth_m * 1e3:.3g} mm short of the mouth"
                if e.offset_m <= i.capture_m
                else f"{i.hole}'s axis {e.offset_m * 1e3:.3g} mm from its tip, beyond the capture "
                f"{i.capture_m * 1e3:.3g} mm (play + chamfers), {max(-e.depth_m, 0.0) * 1e3:.3g} mm above"
            )
            return f"{i.name} did not enter {i.hole} (transition {self.index + 1}, {self._stage_label(self.index)}): {miss}"
        missing = sorted(expect - self._observed)
        out = (
            f"stuck in transition {self.index + 1} ({self._stage_label(self.index)}): "
            f"{', '.join(missing) or 'the seat'} not reached, the part {self.height_m(pose) * 1e3:.3g} mm above "
            "the located pose and not moving down"
        )
        wedged = self._wedged(pose)
        return out + (f"; {wedged}" if wedged else "")

    def _wedged(self, pose: Pose) -> str:
        """The engaged pin whose hole is off its axis by the most beyond its play (what holds the part), or ""."""
        worst, name = 0.0, ""
        for i in self.inserts:
            e = engagement(self.world, pose, i)
            off = max(axis_offsets_m(self.world, pose, i))
            if e.engaged and off - i.play_m > worst:
                worst = off - i.play_m
                name = (
                    f"{i.name} wedged in {i.hole}: the hole's axis {off * 1e3:.3g} mm off the pin's (play "
                    f"{i.play_m * 1e3:.3g} mm), its tip {e.depth_m * 1e3:.3g} mm in"
                )
        return name

    def _check_settled(self, t: float, state: State, twist: FloatArray) -> None:
        if state >= self.goal and float(np.linalg.norm(twist[:3])) < self.execution.stall_speed_mps * 10:
            if self._settled is None:
                self._settled = t
            elif t - self._settled >= self.s.settle_s:
                self.log.outcome = "reached"
                self.log.reason = "every pin engaged, every rest pressed, at rest"
                self.log.transition_at_end = len(self.plan.stages)
                self.log.event(t, "reached", self.log.reason)
        else:
            self._settled = None

    def _fail(self, t: float, reason: str, kind: str) -> None:
        if not self.done:
            self.log.outcome = "failed"
            self.log.reason = reason
            self.log.failure_kind = kind
            self.log.transition_at_end = self.index + 1
            self.log.event(t, "failed", reason)


def _entry_world(fixture: Fixture, pose: Pose, ins: Insert) -> FloatArray:
    """Where ``ins`` enters at ``pose`` (world): its hole's mouth in the part, or a shaft's leading end's centre."""
    if ins.kind == "bore":
        peg = peg_body(fixture.workpiece, pose, next(b for b in fixture.bores if b.name == ins.name))
        return peg.base_world + peg.length_m * peg.axis_world
    return pose.point_world_from_body(fixture.workpiece.hole(ins.hole).p_body)


def _up(fixture: Fixture) -> FloatArray:
    g = np.asarray(fixture.gravity, dtype=float)
    n = float(np.linalg.norm(g))
    return -g / n if n > 0 else np.zeros(3)


def verify_insertion(
    world: Fixture,
    plan: InsertionPlan,
    *,
    settings: Settings = HAPTIC,
    noise: ExecutionNoise | None = None,
    max_sweeps: int | None = None,
    final_gap_m: float | None = None,
    max_penetration_m: float | None = None,
    trace_every_s: float | None = None,
) -> Verification:
    """Run ``plan`` (made on the nominal fixture) in the haptic loop on ``world`` and check the outcome (module text).

    ``settings`` (default: the ``haptic`` profile) give the engine, the rig, the insertion's, the
    verification's and the contact sensing's (``execution``) thresholds and the headroom
    (``search``); ``final_gap_m``, ``max_penetration_m``, ``trace_every_s`` and
    ``max_sweeps`` override single ones.
    """
    from fixplan.engine.simulator import Simulator
    from fixplan.errors import SolverError
    from fixplan.haptics.coordinates import coordinates_from_pose
    from fixplan.haptics.rig import haptic_rig
    from fixplan.planner.verify import final_gap_check, headroom, loop_checks, loop_measures

    vs = settings.verification
    s = settings.insertion
    final_gap_m = vs.final_gap_m if final_gap_m is None else final_gap_m
    max_penetration_m = vs.max_penetration_m if max_penetration_m is None else max_penetration_m
    trace_every_s = vs.trace_every_s if trace_every_s is None else trace_every_s
    sim = Simulator(world, max_iterations=max_sweeps, settings=settings.engine)
    R0 = world.start.R_world_body.copy()
    F_max, T_max, _ = world.hand_limits()
    run = InsertionRun(world, plan, s, noise, sim.dt, execution=settings.execution)
    wp = world.workpiece
    x0 = coordinates_from_pose(world.start, R0)
    carry0 = shift_wrench(-world.gravity_wrench(), world.start.point_world_from_body(wp.com_body), world.start.p_world)
    rig = haptic_rig(world, sim, x0, F_max, T_max, settings.haptic)
    rig = haptic_rig(world, sim, x0 + carry0 / rig.K, F_max, T_max, settings.haptic)
    loop = rig.loop
    contact_gap_m = settings.execution.contact_gap_m
    threshold = max(settings.execution.press_fraction * run.weight_N, 1e-6)
    commands: list[FloatArray] = []

    def operator(tt: float, device: Any) -> FloatArray:
        pose = sim.pose
        pressed = sim.in_contact(threshold, contact_gap_m)
        run.step_time(tt, pose)
        w = run.command(tt, pose, sim.twist, pressed)
        commands.append(np.array(w, dtype=float))
        return rig.operator_wrench(w, device)

    guide = sum(
        float(np.linalg.norm(b.p_world - a.p_world))
        for st in plan.stages
        for a, b in zip(st.poses[:-1], st.poses[1:], strict=True)
    )
    time_limit = s.time_factor * guide / s.insert_speed_mps + s.time_base_s
    if plan.policy is not None:  # the recovery's budget: a run that backs off may take this much longer
        time_limit += plan.policy.time_s
    trace_every = max(int(round(trace_every_s / sim.dt)), 1) if trace_every_s > 0 else 0
    try:
        rec = loop.run(time_limit, operator, trace_every=trace_every, until=lambda: run.done)
    except SolverError as exc:
        why = f"the simulated insertion diverged at t = {sim.time_s:.3f} s (transition {run.index + 1}): {exc}"
        run._fail(sim.time_s, why, "diverged")
        return Verification(
            passed=False, reason=why, failed_checks=["executor"], final_pose=sim.pose,
            max_penetration_m=sim.max_penetration_m, deadline_misses=None, tick_mean_us=None, tick_max_us=None,
            observed_sequence=list(run.log.observed), final_gaps_m={}, duration_s=sim.time_s,
            felt_force_max_N=None, execution=run.log,
        )  # fmt: skip
    if run.log.outcome == "running":
        run._fail(
            sim.time_s,
            f"timed out after {sim.time_s:.2f} s in transition {run.index + 1}: {run.why_stuck(sim.pose)}",
            "timeout",
        )
    pose = sim.pose
    reasons, checks = [], []
    if run.log.outcome != "reached":
        reasons.append(run.log.reason)
        checks.append("executor")
    gaps = seat_gaps_m(world, pose)
    final_gap_check(gaps, final_gap_m, checks, reasons)
    for i in run.inserts:
        mouth, tip = axis_offsets_m(world, pose, i)
        gaps[f"{i.name}.axis_offset"] = max(mouth, tip)
        if max(mouth, tip) > i.play_m * (1.0 + s.axis_play_rel) + final_gap_m:
            checks.append("pin axis")
            reasons.append(
                f"at the end {i.hole}'s axis is {max(mouth, tip) * 1e3:.3g} mm from {i.name}'s "
                f"(expected ≤ the play {i.play_m * 1e3:.3g} mm)"
            )
    push_F, push_T = loop_checks(rec, sim, max_penetration_m, vs, F_max, T_max, vs.limit_slack, checks, reasons)
    measures = loop_measures(rec, sim, trace_every)
    return Verification(
        passed=not reasons,
        reason="; ".join(reasons) if reasons else "every check passed",
        failed_checks=checks,
        **measures,
        **headroom(commands, 3, F_max, T_max, settings.search.limit_fraction, settings.search.binding_rel),
        observed_sequence=list(run.log.observed),
        final_gaps_m=gaps,
        execution=run.log,
        max_push_force_N=push_F,
        max_push_torque_Nm=push_T,
        saturated_ticks=loop.saturated_ticks,
        planner_wall_time_in_loop_s=0.0,
    )


def shifted_world(fixture: Fixture, offset_world: FloatArray, yaw_rad: float, with_start: bool = False) -> Fixture:
    """The fixture with its pins, bores and rests moved rigidly: turned by ``yaw_rad`` about the insertion axis through the first pin, then shifted by ``offset_world``.

    The located pose moves with them; the part's start stays (``with_start``: moves too, for a part
    that starts resting on them, where the world put it). What a pose error of the part in
    the hand looks like from the part: the plan (made on the nominal fixture) guides it to where
    the pins are not.
    """
    u = insertion_axis(fixture)
    pivot = (fixture.pins[0].p_world if fixture.pins else fixture.bores[0].p_world).copy()
    R = exp_so3(yaw_rad * u)

    def move(p: FloatArray) -> FloatArray:
        return pivot + R @ (np.asarray(p) - pivot) + offset_world

    pins = tuple(
        replace(
            p, p_world=move(p.p_world), axis_world=R @ p.axis_world,
            land_direction_world=None if p.land_direction_world is None else R @ p.land_direction_world,
        )
        for p in fixture.pins
    )  # fmt: skip
    bores = tuple(replace(b, p_world=move(b.p_world), axis_world=R @ b.axis_world) for b in fixture.bores)
    locators = tuple(replace(loc, p_world=move(loc.p_world)) for loc in fixture.locators)
    out = replace(fixture, pins=pins, bores=bores, locators=locators)
    if with_start:
        S = fixture.start
        out = replace(out, start=Pose(R @ S.R_world_body, move(S.p_world)))
    G = fixture.goal_pose
    if G is not None:
        goal = Pose(R @ G.R_world_body, move(G.p_world))
        out = replace(out, goal_given=goal, goal_pose=goal)
    return out


__all__ = [
    "InsertionPlan",
    "InsertionRun",
    "Stage",
    "goal_state",
    "plan_insertion",
    "seat_push",
    "shifted_world",
    "started_in",
    "transitions_of",
    "verify_insertion",
]
