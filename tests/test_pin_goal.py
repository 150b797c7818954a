"""The located pose of a part on pins found from its geometry when the file gives none.

Located: every locator touching, each round pin's hole axis its radial play ``(D - d)/2`` from the
pin's axis toward the side the part starts on, each diamond pin's hole centred along its lands.
Checked against the files' own goals (the housing's start lies on its goal's side: the same pose)
and by closed forms on the flange (a hole at its centre, a stop on its +y face).
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from conftest import PROBLEMS

from fixplan.errors import FixtureError
from fixplan.fixture import loads
from fixplan.geometry.pins import radial_play_m
from fixplan.locating import locator_gaps, seating_side_at_start


def _without_goal(text: str) -> str:
    out = re.sub(r"(?m)^goal = .*\n", "", text)
    assert out != text
    return out


def _hole_offset(fx, pose, pin_name: str) -> np.ndarray:
    """The hole's mouth centre from the pin's axis, across the axis, at ``pose`` [m]."""
    pin = next(p for p in fx.pins if p.name == pin_name)
    m = pose.point_world_from_body(fx.workpiece.hole(pin.hole).p_body)
    r = m - pin.p_world
    return r - float(r @ pin.axis_world) * pin.axis_world


def test_the_housing_without_its_goal_is_located_where_its_file_says() -> None:
    """housing-2-pins starts on the side its goal is seated to: the found pose is the file's, to 1e-9 m."""
    text = (PROBLEMS / "housing-2-pins.toml").read_text()
    given = loads(text).goal_pose
    found = loads(_without_goal(text)).goal_pose
    assert np.allclose(found.p_world, given.p_world, atol=1e-9)
    assert np.allclose(found.R_world_body, given.R_world_body, atol=1e-9)


def test_the_flange_is_seated_toward_the_side_it_starts_on_by_the_closed_form() -> None:
    """The flange (hole at its centre, pin 0.1 mm to -x of the file's goal, stop S1 on the +y face).

    Started 5 mm to +y of the pin, the part is seated toward +y: the hole's centre 0.1 mm (the
    play) +y of the pin's axis, at (-0.0001, 0.0001). The +y face (0.05 from the centre) would then
    reach 0.0501 at S1: the part turns about the hole's centre by θ until the face (normal
    (-sin θ, cos θ), 0.05 from the centre) passes through S1 (0.03, 0.05):
    (0.05 - y_c) cos θ - (0.03 - x_c) sin θ = 0.05, turned clockwise seen from above.
    """
    text = _without_goal((PROBLEMS / "flange-1-pin-stop.toml").read_text())
    text = re.sub(r"(?m)^start = .*$", "start = { position = [-0.0001, 0.005, 0.04], rpy_deg = [0.0, 0.0, 0.0] }", text)
    fx = loads(text)
    pin = fx.pins[0]
    u = pin.axis_world
    assert np.allclose(seating_side_at_start(fx, u), [0.0, 1.0, 0.0])
    goal = fx.goal_pose
    play = radial_play_m(fx.workpiece.hole(pin.hole).diameter_m, pin.diameter_m)
    assert play == pytest.approx(1e-4, rel=1e-12)
    off = _hole_offset(fx, goal, "P1")
    assert np.allclose(off, [0.0, play, 0.0], atol=1e-10)
    xc, yc = -0.0001, 0.0001
    # A cos(θ + ψ) = 0.05 with A = hypot(0.05 - yc, 0.03 - xc), ψ = atan2(0.03 - xc, 0.05 - yc)
    A, psi = math.hypot(0.05 - yc, 0.03 - xc), math.atan2(0.03 - xc, 0.05 - yc)
    theta = math.acos(0.05 / A) - psi
    yaw = math.atan2(goal.R_world_body[1, 0], goal.R_world_body[0, 0])
    assert yaw == pytest.approx(theta, abs=1e-9)
    assert theta < 0.0
    gaps = locator_gaps(fx.workpiece, goal, fx.locators)
    assert np.max(np.abs(gaps)) <= 1e-10


def test_a_diamond_pin_s_hole_is_centred_along_its_lands() -> None:
    text = _without_goal((PROBLEMS / "housing-2-pins.toml").read_text())
    fx = loads(text)
    diamond = next(p for p in fx.pins if p.kind == "diamond")
    assert abs(float(_hole_offset(fx, fx.goal_pose, diamond.name) @ diamond.land_direction_world)) <= 1e-10
    (rnd,) = [p for p in fx.pins if p.kind == "round"]
    play = radial_play_m(fx.workpiece.hole(rnd.hole).diameter_m, rnd.diameter_m)
    assert float(np.linalg.norm(_hole_offset(fx, fx.goal_pose, rnd.name))) == pytest.approx(play, abs=1e-10)


def test_no_located_pose_with_the_pins_is_said_in_one_line() -> None:
    """A stop moved 2 cm beyond the flange's +y face (y = 0.07) while the pin holds the hole within
    0.1 mm of its axis: no pose touches it; the loader says so instead of a traceback."""
    text = _without_goal((PROBLEMS / "flange-1-pin-stop.toml").read_text())
    moved = text.replace("position = [0.03, 0.05, 0.01]", "position = [0.03, 0.07, 0.01]")
    assert moved != text
    with pytest.raises(FixtureError) as info:
        loads(moved, source="f.toml")
    (line,) = str(info.value).splitlines()
    assert line.startswith("f.toml: workpiece.goal: missing, and no located pose found with the pins")
    assert line.endswith("give workpiece.goal (the located pose)")


def test_pins_that_are_not_parallel_without_a_goal_are_refused_in_one_line() -> None:
    text = _without_goal((PROBLEMS / "housing-2-pins.toml").read_text())
    head, tail = text.split('name = "P2"', 1)
    tilted = head + 'name = "P2"' + tail.replace("axis = [0.0, 0.0, 1.0]", "axis = [0.3, 0.0, 0.954]", 1)
    assert tilted != text
    with pytest.raises(FixtureError) as info:
        loads(tilted, source="f.toml")
    (line,) = str(info.value).splitlines()
    assert line.startswith(
        "f.toml: workpiece.goal: missing, and no located pose to find: pin.P2.axis: the pins' axes differ"
    )
