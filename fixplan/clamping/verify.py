"""Clamping verified in the engine: clamps ramped in order, the hand let go, each load applied.

A clamp is modelled as an **external force on the part**: ``F_k d_k`` at the part's material
point under its tip (fixed in the body, so its lever follows the part), in fixed world axes,
added to the step's applied wrench about the body origin. Not as a contact with a prescribed
normal force: the engine's contact law has no such contact (a new local solver and its
kernels), and the analysis counts no friction at the clamp's tip either
(:mod:`fixplan.clamping.forces`), so the engine checks exactly the model the forces were
computed for. The tip's friction could only help a real clamp hold.

The run is the schedule of :mod:`fixplan.clamping.stage` with the hand a kinematic hold (after
each step while it holds, the part is put back at the located pose, at rest). The run passes when
the part's displacement stays within ``displacement_m`` and no contact the force program counted
(the locators, and the pins touching at the located pose) opens beyond it: contact is kept.

Each counted contact's normal force in the engine at the end of the run (the clamps on, every load
gone: the ``clamped`` case) is reported next to the force program's. The least locator force is
reported, not required: a rigid part with friction is statically indeterminate, and the engine may
settle in a balance where friction at one locator unloads another that still touches (0 N) although
the force program's balance gave it the preload. Measured on the library's clamped problems
(docs/fixture-format.md, "Clamps and process loads"), such a check would refuse clamping that
holds; the result says so in its ``reason`` instead.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fixplan.clamping.stage import ClampStage, StageRecord
from fixplan.engine.simulator import Simulator
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
    # each counted contact at the end of the run (clamps on, no load): the engine's normal force and
    # the force program's for the ``clamped`` case [N]
    locator_forces_N: dict[str, dict[str, float | None]] = field(default_factory=dict)

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
            "locator_forces_N": self.locator_forces_N,
            "reason": self.reason,
        }


def verify_clamping(
    fixture: Fixture,
    order: tuple[str, ...],
    forces_N: dict[str, float],
    points_world: dict[str, FloatArray],
    settings: Settings = DEFAULT,
    *,
    watched: tuple[str, ...] | None = None,
    program_forces_N: dict[str, float] | None = None,
) -> Verification:
    """Run the clamping stage in the engine (see the module docstring).

    ``points_world``: each clamp's point on the part at the located pose (where its force acts).
    ``watched``: the contacts the force program counted (default: the locators);
    ``program_forces_N``: their normal forces in the program's ``clamped`` case, reported beside
    the engine's.
    """
    st = settings.clamp
    goal = fixture.goal
    sim = Simulator(fixture, settings=settings.engine)
    sim.set_state(goal)
    stage = ClampStage(fixture, order, forces_N, points_world, sim.dt, settings)
    names = tuple(loc.name for loc in fixture.locators) if watched is None else tuple(watched)
    record = StageRecord.for_stage(stage, names, settings)
    for k in range(stage.n_ticks):
        tick = stage.at(k)
        info = sim.step(stage.wrench(tick, sim.pose))
        if tick.hand:  # a kinematic hold
            sim.set_state(goal)
        record.observe(sim, tick, info.error)
    moved, least, who = record.max_displacement_m, record.min_force_N, record.weakest
    gap, opened = record.max_gap_m, record.widest
    passed, why = record.verdict(settings)
    program = program_forces_N or {}
    forces: dict[str, dict[str, float | None]] = {
        name: {"engine_N": record.final_forces_N.get(name), "program_N": program.get(name)} for name in names
    }
    note = ""
    if passed and least < st.contact_N:
        note = (
            f"note: locator {who} touches but carries {least:.3g} N in the engine: a rigid part with friction is "
            "statically indeterminate, and the engine settles in a balance where friction elsewhere unloads it "
            "(the program's preload is one balance among many)"
        )
    return Verification(
        passed,
        moved,
        least,
        who,
        sim.steps,
        why or note,
        record.per_case,
        float(record.max_error),
        float(gap),
        opened,
        forces,
    )
