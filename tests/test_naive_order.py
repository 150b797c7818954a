"""A fixture whose naive loading order fails while the planner finds another.

``problems/naive-order-jams.toml`` (its comment block derives the numbers): a 2D rectangle resting
on B1 alone. The file order S1, B2 must tip the part up about B1 against gravity's 0.544 N m, more
than the hand's 0.2 N m + 0.078 m x 3 N = 0.434 N m; the order B2, S1 lets gravity put the part
on B2 and then slides it 1 cm onto S1 (2.44 N <= max_force 3 N).
"""

from __future__ import annotations

import pytest
from conftest import PROBLEMS

import fixplan
from fixplan.locating import locator_gaps
from fixplan.planner.solve import solve

FILE = PROBLEMS / "naive-order-jams.toml"


@pytest.fixture(scope="module")
def fixture() -> fixplan.Fixture:
    return fixplan.load(FILE)


@pytest.fixture(scope="module")
def naive_order(fixture: fixplan.Fixture) -> list[str]:
    """The locators in file order after those touching at the start."""
    gaps = locator_gaps(fixture.workpiece, fixture.start, fixture.locators)
    touching = {loc.name for loc, g in zip(fixture.locators, gaps, strict=True) if g <= fixture.tolerances.touch_m}
    assert touching == {"B1"}  # some locators touch at the start, not all
    return [loc.name for loc in fixture.locators if loc.name not in touching]


def test_fixture_is_full_and_2d(fixture: fixplan.Fixture, naive_order: list[str]) -> None:
    assert fixture.dimension == 2 and fixture.is_full and len(fixture.locators) == 3
    assert naive_order == ["S1", "B2"]
    assert fixture.manipulator.max_force_N == 3.0 and fixture.manipulator.max_torque_Nm == 0.2


def test_naive_order_is_infeasible_with_the_binding_limit(fixture: fixplan.Fixture, naive_order: list[str]) -> None:
    r = solve(fixture, order=naive_order, run_verification=False)
    assert r.status == "infeasible" and not r.ok
    failed = [a for a in r.attempts if not a.success]
    assert failed, r.attempts
    first = failed[0]
    # the failing transition: tipping from {B1} up onto S1
    assert first.established == ("B1",) and first.target == "S1"
    assert "too weak" in first.reason and "max_force 3 N" in first.reason and "max_torque 0.2 N·m" in first.reason
    # the result's reason names the transition and the binding limit too
    assert "adding S1 to {B1} fails" in r.reason and "max_force" in r.reason


def test_planner_finds_another_order_and_verifies_it(
    fixture: fixplan.Fixture, naive_order: list[str], jams_plan
) -> None:
    r = jams_plan  # solve(fixture), shared with other modules
    assert r.status == "planned" and r.ok, r.reason
    assert r.verification is not None and r.verification.passed, r.verification
    assert r.sequence == [("B1",), ("B1", "B2"), ("B1", "B2", "S1")]
    added = [next(iter(set(b) - set(a))) for a, b in zip(r.sequence, r.sequence[1:], strict=False)]
    assert added == ["B2", "S1"] and added != naive_order
    assert [tr.kind for tr in r.transitions] == ["roll", "slide"]
    for tr in r.transitions:
        assert tr.success and min(tr.margins) > 0
    # the tip-up toward S1 is never fine-planned: the rolling estimate prices B2 first (gravity
    # helps), and the cheap cone check alone rejects the tip-up for the hand's limits
    tip_up = [a for a in r.attempts if a.target == "S1" and a.established == ("B1",)]
    assert all(a.stage == "precheck" and not a.success for a in tip_up)
    from fixplan.planner.solve import Planner

    assert "too weak" in (Planner(fixture).precheck(fixture.start, frozenset({"B1"}), "S1") or "")
    assert max(abs(g) for g in r.verification.final_gaps_m.values()) <= 1e-4
