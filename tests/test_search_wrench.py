"""The wrench search against hand-derived answers: no jamming wrench, free motion, margin targets.

Numbers (box-3-2-1.toml / default.toml: 2 kg, μ = 0.25, g = 9.81, m g = 19.62 N; cylinder-5.toml:
1.5 kg, μ = 0.2, R = 0.04 m) are derived in the comments, never taken from a run.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import PROBLEMS

import fixplan
from fixplan.cli import main
from fixplan.jamming import classify, search_wrench, search_wrench_in
from fixplan.jamming.classify import Classifier
from fixplan.jamming.search import floor_sig
from fixplan.kinematics import ContactSet

G = 9.81


def _com(fx, pose, wrench):
    return fixplan.contact_set(fx, pose).wrench_about_com(wrench)


# ---------------------------------------------------------------- A: the best-margin push jams
def test_best_margin_push_at_the_goal_moves_the_box_instead_of_jamming():
    """Sliding the located box along +x: B1-B3 and S1, S2 slide, E1 opens.

    Before the fix the best-margin wrench pressed all five kept contacts with τ = 14.0 N and a
    drive of only M a = 0.2 N, and was statically balanced (a wedge: base friction tilted to
    press the side locators, side friction tilted to press the base) -> "jammed".
    """
    fx = fixplan.load(PROBLEMS / "box-3-2-1.toml")
    res = search_wrench(fx, [0.1, 0, 0, 0, 0, 0], pose="goal")
    assert res.found and res.confirmed, res.reason
    assert res.contact_roles == {n: "sliding" for n in ("B1", "B2", "B3", "S1", "S2")} | {"E1": "opening"}
    assert res.balance_check.mode == "separates"  # E1 opens: not held, not jammed
    assert res.jam_margin_rel >= 1e-3 * (1 - 1e-4)  # certified distance from balance (solver accuracy)
    assert res.check.mode == "slides"  # the kept contacts, classified on their own
    assert res.check.acceleration[0] >= 0.1 * (1 - 1e-6)
    assert np.linalg.norm(res.wrench[:3]) <= 40.0 * (1 + 1e-6)
    # every kept contact is pressed by τ, and the friction of five contacts at μ τ is overcome:
    # F_x ≥ 5 μ τ + m a
    assert res.margin_N > 10.0
    assert res.wrench[0] >= 5 * 0.25 * res.margin_N + 2.0 * 0.1


def test_the_classifier_confirms_the_push_found():
    fx = fixplan.load(PROBLEMS / "box-3-2-1.toml")
    res = search_wrench(fx, [0.1, 0, 0, 0, 0, 0], pose="goal", objective="effort", min_margin_N=1.0)
    (again,) = classify(fx, [res.wrench], pose="goal")
    assert again.mode not in ("held", "jammed")
    (kept,) = classify(fx, [res.wrench], ["B1", "B2", "B3", "S1", "S2"], pose="goal")
    assert kept.mode == "slides" and kept.acceleration[0] >= 0.1 * (1 - 1e-6)


@pytest.mark.parametrize("a", [0.1, 1.0])
def test_sliding_on_the_base_with_the_side_and_end_locators_opening(a):
    """Motion (a, a/2, 0): B1-B3 slide, S1, S2 (n = +y) and E1 (n = +x) open.

    The base carries N = m g − F_z in total and friction μ N opposes the slip direction
    d = (2, 1)/√5, so the horizontal push is F_h = m a_h + μ (m g − F_z) along d.
    """
    fx = fixplan.load(PROBLEMS / "box-3-2-1.toml")
    m, mu = 2.0, 0.25
    res = search_wrench(fx, [a, a / 2, 0, 0, 0, 0], pose="goal")
    assert res.found and res.confirmed, res.reason
    assert [res.contact_roles[n] for n in ("B1", "B2", "B3", "S1", "S2", "E1")] == ["sliding"] * 3 + ["opening"] * 3
    assert res.check.mode == "slides"
    w = _com(fx, "goal", res.wrench)
    N = m * G - w[2]
    d = np.array([2.0, 1.0]) / np.sqrt(5.0)
    acc = np.asarray(res.check.acceleration)
    a_h = float(d @ acc[:2])
    assert acc[:2] == pytest.approx(a_h * d, abs=1e-9)
    assert a_h >= np.hypot(a, a / 2) * (1 - 1e-6)
    assert w[:2] == pytest.approx((m * a_h + mu * N) * d, rel=1e-6)
    # the base alone is pressed by N ≥ 3 τ
    assert N >= 3 * res.margin_N * (1 - 1e-6)


# ---------------------------------------------------------------- B: every contact opens
def test_lifting_the_default_box_off_its_supports_is_m_g_plus_a():
    """At the default start the box rests on B1-B3 only; lifting at 1 m/s² opens all three:
    no contact force, F = m (g + a) = 2 × 10.81 = 21.62 N through the centre of mass."""
    fx = fixplan.load(fixplan.default_fixture_path())
    res = search_wrench(fx, [0, 0, 1.0, 0, 0, 0])
    assert set(res.contact_roles.values()) == {"opening"}
    assert res.found and res.confirmed, res.reason
    assert res.wrench == pytest.approx([0, 0, 21.62, 0, 0, 0], abs=1e-9)
    assert res.margin_N is None and res.to_json()["margin"] is None
    assert res.check.mode == "separates"
    assert res.acceleration == pytest.approx([0, 0, 1.0, 0, 0, 0])


def test_free_lift_beyond_the_limits_is_refused():
    """Lifting at 15 m/s² needs m (g + a) = 49.62 N > max_force 40 N."""
    fx = fixplan.load(fixplan.default_fixture_path())
    res = search_wrench(fx, [0, 0, 15.0, 0, 0, 0])
    assert not res.found and "too weak" in res.reason and "49.62" in res.reason


# ---------------------------------------------------------------- C: margin targets
def test_a_margin_target_above_the_best_is_reported_not_hidden(capsys):
    fx = fixplan.load(fixplan.default_fixture_path())
    best = search_wrench(fx, [0.1, 0, 0, 0, 0, 0])
    res = search_wrench(fx, [0.1, 0, 0, 0, 0, 0], min_margin_N=25.0)
    assert res.found and res.margin_target_met is False
    assert res.margin_N == pytest.approx(best.margin_N, rel=1e-6) and res.margin_N < 25.0
    assert f"margin target 25 N not met: best {best.margin_N:.4g} N" in res.reason
    ok = search_wrench(fx, [0.1, 0, 0, 0, 0, 0], objective="effort", min_margin_N=2.0)
    assert ok.margin_target_met is True and ok.margin_N >= 2.0 * (1 - 1e-6)
    assert search_wrench(fx, [0.1, 0, 0, 0, 0, 0]).margin_target_met is None  # nothing asked
    path = str(fixplan.default_fixture_path())
    assert main(["search", path, "--motion", "0.1,0,0,0,0,0", "--objective", "effort", "--min-margin", "25"]) == 1
    out = capsys.readouterr().out
    assert "not met" in out and "≥ 19 N" not in out
    assert main(["search", path, "--motion", "0.1,0,0,0,0,0", "--min-margin", "25", "--json"]) == 1
    data = json.loads(capsys.readouterr().out)
    assert data["found"] is True and data["margin_target_met"] is False and data["margin_target"] == 25.0


@pytest.mark.parametrize(
    ("x", "text"), [(18.9753, "18.97"), (0.99999999, "1"), (0.99995, "0.9999"), (123.456, "123.4")]
)
def test_floor_sig_never_prints_above_the_value(x, text):
    assert floor_sig(x) == text
    assert float(floor_sig(x)) <= x * (1 + 1e-7) + 1e-300


# ---------------------------------------------------------------- D: spinning the cylinder
def test_spinning_the_cylinder_slides_with_or_without_its_end_stop():
    """Spin 0.5 N·m about the axis (world x). The V contacts slide with N_L = 6.003 N,
    N_R = 4.002 N per block (expected.toml: 12.006 and 8.004 N over both blocks); E1 lies on
    the axis: it neither slips nor carries force, so it must not change the verdict."""
    fx = fixplan.load(PROBLEMS / "cylinder-5.toml")
    wrench = [0, 0, 0, 0.5, 0, 0]
    (default,) = classify(fx, [wrench])
    (named,) = classify(fx, [wrench], ["L1", "R1", "L2", "R2"])
    assert fixplan.contact_set(fx).names == ["L1", "R1", "L2", "R2", "E1"]
    assert default.mode == named.mode == "slides"
    for name, N in (("L1", 6.003), ("R1", 4.002), ("L2", 6.003), ("R2", 4.002)):
        assert default.contact_forces[name][0] == pytest.approx(N, abs=2e-3)
        assert named.contact_forces[name][0] == pytest.approx(N, abs=2e-3)
    assert np.allclose(default.contact_forces["E1"], 0.0, atol=1e-9)
    # α = (0.5 − μ R Σ N) / I_axis with I_axis = m R² / 2 = 1.2e-3 kg m²
    alpha = (0.5 - 0.2 * 0.04 * 20.01) / 1.2e-3
    assert default.acceleration[3] == pytest.approx(alpha, rel=1e-3)
    assert named.acceleration[3] == pytest.approx(alpha, rel=1e-3)


def test_search_for_the_spin_with_the_end_stop_named_or_not():
    fx = fixplan.load(PROBLEMS / "cylinder-5.toml")
    named = search_wrench(fx, [0, 0, 0, 10, 0, 0], ["L1", "R1", "L2", "R2"])
    assert named.found and named.confirmed and named.check.mode == "slides"
    default = search_wrench(fx, [0, 0, 0, 10, 0, 0])
    # E1 on the axis has no relative motion: "sticking", pressed like every kept contact, so the
    # body turns about it (pivots); the V contacts slide as with the contacts named
    assert default.contact_roles["E1"] == "sticking"
    assert default.found and default.confirmed and default.check.mode == "pivots", default.reason


def test_the_search_check_uses_the_kept_contacts():
    """With contacts opening, the motion's verdict comes from the kept contacts only."""
    fx = fixplan.load(PROBLEMS / "box-3-2-1.toml")
    res = search_wrench(fx, [0.1, 0, 0, 0, 0, 0], pose="goal")
    cs = fixplan.contact_set(fx, "goal")
    kept = ContactSet(
        tuple(c for c in cs.contacts if c.name != "E1"), cs.com_world, cs.mass_matrix, cs.body_origin_world
    )
    again = Classifier(kept, fx.gravity_wrench()).classify(cs.wrench_about_com(res.wrench))
    assert again.mode == res.check.mode == "slides"


# ---------------------------------------------------------------- C: a part that already slides
def test_a_sliding_part_gets_friction_against_its_velocity_not_its_acceleration():
    """The default box slides along +x on B1-B3 at 5 cm/s; the push asks for 0.5 m/s² along +y.

    Coulomb friction opposes the slip velocity: λ_i = N_i (−μ x̂ + ẑ). The dynamics then give the
    push in closed form: F_x = μ N (cancel friction, no x-acceleration), F_y = m s a, with
    N = m g − F_z. From rest the same motion would have friction along −ŷ: F_x = 0 and
    F_y = m s a + μ N.
    """
    fx = fixplan.load(fixplan.default_fixture_path())
    m, mu = 2.0, 0.25
    v = np.array([0.05, 0, 0, 0, 0, 0])
    moving = search_wrench(fx, [0, 0.5, 0, 0, 0, 0], objective="effort", slip_twist=v)
    rest = search_wrench(fx, [0, 0.5, 0, 0, 0, 0], objective="effort")
    assert moving.found and rest.found, (moving.reason, rest.reason)
    assert set(moving.contact_roles.values()) == {"sliding"}
    w_m = _com(fx, "start", moving.wrench)
    N_m = m * G - w_m[2]
    assert N_m > 0
    assert w_m[0] == pytest.approx(mu * N_m, rel=1e-6)  # friction against the slip, cancelled
    assert w_m[1] >= m * 0.5 * (1 - 1e-6)  # s ≥ 1, and no friction along y
    w_r = _com(fx, "start", rest.wrench)
    N_r = m * G - w_r[2]
    a_r = float(rest.check.acceleration[1])
    assert abs(w_r[0]) <= 1e-6 * N_r  # nothing along x
    assert w_r[1] == pytest.approx(m * a_r + mu * N_r, rel=1e-6)  # friction against the acceleration


def test_the_engine_moves_the_sliding_part_as_the_slip_aware_push_asks():
    """One engine tick from the sliding state: with the slip-aware push the x-velocity holds
    (friction cancelled) and the part accelerates along +y; the push computed for a part at rest
    lets friction brake it along x at μ N / m."""
    from fixplan.engine.simulator import Simulator

    fx = fixplan.load(fixplan.default_fixture_path())
    m, mu = 2.0, 0.25
    v = np.array([0.05, 0, 0, 0, 0, 0])
    start = fx.start
    acc = {}
    for label, kwargs in (("moving", {"slip_twist": v}), ("rest", {})):
        res = search_wrench(fx, [0, 0.5, 0, 0, 0, 0], objective="effort", **kwargs)
        sim = Simulator(fx)
        sim.set_state(start, v)
        sim.step(res.wrench)
        acc[label] = (sim.twist - v) / sim.dt
        N = m * G - _com(fx, "start", res.wrench)[2]
        if label == "moving":
            # friction cancelled along x (to 1 %: the slip turns a little within the 1 ms tick)
            assert abs(acc[label][0]) <= 1e-2 * mu * N / m
            assert acc[label][1] >= 0.5 * (1 - 1e-3)
        else:
            # braked by friction (the slip turns a little toward +y within the tick: 5 %)
            assert acc[label][0] == pytest.approx(-mu * N / m, rel=5e-2)


def test_braking_a_sliding_part_is_the_dynamics_with_friction_against_the_slip():
    """The default box slides along +x at 5 cm/s; brake at 0.5 m/s² (certify=False: the push a
    braking operator makes is one friction would hold at rest). Along x: m a_x = F_x − μ N, so
    F_x = μ N − m s 0.5 with s ∈ [1, 1.5] (max_accel_factor): a forward push smaller than friction.
    One engine tick confirms the deceleration."""
    from fixplan.engine.simulator import Simulator

    fx = fixplan.load(fixplan.default_fixture_path())
    m, mu = 2.0, 0.25
    v = np.array([0.05, 0, 0, 0, 0, 0])
    res = search_wrench(
        fx, [-0.5, 0, 0, 0, 0, 0], objective="effort", slip_twist=v, certify=False, max_accel_factor=1.5
    )
    assert res.found, res.reason
    w = _com(fx, "start", res.wrench)
    N = m * G - w[2]
    s = -float(res.acceleration[0]) / 0.5
    assert 1.0 - 1e-6 <= s <= 1.5 + 1e-6
    assert w[0] == pytest.approx(mu * N - m * s * 0.5, rel=1e-6)
    assert 0.0 < w[0] < mu * N  # forward, less than friction
    sim = Simulator(fx)
    sim.set_state(fx.start, v)
    sim.step(res.wrench)
    assert (sim.twist[0] - v[0]) / sim.dt == pytest.approx(-s * 0.5, rel=2e-2)


@pytest.mark.parametrize("objective", ["margin", "effort"])
def test_without_the_classifier_check_the_same_push_is_returned(objective):
    """``confirm=False`` (the executor's 200 Hz re-solves) returns the same certified push, margin
    and forces as the checked search; only the classifier's verdicts are absent."""
    fx = fixplan.load(fixplan.default_fixture_path())
    for motion, slip in [([0, -0.5, 0, 0, 0, 0], None), ([0.3, -0.4, 0, 0, 0, 0.5], [0.01, -0.02, 0, 0, 0, 0.1])]:
        kw = dict(pose="start", objective=objective, friction_margin=0.1, max_accel_factor=1.5, slip_twist=slip)
        full = search_wrench(fx, motion, ["B1", "B2", "B3"], **kw)
        fast = search_wrench(fx, motion, ["B1", "B2", "B3"], confirm=False, **kw)
        assert full.found and fast.found
        assert np.allclose(fast.wrench, full.wrench, rtol=0, atol=1e-12)
        assert fast.margin_N == pytest.approx(full.margin_N, abs=1e-12)
        assert fast.check is None and fast.balance_check is None and not fast.confirmed
        # the push moves the part as asked: the classifier, run here, agrees
        c = classify(fx, fast.wrench, ["B1", "B2", "B3"], pose="start", jobs=1)[0]
        assert c.mode in ("slides", "pivots", "rolls")


# ---------------------------------------------------------------- the contact-set form
def test_the_contact_set_form_gives_the_fixture_level_answer():
    """search_wrench_in(cs, a_com) with the motion moved to the centre of mass by hand: the same push.

    At the located box (centre c), the acceleration of c ``a_c = (0.1, 0.05, 0)``, ``α = (0, 0, 0.2)``
    (sliding on the base, turning, leaving the side locators) seen at the corner point
    ``p = c + (0.1, 0.05, 0)`` is ``a_c + α × (p − c) = (0.1 − 0.2·0.05, 0.05 + 0.2·0.1, 0) = (0.09, 0.07, 0)``.
    """
    fx = fixplan.load(PROBLEMS / "box-3-2-1.toml")
    names = ["B1", "B2", "B3", "S1", "S2"]
    cs = fixplan.contact_set(fx, "goal", names)
    corner = cs.com_world + np.array([0.1, 0.05, 0.0])
    a_com = np.array([0.1, 0.05, 0.0, 0.0, 0.0, 0.2])
    ref = search_wrench(fx, [0.09, 0.07, 0, 0, 0, 0.2], names, pose="goal", at=corner, objective="effort")
    res = search_wrench_in(cs, a_com, fx, about_world=corner, objective="effort")
    assert res.found == ref.found and res.reason == ref.reason
    assert res.contact_roles == ref.contact_roles
    if ref.found:
        assert np.allclose(res.wrench, ref.wrench, rtol=1e-7, atol=1e-9)
        assert np.allclose(res.acceleration, ref.acceleration, rtol=1e-7, atol=1e-12)
    # the acceleration reported is the centre of mass's, along the one asked for
    if res.acceleration is not None:
        s = float(res.acceleration @ a_com) / float(a_com @ a_com)
        assert s >= 1.0 - 1e-9 and np.allclose(res.acceleration, s * a_com, atol=1e-12)


# ---------------------------------------------------------------- D: "too weak" names the limit and the need
def _rect_with_hand(max_force, max_torque):
    """rect-3.toml (2D, 1 kg, μ = 0.5 on B1, B2 under the -y face) with the given hand."""
    text = (PROBLEMS / "rect-3.toml").read_text()
    return fixplan.loads(text + f"\n[manipulator]\nmax_force = {max_force}\nmax_torque = {max_torque}\n")


@pytest.mark.parametrize("max_torque", [5.0, 0.3, 0.05])
def test_too_weak_to_slide_names_the_force_and_the_least_force_needed(max_torque):
    """Sliding along +x on B1, B2 at a = 1 m/s²: the least push tilts up by atan μ and has
    ‖F‖ = (m a + μ m g)/√(1 + μ²) = (1 + 4.905)/√1.25 = 5.2816 N > max_force 3 N. Its moment is free
    (the push only has to keep the part from turning), so the torque limit does not bind. The old
    message printed the unbounded search's push (pressing as hard as 1000 × the limits allowed)."""
    m, mu, a = 1.0, 0.5, 1.0
    need = (m * a + mu * m * G) / np.hypot(1.0, mu)
    res = search_wrench(_rect_with_hand(3.0, max_torque), [a, 0.0, 0.0], ["B1", "B2"])
    assert not res.found and res.binding == ["max_force"]
    assert res.needed_force_N == pytest.approx(need, rel=1e-7)
    assert res.needed_torque_Nm is None  # no push within 3 N slides it, whatever its torque
    assert f"the push needs {need:.4g} N of force, more than max_force 3 N" in res.reason
    assert f"is within max_torque {max_torque:g} N·m" in res.reason
    assert res.to_json()["needed_force"] == res.needed_force_N and res.to_json()["needed_torque"] is None


def test_too_weak_to_tip_names_the_torque_and_the_least_torque_needed():
    """naive-order-jams.toml rests on B1 alone; pivoting counter-clockwise about B1 at α = 1 rad/s²
    needs, about B1, the moment m g r_x + I_B1 α (gravity's lever r_x; B1's force and any force
    through B1 have none), whatever the force: 0.5436 + 0.0103 = 0.5539 N·m > max_torque 0.2 N·m.
    The force is free (B1 can carry the weight), so the force limit (3 N) does not bind."""
    fx = fixplan.load(PROBLEMS / "naive-order-jams.toml")
    B1 = fixplan.contact_set(fx, "start", ["B1"]).contacts[0].point_world
    r = fx.start.point_world_from_body(fx.workpiece.com_body) - B1
    wp = fx.workpiece
    I_B1 = float(np.atleast_2d(wp.inertia_body)[-1, -1]) + wp.mass_kg * float(r @ r)
    need = wp.mass_kg * G * r[0] + I_B1 * 1.0
    res = search_wrench(fx, [0.0, 0.0, 1.0], ["B1"], pose="start", at=B1)
    assert not res.found and res.binding == ["max_torque"]
    assert res.needed_torque_Nm == pytest.approx(need, rel=1e-6)
    assert f"the push needs {need:.4g} N·m of torque, more than max_torque 0.2 N·m" in res.reason
    assert "is within max_force 3 N" in res.reason


def test_a_free_push_beyond_a_limit_names_that_limit():
    """Lifting the default box at 15 m/s² opens every contact: the push is m (g + a) = 49.62 N of
    force through the centre of mass, no torque: the force binds, the torque does not."""
    res = search_wrench(fixplan.load(fixplan.default_fixture_path()), [0, 0, 15.0, 0, 0, 0])
    assert not res.found and res.binding == ["max_force"]
    assert res.needed_force_N == pytest.approx(2.0 * (G + 15.0)) and res.needed_torque_Nm == pytest.approx(
        0.0, abs=1e-9
    )
    assert "needs 49.62 N of force, more than max_force 40 N" in res.reason
