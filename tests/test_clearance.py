"""The range of located poses the pins' clearances allow, against closed forms.

A housing on three rests (they fix z and the tilt) with a round pin P1 in hole H1 (play
``c1 = (D1 − d1)/2``) at ``x1`` and a diamond pin P2 with lands along y in H2 (``c2``) at ``x2``,
``L = x2 − x1``; the body origin at ``x_o``. The hole offsets on the pins change by
``u1 = (v_x, v_y + ω (x1 − x_o))`` and ``u2_y = v_y + ω (x2 − x_o)``, with ``‖e1 + u1‖ ≤ c1``,
``|e2 + u2_y| ≤ c2`` (``eᵢ`` the offsets at the located pose). So, with centred holes:

- x: ``±c1`` (only the round pin takes x);
- the turn about z: ``±(c1 + c2)/L`` (the two holes to opposite sides);
- y of the body origin: ``±(c1 (x2 − x_o) + c2 (x_o − x1))/L``;
- z and the tilts: 0 (the rests).

With H1 offset by ``e1 = +c1`` along x (problems/housing-2-pins.toml, seated against P1) the x range
is ``[−2 c1, 0]``: the part can only move away from the pin's contact.
"""

from __future__ import annotations

import pytest
from conftest import PROBLEMS, run_cli

from fixplan.clearance import clearance_pose_range
from fixplan.fixture import load, loads

HOUSING = PROBLEMS / "housing-2-pins.toml"
TOL = 1e-9  # [m], [rad]: Clarabel's accuracy on a range of 1e-4 m


def _housing(d1: float, d2: float, x2: float):
    """The housing with P1 centred in H1 (diameter d1), P2 (d2) and H2 at x = x2."""
    text = HOUSING.read_text()
    text = text.replace("position = [-0.0401, 0.0, 0.0]", "position = [-0.04, 0.0, 0.0]")
    text = text.replace("position = [0.04, 0.0, -0.015]", f"position = [{x2}, 0.0, -0.015]")
    text = text.replace("position = [0.04, 0.0, 0.0]", f"position = [{x2}, 0.0, 0.0]")
    head, tail = text.split('name = "P2"')
    head = head.replace("diameter = 0.0098", f"diameter = {d1}")
    tail = tail.replace("diameter = 0.0098", f"diameter = {d2}")
    return loads(head + 'name = "P2"' + tail, source="housing")


@pytest.mark.parametrize(("d1", "d2", "x2"), [(0.0098, 0.0098, 0.04), (0.0099, 0.0096, 0.05), (0.0097, 0.0099, 0.03)])
def test_centred_round_and_diamond_pins_closed_forms(d1: float, d2: float, x2: float) -> None:
    fx = _housing(d1, d2, x2)
    r = clearance_pose_range(fx)
    c1, c2 = (0.010 - d1) / 2, (0.010 - d2) / 2
    x1, xo = -0.04, 0.0
    L = x2 - x1
    assert r.translation_m[0] == pytest.approx((-c1, c1), abs=TOL)
    y = (c1 * (x2 - xo) + c2 * (xo - x1)) / L
    assert r.translation_m[1] == pytest.approx((-y, y), abs=TOL)
    assert r.rotation_rad[2] == pytest.approx((-(c1 + c2) / L, (c1 + c2) / L), abs=TOL / L)
    for fixed in (r.translation_m[2], r.rotation_rad[0], r.rotation_rad[1]):
        assert fixed == pytest.approx((0.0, 0.0), abs=TOL)
    assert r.violation <= TOL
    assert r.width("rotation", 2) == pytest.approx(2 * (c1 + c2) / L, abs=2 * TOL / L)


def test_a_part_seated_against_the_round_pin_can_only_move_away_from_it() -> None:
    r = clearance_pose_range(load(HOUSING))
    c = (0.010 - 0.0098) / 2
    assert r.translation_m[0] == pytest.approx((-2 * c, 0.0), abs=TOL)  # H1's axis 0.1 mm to +x of P1's
    assert r.translation_m[1] == pytest.approx((-c, c), abs=TOL)  # midway: (c1 + c2)/2 = c
    assert r.rotation_rad[2] == pytest.approx((-2 * c / 0.08, 2 * c / 0.08), abs=TOL / 0.08)


def test_validate_verbose_shows_the_clearance_range() -> None:
    proc = run_cli("validate", "--verbose", HOUSING, check_rc=0)
    assert (
        "  clearance (P1, P2): the body origin moves x -0.2 .. +0 mm, y -0.1 .. +0.1 mm, z +0 .. +0 mm "
        "(part axes, from the located pose)"
    ) in proc.stdout.splitlines()
    assert "  clearance: the part turns x +0 .. +0 mrad, y +0 .. +0 mrad, z -2.5 .. +2.5 mrad" in proc.stdout
