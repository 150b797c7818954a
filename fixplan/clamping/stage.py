"""The clamping stage as a schedule of engine steps, and what the engine does during it.

One schedule serves the engine's verification (:mod:`fixplan.clamping.verify`, the hand a
kinematic hold) and the haptic loop (``fixplan haptic --clamp``, the hand the person's coupling):

1. the hand holds the part while each clamp, in the clamping order, ramps linearly from 0 to its
   force over ``ramp_s``;
2. the hand lets go: the part stands ``settle_s`` under gravity and the clamps (case ``clamped``);
3. each ``[[load]]`` in turn ramps over ``ramp_s``, holds ``hold_s`` and ramps back down.

A clamp is an **external force on the part**: ``F_k d_k`` at the part's material point under its
tip (fixed in the body, so its lever follows the part), in fixed world axes, added to the step's
applied wrench about the body origin (why not a contact: :mod:`fixplan.clamping.verify`).

:class:`StageRecord` watches the part from the moment the hand lets go: the largest displacement
of its points from the pose where the stage began (its shape's extreme points: a box's corners, a
cylinder's rim polygons; a rigid motion's displacement is largest at one of them), and, for the
contacts the force program counted (the locators and the pins touching at the located pose), the
widest gap and the least normal force, per case, and each one's normal force at the end.
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
from fixplan.spatial import Pose

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class StageTick:
    """What the schedule asks of one engine step."""

    hand: bool  # the hand still holds the part
    scales: dict[str, float]  # clamp name -> fraction of its force applied
    load: FloatArray  # the process load's wrench about the body origin, world axes (zeros: none)
    phase: str  # for people: "K1 ramps", "settle", "drill up", "drill held", "drill down"
    case: str | None  # the case recorded at this step ("clamped", a load's name), None: not recorded per case


class ClampStage:
    """The clamping stage's schedule for a clamping order and its forces (see the module docstring)."""

    def __init__(
        self,
        fixture: Fixture,
        order: tuple[str, ...] | list[str],
        forces_N: dict[str, float],
        points_world: dict[str, FloatArray],
        dt_s: float,
        settings: Settings = DEFAULT,
    ):
        st = settings.clamp
        self.fixture = fixture
        self.order = tuple(order)
        self.forces_N = {k: float(forces_N[k]) for k in self.order}
        self.located = fixture.goal
        clamps = {k.name: k for k in fixture.clamps}
        self._direction = {k: clamps[k].direction_world for k in self.order}
        # the clamps' points are the part's, given at the goal (where the tips touch it)
        self._p_body = {k: fixture.goal.point_body_from_world(points_world[k]) for k in self.order}
        self.dimension = fixture.dimension
        self.n_ramp = max(1, math.ceil(st.ramp_s / dt_s))
        self.n_settle = max(1, math.ceil(st.settle_s / dt_s))
        self.n_hold = max(1, math.ceil(st.hold_s / dt_s))
        self.n_hand = self.n_ramp * len(self.order)  # steps with the hand holding
        per_load = 2 * self.n_ramp + self.n_hold
        self.n_ticks = self.n_hand + self.n_settle + per_load * len(fixture.loads)
        self._zero = np.zeros(fixture.ndof)

    def at(self, k: int) -> StageTick:
        """Step ``k`` (0-based) of the stage."""
        if not 0 <= k < self.n_ticks:
            raise IndexError(f"clamping stage step {k} (expected 0..{self.n_ticks - 1})")
        if k < self.n_hand:
            i, j = divmod(k, self.n_ramp)
            scales = dict.fromkeys(self.order[:i], 1.0) | {self.order[i]: (j + 1) / self.n_ramp}
            return StageTick(True, scales, self._zero, f"{self.order[i]} ramps", None)
        on = dict.fromkeys(self.order, 1.0)
        k -= self.n_hand
        if k < self.n_settle:
            return StageTick(False, on, self._zero, "settle", "clamped")
        k -= self.n_settle
        i, j = divmod(k, 2 * self.n_ramp + self.n_hold)
        load = self.fixture.loads[i]
        if j < self.n_ramp:
            return StageTick(False, on, load.wrench * ((j + 1) / self.n_ramp), f"{load.name} up", load.name)
        j -= self.n_ramp
        if j < self.n_hold:
            return StageTick(False, on, load.wrench, f"{load.name} held", load.name)
        j -= self.n_hold
        return StageTick(False, on, load.wrench * ((self.n_ramp - 1 - j) / self.n_ramp), f"{load.name} down", None)

    def clamp_wrench(self, scales: dict[str, float], pose: Pose) -> FloatArray:
        """The clamps at ``scales[name] × force`` as one wrench about the body origin, world axes, at ``pose``."""
        names = [k for k in self.order if k in scales]
        if not names:
            return np.zeros(self.fixture.ndof)
        f = np.array([scales[k] * self.forces_N[k] * self._direction[k] for k in names])  # (k, d)
        lever = np.array([self._p_body[k] for k in names]) @ pose.R_world_body.T
        if self.dimension == 3:
            m = lever[:, [1, 2, 0]] * f[:, [2, 0, 1]] - lever[:, [2, 0, 1]] * f[:, [1, 2, 0]]  # lever × f, row-wise
            return np.concatenate([f.sum(axis=0), m.sum(axis=0)])
        return np.array([*f.sum(axis=0), float(np.sum(lever[:, 0] * f[:, 1] - lever[:, 1] * f[:, 0]))])

    def wrench(self, tick: StageTick, pose: Pose) -> FloatArray:
        """Everything the stage applies at ``tick`` (clamps and load) about the body origin, world axes."""
        return self.clamp_wrench(tick.scales, pose) + tick.load


@dataclass
class StageRecord:
    """What the engine did from the moment the hand let go (see the module docstring)."""

    watched: tuple[str, ...]  # the contacts the force program counted (locators, touching pins)
    located: Pose
    corners_body: FloatArray
    max_displacement_m: float = 0.0
    min_force_N: float = math.inf
    weakest: str = ""
    max_gap_m: float = -math.inf
    widest: str = ""
    max_error: float = 0.0
    steps: int = 0
    per_case: dict[str, dict[str, float]] = field(default_factory=dict)
    final_forces_N: dict[str, float] = field(default_factory=dict)  # each watched contact's, at the last step

    @classmethod
    def for_stage(
        cls, stage: ClampStage, watched: tuple[str, ...], settings: Settings = DEFAULT, reference: Pose | None = None
    ) -> StageRecord:
        """A record of ``stage`` watching ``watched``; displacements from ``reference`` (default: the located pose)."""
        corners, _ = collision_points(stage.fixture.workpiece.shape, settings.engine.rim_points)
        return cls(tuple(watched), stage.located if reference is None else reference, np.asarray(corners, dtype=float))

    def verdict(self, settings: Settings = DEFAULT) -> tuple[bool, str]:
        """Whether the part stayed put with every watched contact kept, and why not (one line)."""
        limit = settings.clamp.displacement_m
        reasons = []
        if self.max_displacement_m > limit:
            reasons.append(f"the part moved {self.max_displacement_m:.3g} m (expected ≤ {limit:g} m)")
        if self.max_gap_m > limit:
            reasons.append(
                f"locator {self.widest} lost contact (its gap opened to {self.max_gap_m:.3g} m, expected ≤ {limit:g} m)"
            )
        return not reasons, "; ".join(reasons)

    def displacement_m(self, pose: Pose) -> float:
        """The largest distance of a point of the part at ``pose`` from where it is at the located pose."""
        a = self.corners_body @ pose.R_world_body.T + pose.p_world
        b = self.corners_body @ self.located.R_world_body.T + self.located.p_world
        return float(np.max(np.linalg.norm(a - b, axis=1)))

    def observe(self, sim: Simulator, tick: StageTick, error: float = 0.0, contacts: bool = True) -> None:
        """Record the step just taken (only once the hand has let go).

        ``contacts`` False records the displacement only: the contact reports cost a real-time
        tick a tenth of a millisecond, so the haptic loop samples them (its ``trace_every``).
        """
        if tick.hand:
            return
        moved = self.displacement_m(sim.pose)
        self.steps += 1
        self.max_displacement_m = max(self.max_displacement_m, moved)
        self.max_error = max(self.max_error, float(error))
        if tick.case is not None:
            rec = self.per_case.setdefault(tick.case, {})
            rec["max_displacement_m"] = max(rec.get("max_displacement_m", 0.0), moved)
        if not contacts:
            return
        watched = set(self.watched)
        reports = [r for r in sim.contacts() if r.name in watched]
        least, who = min((r.normal_force_N, r.name) for r in reports)
        gap, opened = max((r.gap_m, r.name) for r in reports)
        if least < self.min_force_N:
            self.min_force_N, self.weakest = least, who
        if gap > self.max_gap_m:
            self.max_gap_m, self.widest = gap, opened
        if tick.case is not None:
            rec = self.per_case[tick.case]
            rec["min_locator_force_N"] = min(rec.get("min_locator_force_N", math.inf), least)
        self.final_forces_N = {r.name: float(r.normal_force_N) for r in reports}

    def to_json(self) -> dict[str, Any]:
        return {
            "max_displacement_m": self.max_displacement_m,
            "min_locator_force_N": None if math.isinf(self.min_force_N) else self.min_force_N,
            "weakest_locator": self.weakest,
            "max_gap_m": None if math.isinf(self.max_gap_m) else self.max_gap_m,
            "steps": self.steps,
            "loads": self.per_case,
            "final_forces_N": self.final_forces_N,
        }
