"""The least-effort non-jamming push (``search_wrench(..., objective="effort")``).

Closed form: dragging a block that slides on its supports with acceleration ``a`` needs at
least ``|F| = (m a + μ m g) / √(1 + μ²)``, applied at the friction angle ``atan μ`` above the
direction of motion (minimise ``(m a + μ (m g − F_up))² + F_up²``). With a small required
margin the contact forces can balance the moments, so the least push has no moment about the
centre of mass.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import PROBLEMS

import fixplan
from fixplan.jamming.search import search_wrench

G = 9.81


def _com_wrench(fx, res):
    """The found wrench re-expressed about the centre of mass (it is reported about the body origin)."""
    cs = fixplan.contact_set(fx, "start")
    off = cs.body_origin_world - cs.com_world
    w = np.array(res.wrench, dtype=float)
    d = fx.dimension
    if d == 3:
        return np.concatenate([w[:3], w[3:] + np.cross(off, w[:3])])
    return np.array([w[0], w[1], w[2] + off[0] * w[1] - off[1] * w[0]])


@pytest.mark.parametrize("a", [0.1, 1.0, 3.0])
def test_least_push_to_drag_a_rectangle_is_at_the_friction_angle(a):
    fx = fixplan.load(PROBLEMS / "rect-3.toml")  # 1 kg, μ = 0.5 on B1, B2
    m, mu = 1.0, 0.5
    res = search_wrench(fx, [a, 0.0, 0.0], ["B1", "B2"], objective="effort", min_margin_N=0.01)
    assert res.found, res.reason
    w = _com_wrench(fx, res)
    F_expected = (m * a + mu * m * G) / np.hypot(1.0, mu)
    assert np.hypot(w[0], w[1]) == pytest.approx(F_expected, rel=1e-6)
    # the effort is flat (quadratic) in the push angle at the optimum: the angle is only as
    # accurate as the square root of the solver's relative accuracy
    assert np.arctan2(w[1], w[0]) == pytest.approx(np.arctan(mu), abs=1e-4)
    assert abs(w[2]) <= 1e-4
    assert res.acceleration[0] == pytest.approx(a, rel=1e-6)
    assert res.margin_N >= 0.01 * (1 - 1e-5)


def test_least_push_to_drag_the_box_on_three_supports():
    fx = fixplan.load(PROBLEMS / "box-3-2-1.toml")  # 2 kg, μ = 0.25
    m, mu, a = 2.0, 0.25, 0.5
    res = search_wrench(fx, [a, 0, 0, 0, 0, 0], ["B1", "B2", "B3"], objective="effort", min_margin_N=0.1)
    assert res.found, res.reason
    w = _com_wrench(fx, res)
    assert np.linalg.norm(w[:3]) == pytest.approx((m * a + mu * m * G) / np.hypot(1.0, mu), rel=1e-6)
    assert w[2] / w[0] == pytest.approx(mu, rel=1e-4)  # lifts at the friction angle (flat optimum)
    assert abs(w[1]) <= 1e-4 and np.linalg.norm(w[3:]) <= 1e-4
    assert res.check is not None and res.check.mode == "slides"


def test_effort_keeps_the_required_margin_and_costs_less_than_the_best_margin():
    fx = fixplan.load(PROBLEMS / "box-3-2-1.toml")
    motion = [0.2, 0, 0, 0, 0, 0]
    best = search_wrench(fx, motion, ["B1", "B2", "B3"])
    light = search_wrench(fx, motion, ["B1", "B2", "B3"], objective="effort", min_margin_N=4.0)
    assert best.found and light.found
    assert light.margin_N >= 4.0 * (1 - 1e-5)
    assert best.margin_N >= light.margin_N
    assert np.linalg.norm(_com_wrench(fx, light)[:3]) < np.linalg.norm(_com_wrench(fx, best)[:3])
    for f in light.contact_forces.values():
        assert f[0] >= 4.0 * (1 - 1e-5)


def test_a_required_margin_above_the_best_falls_back_to_the_best():
    fx = fixplan.load(PROBLEMS / "box-3-2-1.toml")
    motion = [0.2, 0, 0, 0, 0, 0]
    best = search_wrench(fx, motion, ["B1", "B2", "B3"])
    capped = search_wrench(fx, motion, ["B1", "B2", "B3"], objective="effort", min_margin_N=1e3)
    assert capped.margin_N == pytest.approx(best.margin_N, rel=1e-5)


def test_unknown_objective_is_an_input_error():
    fx = fixplan.load(PROBLEMS / "box-3-2-1.toml")
    with pytest.raises(fixplan.InputError, match="objective"):
        search_wrench(fx, [0.2, 0, 0, 0, 0, 0], ["B1", "B2", "B3"], objective="fast")
