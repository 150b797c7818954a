"""What the hand carries prices a move, and the headroom never costs the kept contacts their hold.

rect-3.toml (2D, 1 kg rectangle 0.20 × 0.10 m, centre of mass at (0.10, 0.05) at the start,
B1, B2 under it at x = 0.05, 0.15, S1 on its -x face at height 0.05, μ = 0.5, g = 9.81).

Carried share (``planner.segments.carried_fraction``): the least ``‖−m g − Σ f_i n_i‖`` over
normal forces ``f ≥ 0``, over ``m|g|``. Resting on B1 or B2 alone, or both: 0 (a vertical normal
carries the whole weight; the hand balances the moment). The side wall alone: 1 (its normal is
horizontal). Free: 1. No gravity: 0. The part turned by θ and resting on one corner-free face
contact: the normal is θ off the vertical, the best ``f = W cos θ`` leaves ``W sin θ``: ``sin θ``.
Gravity along −x instead: S1 carries all, the base nothing.

Headroom lifted (``jamming.search``): the part on S1 alone, pushed up at 1 m/s². Sliding up the
wall, friction ``μN`` points down, so a push pressing ``N`` into the wall has
``‖F‖² = N² + (m(a + g) + μN)²``; the largest margin ``N`` within a force cap ``F_c`` solves
``(1 + μ²)N² + 2μ m(a+g) N + (m(a+g))² − F_c² = 0``. Hand 20 N: within 80 % (16 N)
``N = 7.078 N`` < W = 9.81 N, with the whole 20 N ``N = 11.335 N`` ≥ 1.5 × 7.078: the whole
limits are used and the search says why. Hand 30 N: within 24 N ``N = 15.32 N`` ≥ W: kept inside.
"""

from __future__ import annotations

import math

import pytest
from conftest import PROBLEMS

import fixplan
from fixplan.jamming import search_wrench
from fixplan.planner.segments import carried_fraction, carry_factor
from fixplan.settings import DEFAULT
from fixplan.spatial import Pose

TEXT = (PROBLEMS / "rect-3.toml").read_text()


def _rect(extra: str = "") -> fixplan.Fixture:
    return fixplan.loads(TEXT + extra)


def _wall_margin(cap_N: float, m: float = 1.0, a: float = 1.0, g: float = 9.81, mu: float = 0.5) -> float:
    c = m * (a + g)
    A, B, C = 1.0 + mu * mu, 2.0 * mu * c, c * c - cap_N * cap_N
    return (-B + math.sqrt(B * B - 4 * A * C)) / (2 * A)


def test_carried_share_closed_forms():
    fx = _rect()
    pose = fx.start
    assert carried_fraction(fx, pose, ["B1"]) == pytest.approx(0.0, abs=1e-12)
    assert carried_fraction(fx, pose, ["B1", "B2"]) == pytest.approx(0.0, abs=1e-12)
    assert carried_fraction(fx, pose, ["S1"]) == pytest.approx(1.0, rel=1e-12)
    assert carried_fraction(fx, pose, ["S1", "B2"]) == pytest.approx(0.0, abs=1e-12)
    assert carried_fraction(fx, pose, []) == 1.0
    weightless = fixplan.loads(TEXT.replace("gravity = [0.0, -9.81]", "gravity = [0.0, 0.0]"))
    assert carried_fraction(weightless, pose, ["S1"]) == 0.0
    assert carry_factor(fx, pose, ["S1"]) == pytest.approx(1.0 + DEFAULT.planner.carry_cost)
    assert carry_factor(fx, pose, ["B1", "B2"]) == pytest.approx(1.0, abs=1e-12)


@pytest.mark.parametrize("theta_deg", [5.0, 20.0, -40.0])
def test_carried_share_of_a_tilted_contact_is_the_sine_of_its_tilt(theta_deg):
    """The rectangle turned by θ, its -y face 1 cm above B1 with B1 under the face's middle (the
    centre at B1 + 0.06 (−sin θ, cos θ)): B1's normal is θ off the vertical, the share sin |θ|."""
    fx = _rect()
    th = math.radians(theta_deg)
    pose = Pose.from_angle_deg([0.05 - 0.06 * math.sin(th), 0.06 * math.cos(th)], theta_deg)
    share = carried_fraction(fx, pose, ["B1"])
    assert share == pytest.approx(abs(math.sin(th)), rel=1e-9)


def test_carried_share_turns_with_gravity():
    """Gravity along -x: the side wall S1 now carries the weight and the base nothing."""
    fx = fixplan.loads(TEXT.replace("gravity = [0.0, -9.81]", "gravity = [-9.81, 0.0]"))
    pose = fx.start
    assert carried_fraction(fx, pose, ["B1", "B2"]) == pytest.approx(1.0, rel=1e-12)
    assert carried_fraction(fx, pose, ["S1"]) == pytest.approx(0.0, abs=1e-12)


def test_the_guess_prices_a_carried_move_dearer():
    """The coarse search's guess of a move is its mass-weighted length times the carry factor.

    The rectangle lifted to (0.13, 0.07), unrotated: S1's gap is 0.03 m. The least-``M``-norm free
    step that closes it moves along the normal row ``G = [1, 0, 0.02]`` (unit +x at a lever
    (−0.13, −0.02) from the centre of mass): length ``0.03/√(m G M⁻¹ Gᵀ)``, ``G M⁻¹ Gᵀ = 1 +
    0.02²/I``. In free space the hand carries everything: priced ``1 + carry_cost`` times that."""
    from fixplan.planner.policy import gap_closing_step

    fx = fixplan.loads(TEXT.replace("position = [0.10, 0.05]", "position = [0.13, 0.07]"))
    step = gap_closing_step(fx, fx.start, frozenset(), "S1", "free")
    assert step is not None
    length = 0.03 / math.sqrt(1.0 + 0.02**2 / (0.05 / 12.0))
    assert step[0] == pytest.approx(length * (1.0 + DEFAULT.planner.carry_cost), rel=1e-9)


@pytest.mark.parametrize(("hand_N", "lifted"), [(20.0, True), (30.0, False)])
def test_headroom_is_lifted_only_where_the_margin_stays_below_the_weight(hand_N, lifted):
    fx = _rect(f"\n[manipulator]\nmax_force = {hand_N}\nmax_torque = 5.0\n")
    res = search_wrench(fx, [0.0, 1.0, 0.0], ["S1"])
    assert res.found
    inside, whole = _wall_margin(DEFAULT.search.limit_fraction * hand_N), _wall_margin(hand_N)
    assert inside < 9.81 * (1.0 if lifted else 2.0)
    if lifted:
        assert whole >= DEFAULT.search.headroom_margin_gain * inside
        assert res.within_fraction is False
        assert res.margin_N == pytest.approx(whole, rel=1e-4)
        assert f"pressed by only {inside:.4g}"[:-1] in res.reason and "less than the weight" in res.reason
    else:
        assert inside >= 9.81
        assert res.within_fraction is True
        assert res.margin_N == pytest.approx(inside, rel=1e-4)
        assert res.force_fraction <= DEFAULT.search.limit_fraction * (1 + 1e-6)
