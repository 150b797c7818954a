"""The plane-pin-stop family: seeded plates on 3 rests, one round pin in a bored hole and a stop.

Measured in the loaded files (never taken from the generator's own numbers): the drawn ranges,
the located pose as built (every locator touching, the round pin touching its hole's wall, the
stop facing across the pin's axis and taking the turn about it), the start clear above the pin's
tip and the stop, tilted, the family's determinism, its rotated twins (``--rotate-world``: every
gap the unrotated fixture's) and one fixture planned and verified from its start.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from conftest import run_cli

import fixplan
import fixplan.generate as gen
from fixplan.locating import cylinder_contacts, insertion_axis, located_pose, locator_gaps, seat_at
from fixplan.settings import HAPTIC
from fixplan.spatial import log_so3

FAMILY = "plane-pin-stop"


@pytest.fixture(scope="module")
def drawn() -> list[tuple[gen.GeneratedFixture, fixplan.Fixture]]:
    return [(g, fixplan.loads(g.toml_text)) for g in gen.generate(FAMILY, 12, 2026)]


def test_ranges_in_the_loaded_files(drawn) -> None:
    faces, tips, mirrored, tilts = set(), [], set(), []
    for g, fx in drawn:
        (hole,), (pin,) = fx.workpiece.holes, fx.pins
        a, b, c = 2.0 * np.asarray(fx.workpiece.shape.half)
        for x, (lo, hi) in zip((a, b, c), gen.PIN_PART_EDGE_M, strict=True):
            assert lo - 1e-4 <= x <= hi + 1e-4
        assert gen.PIN_HOLE_D_M[0] <= hole.diameter_m <= gen.PIN_HOLE_D_M[1] and hole.through
        play = 0.5 * (hole.diameter_m - pin.diameter_m)
        assert gen.PIN_PLAY_M[0] * (1 - 1e-2) <= play <= gen.PIN_PLAY_M[1] * (1 + 1e-2)
        for chamfer in (hole.chamfer_m, pin.chamfer_m):
            assert gen.PIN_CHAMFER_M[0] <= chamfer <= gen.PIN_CHAMFER_M[1]
        assert pin.kind == "round"
        assert gen.PIN_LENGTH_FRACTION[0] * c - 1e-4 <= pin.length_m <= gen.PIN_LENGTH_FRACTION[1] * c + 1e-4
        s1 = next(loc for loc in fx.locators if loc.name == "S1")
        assert s1.radius_m == 0.0 or gen.STOP_TIP_RADIUS_M[0] <= s1.radius_m <= gen.STOP_TIP_RADIUS_M[1]
        tips.append(s1.radius_m)
        height = float(s1.p_world[2])
        assert gen.STOP_HEIGHT_FRACTION[0] * c - 1e-4 <= height <= gen.STOP_HEIGHT_FRACTION[1] * c + 1e-4
        faces.add(g.params["stop_face"])
        mirrored.add(g.params["rests_mirrored"])
        tilts.append(log_so3(fx.start.R_world_body @ fx.goal.R_world_body.T))
    assert faces == {"-x", "+x", "-y", "+y"} and mirrored == {True, False}
    assert 0.0 in tips and max(tips) > 0.0  # point and spherical tips
    # tilted about every axis, up to 10 deg each (the rotation vector of small turns: close to the rpy)
    tilts = np.abs(np.array(tilts))
    assert np.all(tilts.max(axis=0) > math.radians(5.0)) and tilts.max() < math.radians(1.1 * gen.PIN_STOP_TILT_DEG * 3)


def test_located_pose_as_built_and_start_clear_above_everything(drawn) -> None:
    """At the goal every locator at gap 0, P1 touching its hole, S1 a stop that takes the turn about P1; at the start nothing within reach."""
    from fixplan.planner.insertion import seat_turn

    for _g, fx in drawn:
        wp = fx.workpiece
        G, u = located_pose(fx), insertion_axis(fx)
        assert np.abs(locator_gaps(wp, G, fx.locators)).max() <= gen.EXACT_M
        assert abs(min(c.gap_m for c in cylinder_contacts(fx, G))) <= gen.EXACT_M
        seat = seat_at(fx, G, u)
        assert seat.stop_names == ("S1",)
        pin = fx.pins[0]
        (stop,) = seat.stops
        lever = abs(float(stop.normal_world @ np.cross(u, stop.point_world - pin.p_world)))
        assert lever >= gen.STOP_LEVER_FRACTION * 2.0 * float(min(wp.shape.half[:2])) - 1e-9
        assert seat_turn(fx, G, u, HAPTIC.insertion) is not None  # it goes down turned away from S1
        assert locator_gaps(wp, fx.start, fx.locators).min() > gen.CLEARANCE_M
        # the part's lowest corner above the pin's tip and the stop's top
        corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * wp.shape.half
        lowest = float(np.min((corners @ fx.start.R_world_body.T + fx.start.p_world) @ u))
        s1 = next(loc for loc in fx.locators if loc.name == "S1")
        assert lowest >= max(pin.length_m, float(s1.p_world[2]) + s1.radius_m) + gen.PIN_STOP_RISE_M[0] - 1e-6


def test_deterministic_per_seed_and_index() -> None:
    a = gen.generate(FAMILY, 3, 11)
    assert [x.toml_text for x in a] == [x.toml_text for x in gen.generate(FAMILY, 3, 11)]
    assert gen.generate_one(FAMILY, 11, 2).toml_text == a[2].toml_text
    assert all(x.toml_text != y.toml_text for x, y in zip(a, gen.generate(FAMILY, 3, 12), strict=True))


def test_rotate_world_keeps_every_gap(drawn) -> None:
    for (g, fx), turned in zip(drawn[:3], gen.generate(FAMILY, 3, 2026, rotate_world=True), strict=True):
        assert turned.name == g.name + "-rotated" and turned.draws == g.draws
        R = np.asarray(turned.params["world_rotation"])
        tw = fixplan.loads(turned.toml_text)
        np.testing.assert_allclose(tw.pins[0].axis_world, R @ fx.pins[0].axis_world, atol=1e-12)
        for a, b in ((fx.start, tw.start), (fx.goal, tw.goal)):
            np.testing.assert_allclose(
                locator_gaps(tw.workpiece, b, tw.locators), locator_gaps(fx.workpiece, a, fx.locators), atol=1e-12
            )
        assert seat_at(tw, tw.goal, insertion_axis(tw)).stop_names == ("S1",)


def test_cli_writes_files_that_validate(tmp_path) -> None:
    proc = run_cli("generate", FAMILY, "--count", "2", "--seed", "5", "--out", tmp_path, "--json", check_rc=0)
    files = [f["path"] for f in json.loads(proc.stdout)["files"]]
    valid = run_cli("validate", *files)
    assert valid.returncode == 0 and "warning" not in valid.stdout + valid.stderr, valid.stderr


def test_a_generated_fixture_is_planned_and_verified_onto_its_stop(drawn) -> None:
    _g, fx = drawn[0]
    result = fixplan.solve(fx)
    assert result.status == "planned", result.reason
    v = result.verification
    assert v is not None and v.passed and [list(s) for s in v.observed_sequence][-1] == ["B1", "B2", "B3", "P1", "S1"]
    assert np.abs(locator_gaps(fx.workpiece, v.final_pose, fx.locators)).max() <= HAPTIC.execution.contact_gap_m
