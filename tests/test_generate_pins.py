"""The plane-2-pins family: seeded boxes on 3 rests, a round and a diamond pin in two bored holes.

Measured in the loaded files (never taken from the generator's own numbers): the drawn ranges,
the located pose as built (every rest touching, the round pin touching its hole's wall, the diamond
pin centred with the radial play (D − d)/2 on each side), the start clear above the pins with each
hole within the chamfers' capture of its pin, the family's determinism, and its rotated twins
(``--rotate-world``: every gap the unrotated fixture's).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import run_cli

import fixplan
import fixplan.generate as gen
from fixplan.locating import cylinder_contacts, locator_gaps

FAMILY = "plane-2-pins"


@pytest.fixture(scope="module")
def drawn() -> list[tuple[gen.GeneratedFixture, fixplan.Fixture]]:
    return [(g, fixplan.loads(g.toml_text)) for g in gen.generate(FAMILY, 12, 2026)]


def test_ranges_in_the_loaded_files(drawn) -> None:
    chamfers = []
    longer = []
    for _g, fx in drawn:
        (h1, h2), (p1, p2) = fx.workpiece.holes, fx.pins
        thickness = 2.0 * fx.workpiece.shape.half[2]
        for pin in (p1, p2):  # each pin's length drawn on its own
            lo, hi = gen.PIN_LENGTH_FRACTION
            assert lo * thickness - 1e-4 <= pin.length_m <= hi * thickness + 1e-4
        longer.append(p1.length_m > p2.length_m)
        D, d = h1.diameter_m, p1.diameter_m
        assert gen.PIN_HOLE_D_M[0] <= D <= gen.PIN_HOLE_D_M[1] and h2.diameter_m == D
        play = 0.5 * (D - d)
        assert gen.PIN_PLAY_M[0] * (1 - 1e-2) <= play <= gen.PIN_PLAY_M[1] * (1 + 1e-2)
        for c in (h1.chamfer_m, p1.chamfer_m):
            assert gen.PIN_CHAMFER_M[0] <= c <= gen.PIN_CHAMFER_M[1]
        chamfers += [h1.chamfer_m, p1.chamfer_m]
        assert h1.through and h2.through  # bored through the part
        assert p1.kind == "round" and p2.kind == "diamond"
        # the diamond's lands locate across the line between the holes (the turn about the round pin);
        # the round pin stands the play off its hole's axis
        between = p2.p_world - p1.p_world
        assert abs(float(np.dot(p2.land_direction_world, between))) <= play + 1e-9
        assert float(np.linalg.norm(between[:2])) >= gen.PIN_SPAN_FRACTION * fx.workpiece.shape.half[0] * 2 - play
    assert min(chamfers) < 0.5e-3 and max(chamfers) > 1.5e-3  # the range is used
    assert 0 < sum(longer) < len(longer)  # either pin may be the longer: either engages first


def test_located_pose_as_built_and_start_above_the_pins(drawn) -> None:
    """At the goal: rests at gap 0, P1 at 0 (seated against it), P2 at (D − d)/2; at the start nothing touches."""
    for _g, fx in drawn:
        wp = fx.workpiece
        assert np.abs(locator_gaps(wp, fx.goal, fx.locators)).max() <= gen.EXACT_M
        least: dict[str, float] = {}
        for c in cylinder_contacts(fx, fx.goal):
            least[c.owner] = min(least.get(c.owner, np.inf), c.gap_m)
        play = 0.5 * (wp.holes[0].diameter_m - fx.pins[0].diameter_m)
        assert abs(least["P1"]) <= gen.EXACT_M
        assert least["P2"] == pytest.approx(play, abs=gen.EXACT_M)
        assert locator_gaps(wp, fx.start, fx.locators).min() > gen.CLEARANCE_M
        assert all(c.gap_m > gen.CLEARANCE_M for c in cylinder_contacts(fx, fx.start))
        capture = play + wp.holes[0].chamfer_m + fx.pins[0].chamfer_m
        for pin in fx.pins:
            mouth = fx.start.point_world_from_body(wp.hole(pin.hole).p_body)
            off = mouth - pin.p_world
            lateral = np.linalg.norm(off - np.dot(off, pin.axis_world) * pin.axis_world)
            assert lateral <= gen.PIN_CAPTURE_CHECK * capture + 1e-12
            assert np.dot(off, pin.axis_world) > pin.length_m  # the mouth above the pin's tip


def test_deterministic_per_seed_and_index() -> None:
    a = gen.generate(FAMILY, 3, 11)
    assert [x.toml_text for x in a] == [x.toml_text for x in gen.generate(FAMILY, 3, 11)]
    assert gen.generate_one(FAMILY, 11, 2).toml_text == a[2].toml_text
    assert all(x.toml_text != y.toml_text for x, y in zip(a, gen.generate(FAMILY, 3, 12), strict=True))


def test_cli_writes_files_that_validate(tmp_path) -> None:
    proc = run_cli("generate", FAMILY, "--count", "2", "--seed", "5", "--out", tmp_path, "--json", check_rc=0)
    files = [f["path"] for f in json.loads(proc.stdout)["files"]]
    valid = run_cli("validate", *files)
    assert valid.returncode == 0 and "warning" not in valid.stdout + valid.stderr, valid.stderr


def test_rotate_world_turns_the_pins_and_keeps_every_gap(drawn) -> None:
    """``--rotate-world``: the same draw turned by R, the pins' axes R (0, 0, 1); every gap at the start and goal the same."""
    for (g, fx), turned in zip(drawn[:3], gen.generate(FAMILY, 3, 2026, rotate_world=True), strict=True):
        assert turned.name == g.name + "-rotated" and turned.draws == g.draws
        R = np.asarray(turned.params["world_rotation"])
        tw = fixplan.loads(turned.toml_text)
        for pin, twin_pin in zip(fx.pins, tw.pins, strict=True):
            np.testing.assert_allclose(twin_pin.axis_world, R @ pin.axis_world, atol=1e-12)
            np.testing.assert_allclose(twin_pin.p_world, R @ pin.p_world, atol=1e-12)
        assert [h.p_body.tolist() for h in tw.workpiece.holes] == [h.p_body.tolist() for h in fx.workpiece.holes]
        for a, b in ((fx.start, tw.start), (fx.goal, tw.goal)):
            np.testing.assert_allclose(
                locator_gaps(tw.workpiece, b, tw.locators), locator_gaps(fx.workpiece, a, fx.locators), atol=1e-12
            )
            for owner in ("P1", "P2"):
                least = [min(c.gap_m for c in cylinder_contacts(f, pose) if c.owner == owner)
                         for f, pose in ((fx, a), (tw, b))]  # fmt: skip
                assert least[1] == pytest.approx(least[0], abs=1e-12)


def test_cli_rotate_world_writes_pin_files_that_validate(tmp_path) -> None:
    proc = run_cli("generate", FAMILY, "--count", "1", "--seed", "5", "--rotate-world", "--out", tmp_path, "--json",
                   check_rc=0)  # fmt: skip
    (entry,) = json.loads(proc.stdout)["files"]
    assert entry["path"].endswith("plane-2-pins-s5-000-rotated.toml")
    assert run_cli("validate", entry["path"]).returncode == 0


# -- plane-2-pins-mesh: the same draws, the box written as a mesh part with its bores modelled --------
MESH_FAMILY = "plane-2-pins-mesh"


def _load_beside(g: gen.GeneratedFixture, folder) -> fixplan.Fixture:
    for name, data in g.files:
        (folder / name).write_bytes(data)
    (folder / f"{g.name}.toml").write_text(g.toml_text)
    return fixplan.load(folder / f"{g.name}.toml")


def test_the_mesh_variant_is_the_box_variants_fixture_seed_for_seed(tmp_path) -> None:
    """Same draw, rests, pins, holes, start, goal and mass; the mesh's box has the drawn size, its volume the box's
    less the two square channels (half side D/2 + chamfer, up to 0.1 mm), each hole's axis inside its channel."""
    for box_g, mesh_g in zip(gen.generate(FAMILY, 6, 2026), gen.generate(MESH_FAMILY, 6, 2026), strict=True):
        assert mesh_g.draws == box_g.draws and mesh_g.params == box_g.params
        assert [name for name, _data in mesh_g.files] == [f"{mesh_g.name}.stl"]
        box, mesh = fixplan.loads(box_g.toml_text), _load_beside(mesh_g, tmp_path)
        for a, b in ((box.locators, mesh.locators), (box.pins, mesh.pins), (box.workpiece.holes, mesh.workpiece.holes)):
            assert [repr(x) for x in a] == [repr(x) for x in b]
        assert box.start.distance_to(mesh.start) == (0.0, 0.0) and box.goal.distance_to(mesh.goal) == (0.0, 0.0)
        assert mesh.workpiece.mass_kg == box.workpiece.mass_kg
        a, b, c = (2.0 * h for h in box.workpiece.shape.half)
        V = np.asarray(mesh.workpiece.shape.vertices)
        np.testing.assert_allclose(
            V.max(axis=0) - V.min(axis=0), [a, b, c], rtol=0, atol=2e-8
        )  # float32 in mm: half an ulp at 150 mm is 7.6e-9 m a face
        halves = [np.ceil((0.5 * h.diameter_m + h.chamfer_m) * 1e4) / 1e4 for h in box.workpiece.holes]
        expected = a * b * c - sum((2.0 * s) ** 2 * c for s in halves)
        assert mesh.workpiece.shape.volume_m3 == pytest.approx(expected, rel=1e-6)
        for hole, half in zip(mesh.workpiece.holes, halves, strict=True):
            assert hole.through  # the channel: nothing past the bottom
            mid = hole.p_body - 0.5 * hole.depth_m * hole.axis_body  # on the axis, halfway down: in the channel
            assert mesh.workpiece.shape.project(mid).distance == pytest.approx(half, abs=2e-8)


def test_cli_writes_each_mesh_variant_beside_its_stl(tmp_path) -> None:
    proc = run_cli("generate", MESH_FAMILY, "--count", "2", "--seed", "5", "--out", tmp_path, "--json", check_rc=0)
    doc = json.loads(proc.stdout)["files"]
    assert [f["files"] for f in doc] == [[str(tmp_path / f"{MESH_FAMILY}-s5-{i:03d}.stl")] for i in range(2)]
    valid = run_cli("validate", *(f["path"] for f in doc))
    assert valid.returncode == 0 and "warning" not in valid.stdout + valid.stderr, valid.stderr


def test_the_mesh_variant_turned_with_the_world_keeps_its_mesh_and_every_gap(tmp_path) -> None:
    """``--rotate-world``: the mesh is the part's (its own frame), written as drawn; the pins turn with the world."""
    (g,) = gen.generate(MESH_FAMILY, 1, 2026)
    (turned,) = gen.generate(MESH_FAMILY, 1, 2026, rotate_world=True)
    assert [name for name, _ in turned.files] == [f"{turned.name}.stl"] and turned.files[0][1] == g.files[0][1]
    fx, tw = _load_beside(g, tmp_path), _load_beside(turned, tmp_path)
    R = np.asarray(turned.params["world_rotation"])
    for pin, twin_pin in zip(fx.pins, tw.pins, strict=True):
        np.testing.assert_allclose(twin_pin.axis_world, R @ pin.axis_world, atol=1e-12)
    for a, b in ((fx.start, tw.start), (fx.goal, tw.goal)):
        np.testing.assert_allclose(
            locator_gaps(tw.workpiece, b, tw.locators), locator_gaps(fx.workpiece, a, fx.locators), atol=1e-9
        )


@pytest.mark.slow
def test_a_generated_mesh_fixture_is_planned_and_verified_as_its_box(tmp_path) -> None:
    """The staged insertion of one fixture, as a box and as a mesh with modelled bores: planned, verified, the same stages."""
    from fixplan.planner.solve import solve

    box_g, mesh_g = gen.generate_one(FAMILY, 2031, 1), gen.generate_one(MESH_FAMILY, 2031, 1)
    box, mesh = solve(fixplan.loads(box_g.toml_text)), solve(_load_beside(mesh_g, tmp_path))
    assert box.status == mesh.status == "planned", mesh.reason
    assert [t.added for t in mesh.transitions] == [t.added for t in box.transitions]
    assert mesh.verification is not None and mesh.verification.passed
    assert mesh.verification.observed_sequence == box.verification.observed_sequence  # type: ignore[union-attr]
