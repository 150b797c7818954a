"""Headroom to the hand's limits, and the infeasible reason that quotes the least-demanding failure.

The pushes are sought within ``settings.search.limit_fraction`` (0.8) of ``max_force`` and
``max_torque`` first; only where no non-jamming push exists inside do they use more, and say so.
The verified run reports the executor's peak push as fractions of the limits and the ticks spent
above the fraction; the numbers are recomputed here from the trace.

Numbers (default.toml: 2 kg box, μ = 0.25, g = 9.81, m g = 19.62 N, hand 40 N / 2 N·m; the planner
pushes at a = 1 m/s² robust to friction μ(1 ± 0.1)) are derived in the docstrings.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from conftest import PROBLEMS

import fixplan
from fixplan.jamming import search_wrench
from fixplan.planner.coarse import Attempt, _no_sequence
from fixplan.planner.segments import needed_scale
from fixplan.planner.solve import solve
from fixplan.settings import DEFAULT

G = 9.81
FRACTION = DEFAULT.search.limit_fraction
TOL = 1 + 1e-6  # solver accuracy on a cap


def _default_with(**changes: str) -> fixplan.Fixture:
    """The bundled box with some lines of its TOML replaced (``old=new``)."""
    text = fixplan.default_fixture_path().read_text()
    for old, new in changes.items():
        assert old in text
        text = text.replace(old, new)
    return fixplan.loads(text)


def _slide_need(m: float, mu: float, a: float) -> float:
    """The least push that slides a block on its base at ``a``: it tilts up by atan μ,
    ‖F‖ = (m a + μ m g)/√(1 + μ²) (its moment is free when the torque limit is slack)."""
    return (m * a + mu * m * G) / math.hypot(1.0, mu)


def _fractions(W: np.ndarray, d: int, F_max: float, T_max: float) -> tuple[np.ndarray, np.ndarray]:
    return np.linalg.norm(W[:, :d], axis=1) / F_max, np.linalg.norm(W[:, d:], axis=1) / T_max


# ---------------------------------------------------------------- the search keeps the headroom
def test_search_keeps_the_push_within_the_fraction_of_the_limits():
    """Sliding the default box along +x at 0.1 m/s² on B1, B2, B3: the best-margin push pressed
    as hard as the hand allows (37 N down, ‖F‖ = 40 N: max_force binds). Within 80 % it stops at
    32 N, and a light margin target (1 N) needs a push of about (m a + μ m g)/√(1 + μ²) + the
    margin's share: 4.8 N, 12 % of max_force."""
    fx = fixplan.load(fixplan.default_fixture_path())
    full = search_wrench(fx, [0.1, 0, 0, 0, 0, 0], ["B1", "B2", "B3"], limit_fraction=1.0)
    assert full.found and "max_force" in full.binding and full.force_fraction == pytest.approx(1.0, rel=1e-6)
    kept = search_wrench(fx, [0.1, 0, 0, 0, 0, 0], ["B1", "B2", "B3"])
    assert kept.found and kept.within_fraction is True and kept.limit_fraction == FRACTION
    assert kept.force_fraction <= FRACTION * TOL and kept.torque_fraction <= FRACTION * TOL
    assert kept.force_fraction == pytest.approx(np.linalg.norm(kept.wrench[:3]) / 40.0)
    assert kept.margin_N < full.margin_N  # the headroom costs margin, never the motion
    light = search_wrench(fx, [0.1, 0, 0, 0, 0, 0], ["B1", "B2", "B3"], objective="effort", min_margin_N=1.0)
    assert light.found and light.force_fraction < 0.13
    assert np.linalg.norm(light.wrench[:3]) >= _slide_need(2.0, 0.25, 0.1) * (1 - 1e-6)
    js = json.loads(json.dumps(kept.to_json(), allow_nan=False))
    assert js["limit_fraction"] == FRACTION and js["within_fraction"] is True
    assert js["force_fraction"] == pytest.approx(kept.force_fraction)
    assert js["torque_fraction"] == pytest.approx(kept.torque_fraction)


def test_search_uses_more_only_where_nothing_inside_moves_the_part_and_says_so():
    """rect-3.toml (2D, 1 kg, μ = 0.5 on B1, B2) with a 6 N hand: sliding along +x at 1 m/s²
    needs ‖F‖ ≥ (1 + 4.905)/√1.25 = 5.2816 N > 0.8 × 6 = 4.8 N. No push within the headroom exists,
    so the search uses the whole limit, reports it beyond the fraction and says so."""
    text = (PROBLEMS / "rect-3.toml").read_text()
    fx = fixplan.loads(text + "\n[manipulator]\nmax_force = 6.0\nmax_torque = 5.0\n")
    need = _slide_need(1.0, 0.5, 1.0)
    assert need > FRACTION * 6.0
    res = search_wrench(fx, [1.0, 0.0, 0.0], ["B1", "B2"], objective="effort", min_margin_N=1e-3)
    assert res.found and res.within_fraction is False
    assert res.force_fraction * 6.0 >= need * (1 - 1e-6) and res.force_fraction <= 1.0 * TOL
    assert f"no non-jamming push within {FRACTION:.0%} of the hand's limits" in res.reason


# ---------------------------------------------------------------- the verified default plan
@pytest.fixture(scope="module")
def default_plan():
    """The default box, its trace sampled at every tick (so the peaks can be recomputed)."""
    return solve(fixplan.load(fixplan.default_fixture_path()), verify_options={"trace_every_s": 1e-3})


def test_default_plan_peaks_within_the_fraction_of_the_limits(default_plan):
    """Before the headroom the executor pushed at 40 N (1.0 of max_force) for 241 ticks."""
    r = default_plan
    assert r.status == "planned", r.reason
    v = r.verification
    assert v.limit_fraction == FRACTION
    assert v.peak_force_fraction <= FRACTION * TOL and v.peak_torque_fraction <= FRACTION * TOL
    assert v.ticks_above_fraction == 0 and v.execution.beyond_fraction_solves == 0
    assert v.saturated_ticks == 0  # the coupling's transients stay within the hand too
    for tr in r.plan.transitions:  # the planned pushes keep the headroom too
        assert tr.peak_force_fraction <= FRACTION * TOL and tr.peak_torque_fraction <= FRACTION * TOL


def test_the_reported_peaks_are_the_traces(default_plan):
    """Recomputed from the JSON trace (every tick): ‖F‖ / 40 N and ‖T‖ / 2 N·m of command_wrench."""
    data = json.loads(json.dumps(default_plan.to_json(), allow_nan=False))
    v = data["verification"]
    for key in ("limit_fraction", "peak_force_fraction", "peak_torque_fraction", "ticks_above_fraction"):
        assert key in v and v[key] is not None
    W = np.array(v["trace"]["command_wrench"])
    assert W.shape == (len(v["trace"]["time_s"]), 6)
    assert W.shape[0] == round(v["duration_s"] / 1e-3)  # every tick
    f, t = _fractions(W, 3, 40.0, 2.0)
    assert v["peak_force_fraction"] == pytest.approx(float(f.max()), rel=1e-12)
    assert v["peak_torque_fraction"] == pytest.approx(float(t.max()), rel=1e-12)
    above = v["limit_fraction"] * (1 + DEFAULT.search.binding_rel)
    assert v["ticks_above_fraction"] == int(np.count_nonzero((f > above) | (t > above)))
    for tr, planned in zip(data["transitions"], default_plan.transitions, strict=True):
        rows = planned.wrenches[np.isfinite(planned.wrenches).all(axis=1)]
        pf, pt = _fractions(rows, 3, 40.0, 2.0)
        assert tr["peak_force_fraction"] == pytest.approx(float(pf.max()))
        assert tr["peak_torque_fraction"] == pytest.approx(float(pt.max()))


def test_a_task_beyond_the_headroom_still_plans_and_says_so():
    """The default box with an 8 N hand: the least push that slides it at 1 m/s² robust to
    μ(1 + 0.1) = 0.275 is (2 + 0.275 × 19.62)/√(1 + 0.275²) = 7.131 N > 0.8 × 8 = 6.4 N, so no
    push within the headroom moves it. It still plans and verifies, using more than 80 %, and
    says so: the peaks, the ticks above, the solves, an event."""
    need = _slide_need(2.0, 0.25 * 1.1, 1.0)
    assert need == pytest.approx(7.1308, abs=1e-4) and need > FRACTION * 8.0
    r = solve(_default_with(**{"max_force = 40.0": "max_force = 8.0"}))
    assert r.status == "planned", r.reason
    v = r.verification
    assert FRACTION < v.peak_force_fraction <= 1.0 + DEFAULT.verification.limit_slack
    assert v.ticks_above_fraction > 0 and v.execution.beyond_fraction_solves > 0
    assert any(
        kind == "limits" and f"no non-jamming push within {FRACTION:.0%}" in msg for _, kind, msg in v.execution.events
    )
    assert max(tr.peak_force_fraction for tr in r.plan.transitions) > FRACTION
    # the 10 ms trace samples some of the ticks: never more than the run's figures
    data = json.loads(json.dumps(r.to_json(), allow_nan=False))["verification"]
    f, t = _fractions(np.array(data["trace"]["command_wrench"]), 3, 8.0, 2.0)
    assert f.max() <= data["peak_force_fraction"] * (1 + 1e-12) and t.max() <= data["peak_torque_fraction"] * (
        1 + 1e-12
    )
    above = FRACTION * (1 + DEFAULT.search.binding_rel)
    assert 0 < int(np.count_nonzero((f > above) | (t > above))) <= data["ticks_above_fraction"]


# ---------------------------------------------------------------- the infeasible reason
def test_needed_scale_is_the_least_growth_of_one_limit():
    assert needed_scale((6.0, None), 3.0, 2.0) == pytest.approx(2.0)  # force alone binds
    assert needed_scale((None, 3.0), 3.0, 2.0) == pytest.approx(1.5)  # torque alone
    assert needed_scale((4.5, 5.0), 3.0, 2.0) == pytest.approx(1.5)  # either: raising force suffices
    assert needed_scale((None, None), 3.0, 2.0) is None


def test_no_sequence_quotes_the_least_demanding_failure():
    a = Attempt(("B1",), "E1", False, math.inf, "E1 needs 9 N", "fine", (), 3.0)
    b = Attempt(("B1",), "S1", False, math.inf, "S1 needs 6 N", "fine", (), 2.0)
    c = Attempt(("B1",), "S2", False, math.inf, "no path", "fine")
    why = _no_sequence([b, a, c])
    assert "the least demanding is: adding S1 to {B1} fails: S1 needs 6 N" in why
    assert "e.g. adding S2 to {B1} fails: no path" in _no_sequence([c])


def test_infeasible_single_transition_quotes_the_hand_derived_need():
    """The box placed 5 mm beyond its located pose along +x, a 3 N hand: only E1 is left, by
    sliding along −x on the base (S1 and S2 slide unloaded) at 1 m/s² with friction μ(1 + 0.1):
    (2 + 0.275 × 19.62)/√(1 + 0.275²) = 7.131 N of force, max_force binding."""
    fx = _default_with(
        **{
            "max_force = 40.0": "max_force = 3.0",
            "start = { position = [0.115, 0.06, 0.025], rpy_deg = [0.0, 0.0, 4.0] }": (
                "start = { position = [0.105, 0.05, 0.025] }"
            ),
        }
    )
    r = solve(fx, run_verification=False)
    assert r.status == "infeasible" and r.proven
    need = _slide_need(2.0, 0.25 * 1.1, 1.0)
    assert f"the push needs {need:.4g} N of force, more than max_force 3 N" in r.reason


def test_infeasible_reason_quotes_the_least_demanding_candidate():
    """The default box with a 3 N hand: from the base every next locator (E1, S1, S2) is too far
    for it. The reason quotes the transition needing the least force (each transition's need is
    its most demanding segment's), not the last one tried: before, it quoted E1's 7.06 N where
    S2 needs 6.5 N."""
    r = solve(_default_with(**{"max_force = 40.0": "max_force = 3.0"}), run_verification=False)
    assert r.status == "infeasible" and r.proven
    fine = [a for a in r.attempts if a.stage == "fine" and not a.success]
    assert len({a.target for a in fine}) == 3 and all(a.needed_scale is not None for a in fine)
    least = min(fine, key=lambda a: a.needed_scale)
    assert f"the least demanding is: adding {least.target} to {{B1, B2, B3}} fails: {least.reason}" in r.reason
    quoted = float(r.reason.split("the push needs ")[1].split(" N")[0])
    assert quoted == pytest.approx(least.needed_scale * 3.0, rel=1e-3)
    assert all(quoted <= a.needed_scale * 3.0 * (1 + 1e-3) for a in fine)
    assert "more than max_force 3 N" in r.reason  # the limit that binds
