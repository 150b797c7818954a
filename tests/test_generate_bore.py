"""The shaft-bore family: seeded shafts above a blind bore, to be loaded to its bottom.

Measured in the loaded files (never taken from the generator's own numbers): the drawn ranges (the
shaft, the radial play (D − d)/2, the mouth chamfer, sharp bores among them), the located pose the
loader derives (coaxial, the leading end on the bottom, in the file's form in ``goal``), the start
clear above the bore (its lowest point 2–20 mm over the mouth's plane, tilted within 10°), the
family's determinism, its rotated twins (``--rotate-world``: the bore's axis R (0, 0, 1), every gap
the unrotated fixture's), and that the planner loads a sharp and a rotated one.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from conftest import run_cli

import fixplan
import fixplan.generate as gen
from fixplan.locating import bottom_gap_m, cylinder_contacts, located_pose

FAMILY = "shaft-bore"


@pytest.fixture(scope="module")
def drawn() -> list[tuple[gen.GeneratedFixture, fixplan.Fixture]]:
    return [(g, fixplan.loads(g.toml_text)) for g in gen.generate(FAMILY, 16, 2026)]


def _lowest_above_mouth(fx: fixplan.Fixture) -> float:
    """The shaft's lowest point above the bore's mouth plane at the start: an end's centre less r sin(tilt)."""
    (bore,) = fx.bores
    shape, S = fx.workpiece.shape, fx.start
    z = S.R_world_body[:, 2]
    sin_tilt = math.sqrt(max(0.0, 1.0 - float(z @ bore.axis_world) ** 2))
    ends = [S.p_world + s * 0.5 * shape.length * z for s in (1.0, -1.0)]
    return min(float((e - bore.p_world) @ bore.axis_world) for e in ends) - shape.radius * sin_tilt


def test_ranges_in_the_loaded_files(drawn) -> None:
    chamfers = []
    for _g, fx in drawn:
        shape, (bore,) = fx.workpiece.shape, fx.bores
        assert fx.locators == () and fx.pins == () and shape.name == "cylinder"
        assert gen.SHAFT_RADIUS_M[0] <= shape.radius <= gen.SHAFT_RADIUS_M[1]
        ratio = shape.length / (2.0 * shape.radius)
        assert gen.SHAFT_LENGTH_PER_DIAMETER[0] * 0.99 <= ratio <= gen.SHAFT_LENGTH_PER_DIAMETER[1] * 1.01
        play = 0.5 * bore.diameter_m - shape.radius
        assert gen.BORE_PLAY_M[0] * 0.99 <= play <= gen.BORE_PLAY_M[1] * 1.01
        assert gen.BORE_CHAMFER_M[0] <= bore.chamfer_m <= gen.BORE_CHAMFER_M[1]
        depth = bore.depth_m / shape.length
        assert gen.BORE_DEPTH_FRACTION[0] - 1e-3 <= depth <= gen.BORE_DEPTH_FRACTION[1] + 1e-3
        chamfers.append(bore.chamfer_m)
        np.testing.assert_array_equal(bore.axis_world, [0.0, 0.0, 1.0])
    assert 0.0 in chamfers and max(chamfers) > 1e-3  # sharp bores and wide chamfers both drawn


def test_the_located_pose_is_derived_and_the_start_is_clear_above(drawn) -> None:
    """No goal in the file; the derived pose coaxial on the bottom (the GeneratedFixture's goal); nothing touches."""
    for g, fx in drawn:
        assert "goal =" not in g.toml_text and fx.goal_given is None
        (bore,) = fx.bores
        G = located_pose(fx)
        assert abs(bottom_gap_m(fx, G, bore)) <= gen.EXACT_M
        np.testing.assert_allclose(G.R_world_body[:, 2] * np.sign(G.R_world_body[2, 2]), [0.0, 0.0, 1.0], atol=1e-12)
        np.testing.assert_allclose(G.p_world[:2], [0.0, 0.0], atol=1e-12)
        assert G.p_world[2] == pytest.approx(0.5 * fx.workpiece.shape.length - bore.depth_m, abs=1e-12)
        np.testing.assert_allclose(g.goal["position"], G.p_world, atol=1e-12)
        low = _lowest_above_mouth(fx)
        assert gen.SHAFT_START_RISE_M[0] - 1e-9 <= low <= gen.SHAFT_START_RISE_M[1] + 1e-9
        assert all(c.gap_m > gen.CLEARANCE_M for c in cylinder_contacts(fx, fx.start))
        tilt = math.degrees(math.acos(min(1.0, abs(float(fx.start.R_world_body[2, 2])))))
        assert tilt <= math.sqrt(2.0) * gen.SHAFT_START_TILT_DEG + 1e-6


def test_deterministic_per_seed_and_index() -> None:
    a = gen.generate(FAMILY, 3, 11)
    assert [x.toml_text for x in a] == [x.toml_text for x in gen.generate(FAMILY, 3, 11)]
    assert gen.generate_one(FAMILY, 11, 2).toml_text == a[2].toml_text
    assert all(x.toml_text != y.toml_text for x, y in zip(a, gen.generate(FAMILY, 3, 12), strict=True))


def test_rotate_world_tilts_the_bore_and_keeps_every_gap(drawn) -> None:
    """``--rotate-world``: the bore's mouth R·0 and axis R (0, 0, 1); the least gap at the start and at the located pose the same."""
    for (g, fx), turned in zip(drawn[:3], gen.generate(FAMILY, 3, 2026, rotate_world=True), strict=True):
        assert turned.name == g.name + "-rotated" and turned.draws == g.draws
        R = np.asarray(turned.params["world_rotation"])
        tw = fixplan.loads(turned.toml_text)
        np.testing.assert_allclose(tw.bores[0].axis_world, R @ [0.0, 0.0, 1.0], atol=1e-12)
        np.testing.assert_allclose(tw.gravity, R @ [0.0, 0.0, -9.81], atol=1e-12)
        np.testing.assert_allclose(turned.goal["position"], R @ located_pose(fx).p_world, atol=1e-9)
        for a, b in ((fx.start, tw.start), (located_pose(fx), located_pose(tw))):
            least = [min(c.gap_m for c in cylinder_contacts(f, pose)) for f, pose in ((fx, a), (tw, b))]
            assert least[1] == pytest.approx(least[0], abs=1e-9)


def test_cli_lists_the_family_and_writes_files_that_validate(tmp_path) -> None:
    listed = run_cli("generate", "--list", "--json", check_rc=0)
    assert json.loads(listed.stdout)["families"][FAMILY] == gen.PIN_FAMILIES[FAMILY]
    proc = run_cli("generate", FAMILY, "--count", "2", "--seed", "5", "--rotate-world", "--out", tmp_path, "--json",
                   check_rc=0)  # fmt: skip
    files = [f["path"] for f in json.loads(proc.stdout)["files"]]
    assert files[0].endswith("shaft-bore-s5-000-rotated.toml")
    valid = run_cli("validate", *files)
    assert valid.returncode == 0 and "warning" not in valid.stdout + valid.stderr, valid.stderr


@pytest.mark.slow
def test_a_sharp_bore_and_a_tilted_world_are_planned_and_verified() -> None:
    """Seed 2031: the first sharp bore (its play the only capture) and fixture 0 turned with the world: each loaded to
    the bottom, coaxial within the play, without retries."""
    from fixplan.planner.solve import solve

    sharp = next(g for g in gen.generate(FAMILY, 20, 2031) if g.params["bore_chamfer_m"] == 0.0)
    for g in (sharp, gen.generate_one(FAMILY, 2031, 0, rotate_world=True)):
        r = solve(fixplan.loads(g.toml_text))
        assert r.status == "planned", r.reason
        v = r.verification
        assert v is not None and v.observed_sequence == [("B1",), ("B1", "B1.bottom")]
        assert v.final_gaps_m["B1.axis_offset"] <= g.params["radial_play_m"] * 1.05
        assert v.max_penetration_m <= 1e-6
        assert v.execution is not None and v.execution.counts["retries"] == 0
