"""The clamping stage played in the simulated haptic loop (:class:`~fixplan.haptics.loop.HapticLoop`).

The schedule is :class:`fixplan.clamping.stage.ClampStage`'s: while the hand holds, the device's
coupling holds the part and each clamp ramps in order (the person feels what the clamps push
through the part into the hand); then the hand lets go (the coupling's wrench and the device's
display drop to 0) and each load ramps, holds and ramps down. The engine applies the clamps and
the load as external wrenches. :func:`play_clamping` returns the stage's
:class:`~fixplan.clamping.stage.StageRecord`, its displacements measured from the pose where the
hand let go.
"""

from __future__ import annotations

import numpy as np

from fixplan.clamping.stage import ClampStage, StageRecord
from fixplan.haptics.loop import HapticLoop
from fixplan.settings import DEFAULT, Settings


def play_clamping(
    loop: HapticLoop, stage: ClampStage, watched: tuple[str, ...], settings: Settings = DEFAULT
) -> tuple[StageRecord, float]:
    """Play ``stage`` in ``loop`` (the operator keeps still); the record and the largest |felt| once let go [N, N·m]."""
    sim = loop.sim
    record = StageRecord.for_stage(stage, watched, settings, reference=sim.pose)
    still = np.zeros(6 if sim.dimension == 3 else 3)
    felt_after = 0.0
    for k in range(stage.n_ticks):
        tick = stage.at(k)
        if k == stage.n_hand:
            record.located = sim.pose  # the hand lets go: from here the part must stay put
        _, felt, _ = loop.tick(still, external=stage.wrench(tick, sim.pose), hand=tick.hand)
        last = sim.last
        record.observe(sim, tick, 0.0 if last is None else last.error)
        if not tick.hand:
            felt_after = max(felt_after, float(np.max(np.abs(felt))))
    return record, felt_after
