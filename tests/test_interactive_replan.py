"""The haptic session's guide for pins re-plans when its insertion run fails, and seats the part.

``Guide.update``: an :class:`~fixplan.interactive.session.InsertionGuide` whose run ended ``failed``
is dropped and a new one is planned from the pose the part is in; a part partly on its pins is
lifted straight out along the pins' axis before it moves (:func:`fixplan.planner.insertion.plan_insertion`).
``problems/housing-2-pins.toml`` started 20 mm above its located pose (the holes over their pins,
8 mm above the tips of its two 12 mm pins): its plan is the approach, both pins in one transition,
then down onto the rests. The first run is made to fail once both pins are in their holes, the
rests still open (its stage down onto the rests under way), as a stall past its retries does. The
guide re-plans once; the new plan lifts the part off the pins first when they are within the
chamfers, seats it from there when past them; and the session ends seated:
every rest within ``1e-4`` m, the penetration within ``1e-5`` m (measured: failed at 0.72 s, 11.3 mm
above the located pose, lifted to 13.9 mm, the staging height, seated at 2.15 s; or failed at 1.07 s,
3.87 mm above, the new plan its seating stage only, seated at 1.50 s; the rests' gaps below 1.1e-10 m,
the penetration 1.6e-12 m).
A run that fails by its own check (every stall check failing: the policy's retries spent at the
pins' entry) is re-planned once and seated too.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np
import pytest
from conftest import PROBLEMS

import fixplan
from fixplan.interactive import session as session_module
from fixplan.interactive.session import HapticSession, InsertionGuide
from fixplan.locating import engagement, inserts

HOUSING = PROBLEMS / "housing-2-pins.toml"
RISE_M = 0.02  # the start above the located pose (the pins are 12 mm long)
FINAL_GAP_M = 1e-4
PENETRATION_M = 1e-5


class _FailsOnThePins(InsertionGuide):
    """The first guide's run fails once every pin is engaged and the rests are still open (the later ones run as planned)."""

    made: list[_FailsOnThePins] = []
    failed_at: list[tuple[float, Any]] = []
    below_m = 0.0  # the run fails once the part is this close above its located pose (and both pins are in)

    def __init__(self, fixture: Any, pose: Any, tick_s: float, *args: Any, **kwargs: Any):
        super().__init__(fixture, pose, tick_s, *args, **kwargs)
        self.made.append(self)

    def command(self, t: float, pose: Any, twist: Any, pressed: frozenset[str]) -> Any:
        push = super().command(t, pose, twist, pressed)
        first = self is self.made[0]
        low = float((pose.p_world - self.plan.goal.p_world) @ self.plan.axis_world) <= self.below_m
        if first and not self.run.done and self.run.index == 2 and low and not {"B1", "B2", "B3"} & pressed:
            self.run._fail(t, "forced: the run stops with both pins in their holes", "stall")
            self.failed_at.append((t, pose))
        return push


@pytest.fixture
def failing_guide(monkeypatch: pytest.MonkeyPatch) -> type[_FailsOnThePins]:
    _FailsOnThePins.made = []
    _FailsOnThePins.failed_at = []
    monkeypatch.setattr(session_module, "InsertionGuide", _FailsOnThePins)
    return _FailsOnThePins


@pytest.mark.parametrize(("below_m", "lifted"), [(0.0115, True), (0.004, False)])
def test_a_failed_insertion_run_is_re_planned_and_seated(failing_guide: Any, below_m: float, lifted: bool) -> None:
    """Failed with the tips just in their holes, within the chamfers (11.5 mm above the located pose): the new plan
    lifts the part straight up off its pins first. Failed deep in, past the chamfers (4 mm above): the new plan
    seats it from there (``plan_insertion``: a part in past the chamfers is not lifted out)."""
    failing_guide.below_m = below_m
    fx = fixplan.load(HOUSING)
    fx = replace(fx, start=fx.goal.translated(np.array([0.0, 0.0, RISE_M])))
    s = HapticSession(fx, None, realtime=False, synchronous=True, until_goal=True, duration_s=12.0)
    result = s.run()
    guide = s.guide
    assert isinstance(guide, session_module.Guide)
    # the first run failed with the part on its pins, the rests open
    assert len(failing_guide.failed_at) == 1
    t_fail, pose_fail = failing_guide.failed_at[0]
    first, *later = failing_guide.made
    assert first.log.outcome == "failed" and first.log.reason.startswith("forced")
    assert all(engagement(fx, pose_fail, i).engaged for i in inserts(fx))
    assert float(pose_fail.p_world[2] - fx.goal.p_world[2]) <= below_m
    # one re-plan, from that pose
    assert guide.plans == 2 and len(later) == 1
    again = later[0].plan
    after = [(t, p) for t, p in zip(result.trace.time_s, result.trace.poses, strict=True) if t > t_fail]
    off = [t for t, p in after if not any(engagement(fx, p, i).engaged for i in inserts(fx))]
    if lifted:  # its approach rises straight up the pins' axis first, and the part comes off its pins
        approach = again.stages[0]
        assert approach.kind == "free"
        u = again.axis_world
        start, top = approach.poses[0], approach.poses[1]
        rise = float((top.p_world - start.p_world) @ u)
        sideways = top.p_world - start.p_world - rise * u
        assert rise > 0.0 and float(np.linalg.norm(sideways)) <= 1e-12
        assert off, "the part was not lifted off its pins"
    else:  # no approach: the part stays on its pins
        assert all(st.kind != "free" for st in again.stages)
        assert not off
    assert result.reached, result.reason
    assert later[0].log.outcome != "failed"  # the session's goal ends it, the run's seating push under way
    assert all(abs(result.final_gaps_m[n]) <= FINAL_GAP_M for n in ("B1", "B2", "B3"))
    assert result.max_penetration_m <= PENETRATION_M


class _StallsAtOnce(InsertionGuide):
    """The first guide's run stalls at every check (``stall_s`` 0, a progress of 1 m needed): its own recoveries, then its failure."""

    made: list[_StallsAtOnce] = []

    def __init__(self, fixture: Any, pose: Any, tick_s: float, *args: Any, **kwargs: Any):
        super().__init__(fixture, pose, tick_s, *args, **kwargs)
        self.made.append(self)
        if len(self.made) == 1:
            self.run.s = replace(self.run.s, stall_s=0.0, stall_progress_m=1.0)


def test_a_run_that_fails_by_its_own_stall_check_is_re_planned_and_seated(monkeypatch: pytest.MonkeyPatch) -> None:
    """The failure the run reports itself: a stall at the first pins' entry, the policy's retries spent; re-planned once, seated."""
    _StallsAtOnce.made = []
    monkeypatch.setattr(session_module, "InsertionGuide", _StallsAtOnce)
    fx = fixplan.load(HOUSING)
    fx = replace(fx, start=fx.goal.translated(np.array([0.0, 0.0, RISE_M])))
    s = HapticSession(fx, None, realtime=False, synchronous=True, until_goal=True, duration_s=12.0)
    result = s.run()
    first, *later = _StallsAtOnce.made
    assert first.log.outcome == "failed" and first.log.failure_kind == "stall"
    assert "retries spent" in first.log.reason and first.log.counts["stalls"] > 1
    assert isinstance(s.guide, session_module.Guide) and s.guide.plans == 2 and len(later) == 1
    assert result.reached, result.reason
    assert later[0].log.outcome != "failed"
    assert all(abs(result.final_gaps_m[n]) <= FINAL_GAP_M for n in ("B1", "B2", "B3"))
    assert result.max_penetration_m <= PENETRATION_M
