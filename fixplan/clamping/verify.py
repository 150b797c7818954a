"""Clamping verified in the engine: clamps ramped in order, the hand let go, each load applied.

A clamp is modelled as an **external force on the part**: ``F_k d_k`` at the part's material
point under its tip (fixed in the body, so its lever follows the part), in fixed world axes,
added to the step's applied wrench about the body origin. Not as a contact with a prescribed
normal force: the engine's contact law has no such contact (a new local solver and its
kernels), and the analysis counts no friction at the clamp's tip either
(:mod:`fixplan.clamping.forces`), so the engine checks exactly the model the forces were
computed for. The tip's friction could only help a real clamp hold.

The run (``ClampSettings``):

1. the part at its located pose, held by the hand: the hand is a kinematic hold (after each
   step the part is put back at the located pose, at rest) while each clamp ramps linearly from
   0 to its force over ``ramp_s``, in the clamping order;
2. the hand lets go: the part stands ``settle_s`` under gravity and the clamps;
3. each load in turn ramps over ``ramp_s``, holds ``hold_s`` and ramps back down.

From the moment the hand lets go, every step records the largest displacement of the part's
points from the located pose (its shape's extreme points: a box's corners, a cylinder's rim
polygons, a polygon's vertices; the displacement of a rigid motion is largest at one of them)
the widest gap of a locator and the least normal force of the locators. The run passes when the
displacement stays within ``displacement_m`` and no locator's gap opens beyond it (contact is
kept). The least locator force is reported, not required: a rigid part with friction is
statically indeterminate, and the engine may settle in a balance where friction at one locator
unloads another that still touches (0 N) although the force program's balance gave it the
preload; the result then says so in its ``reason``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fixplan.engine.simulator import Simulator
from fixplan.geometry.collision import collision_points
from fixplan.model import Fixture
from fixplan.settings import DEFAULT, Settings

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Verification:
    """What the engine says of the clamped part."""

    passed: bool
    max_displacement_m: float  # largest displacement of a point of the part after the hand let go
    min_locator_force_N: float  # least locator normal force after the hand let go
    weakest_locator: str
    steps: int
    reason: str  # "" when passed
    per_load: dict[str, dict[str, float]] = field(default_factory=dict)  # name -> displacement, least force
    max_nsgs_error: float = 0.0  # largest NSGS residual of a step after the hand let go
    max_gap_m: float = 0.0  # the widest a locator's gap opened after the hand let go
    widest_gap_locator: str = ""

    def to_json(self) -> dict[str, Any]:
        return {
            "passed": self.passed,
            "max_displacement_m": self.max_displacement_m,
            "min_locator_force_N": self.min_locator_force_N,
            "weakest_locator": self.weakest_locator,
            "steps": self.steps,
            "max_nsgs_error": self.max_nsgs_error,
            "max_gap_m": self.max_gap_m,
            "loads": self.per_load,
            "reason": self.reason,
        }


def verify_clamping(
    fixture: Fixture,
    order: tuple[str, ...],
    forces_N: dict[str, float],
    points_world: dict[str, FloatArray],
    settings: Settings = DEFAULT,
) -> Verification:
    """Run the clamping stage in the engine (see the module docstring).

    ``points_world``: each clamp's point on the part at the located pose (where its force acts).
    """
    st = settings.clamp
    goal = fixture.goal
    sim = Simulator(fixture, settings=settings.engine)
    sim.set_state(goal)
    dt, d = sim.dt, fixture.dimension
    n_ramp = max(1, math.ceil(st.ramp_s / dt))
    n_settle = max(1, math.ceil(st.settle_s / dt))
    n_hold = max(1, math.ceil(st.hold_s / dt))
    clamps = {k.name: k for k in fixture.clamps}
    p_body = {name: goal.point_body_from_world(p) for name, p in points_world.items()}
    corners, _ = collision_points(fixture.workpiece.shape, settings.engine.rim_points)
    corners_goal = np.array([goal.point_world_from_body(b) for b in corners])

    def clamp_wrench(scale: dict[str, float]) -> FloatArray:
        """The clamps at ``scale[name] × force`` as one wrench about the body origin, world axes."""
        R = sim.pose.R_world_body
        w = np.zeros(6 if d == 3 else 3)
        for name, s in scale.items():
            f = s * forces_N[name] * clamps[name].direction_world
            lever = R @ p_body[name]
            if d == 3:
                w[:3] += f
                w[3:] += np.cross(lever, f)
            else:
                w[:2] += f
                w[2] += lever[0] * f[1] - lever[1] * f[0]
        return w

    # 1. held by the hand (a kinematic hold), the clamps ramped in order
    on: dict[str, float] = {}
    for name in order:
        for i in range(1, n_ramp + 1):
            on[name] = i / n_ramp
            sim.step(clamp_wrench(on))
            sim.set_state(goal)
    # 2-3. let go; settle; each load up, held, down
    worst: list[Any] = [
        0.0,
        math.inf,
        "",
        0.0,
        -math.inf,
        "",
    ]  # displacement, least force, its locator, NSGS error, widest gap, its locator

    def advance(extra: FloatArray, record: dict[str, float] | None) -> None:
        info = sim.step(clamp_wrench(on) + extra)
        pose = sim.pose
        moved = float(np.max(np.linalg.norm(corners @ pose.R_world_body.T + pose.p_world - corners_goal, axis=1)))
        reports = sim.contacts()
        least, who = min((r.normal_force_N, r.name) for r in reports)
        gap, opened = max((r.gap_m, r.name) for r in reports)
        if gap > worst[4]:
            worst[4], worst[5] = gap, opened
        worst[0] = max(worst[0], moved)
        worst[3] = max(worst[3], info.error)
        if least < worst[1]:
            worst[1], worst[2] = least, who
        if record is not None:
            record["max_displacement_m"] = max(record.get("max_displacement_m", 0.0), moved)
            record["min_locator_force_N"] = min(record.get("min_locator_force_N", math.inf), least)

    zero = np.zeros(6 if d == 3 else 3)
    clamped: dict[str, float] = {}
    for _ in range(n_settle):
        advance(zero, clamped)
    per_load = {"clamped": clamped}
    for load in fixture.loads:
        rec: dict[str, float] = {}
        for i in range(1, n_ramp + 1):
            advance(load.wrench * (i / n_ramp), rec)
        for _ in range(n_hold):
            advance(load.wrench, rec)
        for i in range(n_ramp - 1, -1, -1):
            advance(load.wrench * (i / n_ramp), None)
        per_load[load.name] = rec
    moved, least, who, err, gap, opened = worst
    reasons = []
    if moved > st.displacement_m:
        reasons.append(f"the part moved {moved:.3g} m (expected ≤ {st.displacement_m:g} m)")
    if gap > st.displacement_m:
        reasons.append(
            f"locator {opened} lost contact (its gap opened to {gap:.3g} m, expected ≤ {st.displacement_m:g} m)"
        )
    note = ""
    if not reasons and least < st.contact_N:
        note = (
            f"note: locator {who} touches but carries {least:.3g} N in the engine: a rigid part with friction is "
            "statically indeterminate, and the engine settles in a balance where friction elsewhere unloads it "
            "(the program's preload is one balance among many)"
        )
    return Verification(
        not reasons, moved, least, who, sim.steps, "; ".join(reasons) or note, per_load, float(err), float(gap), opened
    )
