"""Metamorphic tests of pin and bore fixtures: a fixture's rotated and mirrored twins get the same plan.

A rigid motion or a reflection of the whole world (rests, pins, bores, start, goal, gravity; the
part's holes ride in its body frame and flip with it in a mirror: :mod:`fixplan.twins`) changes
no gap, no normal force and no friction cone, so ``solve`` must give each twin the same status,
the same contact-state sequence (the mirror's rests renamed and listed in reverse order) and the
same insertion stages, and a final pose that the map carries onto the original's:

- rotated by ``R``: ``(R R_f, R p_f)``;
- mirrored by ``x → M x + t``: ``(M R_f S, M p_f + t)``, ``S = R_s0ᵀ Mᵀ R_s1`` the body flip the
  mirror chose (read from the two files' start poses, not from the twin module).

Tolerance of the final poses (the end of a simulated insertion, not a closed form). The contacts
are found on circles sampled from a basis anchored on world axes, so a twin samples other angles
and its refined extremes agree to about 1e-12 m; a mirrored twin also lists its rests in reverse
order, so the engine's Gauss–Seidel sweeps them in another order and splits the friction
differently where the located pose leaves slack (a diamond pin's play about the round pin: the
part's yaw is held by friction only). Measured on these cases: boxes within 2.3e-9 m and
3.1e-8 rad (rotated twins within 2e-11 m and 6e-11 rad), shafts within 4.3e-7 m and 4.9e-7 rad.
The bounds: 2e-8 m and 2e-7 rad for boxes, 2e-6 m and 5e-6 rad for shafts (a fifth of the least
radial play of these cases, 1e-5 m); a shaft's spin about its own axis is free (the bore leaves
it), so only its axis is compared.

Cases: the library's pin problems (problems/housing-2-pins*.toml, shaft-in-bore, shaft-into-bore:
there is no flange problem), three seeded ``plane-2-pins`` fixtures and three seeded shafts in
bores (:func:`bore_case`).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import PROBLEMS

import fixplan
import fixplan.generate as gen
from fixplan import twins
from fixplan.fixture import parse_toml
from fixplan.geometry import Cylinder
from fixplan.locating import cylinder_contacts, locator_gaps
from fixplan.planner.solve import solve
from fixplan.spatial import Pose, log_so3, matrix_from_rpy

LIBRARY = ["housing-2-pins", "housing-2-pins-load", "housing-2-pins-clamped", "shaft-in-bore", "shaft-into-bore"]
BOX_TOL_M, BOX_TOL_RAD = 2e-8, 2e-7
SHAFT_TOL_M, SHAFT_TOL_RAD = 2e-6, 5e-6


def bore_case(index: int) -> str:
    """A seeded shaft over a blind bore (axis +z), off its axis by up to half of play + chamfer, tilted up to 1°.

    Radius 5-15 mm, length 6-10 radii, radial play 10-100 µm (log-uniform), mouth chamfer 0.5-1.5 mm,
    depth 2-4 radii, 0.1-1 kg, μ 0.1-0.3; the lower end 2-10 mm above the mouth, spun at random.
    """
    rng = np.random.default_rng([2027, index])
    r = round(float(rng.uniform(0.005, 0.015)), 4)
    length = round(r * float(rng.uniform(6.0, 10.0)), 4)
    play = float(f"{math.exp(rng.uniform(math.log(1e-5), math.log(1e-4))):.3g}")
    chamfer = round(float(rng.uniform(0.0005, 0.0015)), 5)
    depth = round(r * float(rng.uniform(2.0, 4.0)), 4)
    mass = round(float(rng.uniform(0.1, 1.0)), 3)
    mu = round(float(rng.uniform(0.1, 0.3)), 3)
    mouth = np.round(rng.uniform(-0.05, 0.05, 3), 4)
    off = rng.uniform(-1.0, 1.0, 2)
    off = off / max(1.0, float(np.linalg.norm(off))) * 0.5 * (play + chamfer)
    rise = float(rng.uniform(0.002, 0.01))
    tilt = [round(float(v), 3) for v in rng.uniform(-1.0, 1.0, 2)] + [round(float(rng.uniform(-180, 180)), 2)]
    centre = [float(v) for v in mouth + np.array([off[0], off[1], rise + length / 2])]
    return "\n".join(
        [
            "format = 1",
            "[scene]",
            f'name = "bore-case-{index}"',
            "[workpiece]",
            'shape = "cylinder"',
            f"radius = {r!r}",
            f"length = {length!r}",
            f"mass = {mass!r}",
            f"start = {{ position = {centre!r}, rpy_deg = {tilt!r} }}",
            "[[bore]]",
            'name = "B1"',
            f"position = {[float(v) for v in mouth]!r}",
            "axis = [0.0, 0.0, 1.0]",
            f"diameter = {2 * r + 2 * play!r}",
            f"depth = {depth!r}",
            f"chamfer = {chamfer!r}",
            f"friction = {mu!r}",
        ]
    )


def _texts() -> dict[str, str]:
    out = {name: (PROBLEMS / f"{name}.toml").read_text() for name in LIBRARY}
    out |= {g.name: g.toml_text for g in gen.generate("plane-2-pins", 3, 2026)}
    out |= {f"bore-case-{i}": bore_case(i) for i in range(3)}
    return out


TEXTS = _texts()
_solved: dict[str, tuple] = {}


def answer(fixture: fixplan.Fixture) -> tuple:
    result = solve(fixture)
    stages = [(st.kind, (st.target, *st.together)) for st in result.insertion.stages]
    final = None if result.verification is None else result.verification.final_pose
    return result.status, [tuple(sorted(s)) for s in result.sequence], stages, final


def original(case: str) -> tuple:
    if case not in _solved:
        _solved[case] = answer(fixplan.loads(TEXTS[case], source=case))
    return _solved[case]


def rotated_twin(case: str) -> tuple[fixplan.Fixture, dict[str, str], np.ndarray, np.ndarray]:
    R = twins.random_rotation(np.random.default_rng([20, len(case)]), 3)
    twin = fixplan.loads(twins.rotated_fixture_text(TEXTS[case], R), source=f"{case}-rotated")
    return twin, {}, R, np.zeros(3)


def mirrored_twin(case: str) -> tuple[fixplan.Fixture, dict[str, str], np.ndarray, np.ndarray]:
    fx = fixplan.loads(TEXTS[case], source=case)
    names = [loc.name for loc in fx.locators]
    mapping = {n: f"M{k}" for k, n in enumerate(reversed(names))}
    rng = np.random.default_rng([21, len(case)])
    normal, offset = rng.standard_normal(3), float(rng.uniform(-0.1, 0.1))
    order = [mapping[n] for n in reversed(names)] if names else None
    text = twins.mirrored_fixture_text(TEXTS[case], normal, offset, mapping or None, order)
    n = normal / np.linalg.norm(normal)
    return fixplan.loads(text, source=f"{case}-mirrored"), mapping, np.eye(3) - 2.0 * np.outer(n, n), 2.0 * offset * n


def assert_poses_map(fx: fixplan.Fixture, twin: fixplan.Fixture, A: np.ndarray, t: np.ndarray, a: Pose, b: Pose):
    """``b`` is ``a`` carried by the world map ``x → A x + t`` (the body flip read from the start poses)."""
    S = fx.start.R_world_body.T @ A.T @ twin.start.R_world_body  # R_s1 = A R_s0 S; the identity for a rotation
    np.testing.assert_allclose(S @ S.T, np.eye(3), atol=1e-12)
    mapped = Pose(A @ a.R_world_body @ S, A @ a.p_world + t)
    dp = float(np.linalg.norm(mapped.p_world - b.p_world))
    if isinstance(fx.workpiece.shape, Cylinder):  # the spin about the shaft's axis is free: its axis only
        za, zb = mapped.R_world_body[:, 2], b.R_world_body[:, 2]
        angle = math.atan2(float(np.linalg.norm(np.cross(za, zb))), float(za @ zb))
        assert dp <= SHAFT_TOL_M and angle <= SHAFT_TOL_RAD, (dp, angle)
    else:
        angle = float(np.linalg.norm(log_so3(mapped.R_world_body.T @ b.R_world_body)))
        assert dp <= BOX_TOL_M and angle <= BOX_TOL_RAD, (dp, angle)


@pytest.mark.parametrize("make_twin", [rotated_twin, mirrored_twin], ids=["rotated", "mirrored"])
@pytest.mark.parametrize("case", sorted(TEXTS))
def test_a_pin_fixtures_world_twin_gets_the_same_plan(case: str, make_twin) -> None:
    status, sequence, stages, final = original(case)
    assert status == "planned"  # every case plans and verifies today: the comparison is between two plans
    fx = fixplan.loads(TEXTS[case], source=case)
    twin, mapping, A, t = make_twin(case)
    twin_status, twin_sequence, twin_stages, twin_final = answer(twin)
    back = {new: old for old, new in mapping.items()}
    mapped = [tuple(sorted(back.get(n, n) for n in state)) for state in twin_sequence]
    assert (twin_status, mapped) == (status, sequence)
    # the insertion's stages, each with what it adds (the seating's rests named and listed as the twin's file does)
    mapped_stages = [(kind, sorted(back.get(n, n) for n in added)) for kind, added in twin_stages]
    assert mapped_stages == [(kind, sorted(added)) for kind, added in stages]
    assert_poses_map(fx, twin, A, t, final, twin_final)


@pytest.mark.parametrize("make_twin", [rotated_twin, mirrored_twin], ids=["rotated", "mirrored"])
@pytest.mark.parametrize("case", sorted(TEXTS))
def test_a_twins_gaps_are_the_fixtures(case: str, make_twin) -> None:
    """At the start (and the goal when given), every rest's gap and every pin's or bore's near contacts' gaps, to 1e-12 m.

    Near: within 0.2 mm. Farther out, a tip contact's least along its circle may end on either side
    of a jump of its nearest feature (or be found on one side only) by the circle's sampling, which
    a twin anchors elsewhere (tests/engine/test_pin_slots.py bounds the same effect); each pin's least
    gap is compared all the same. Near gaps are compared as values found in the other, not one to one:
    where a hole's mouth lies exactly at its pin's base (a generated fixture at its goal), rounding
    decides whether the mouth's edge is on the pin's side, and a land's second contact at the same gap
    may be counted once.
    """
    fx = fixplan.loads(TEXTS[case], source=case)
    twin, mapping, _A, _t = make_twin(case)
    poses = [(fx.start, twin.start)] + ([(fx.goal, twin.goal)] if fx.goal_pose is not None else [])
    for a, b in poses:
        mine, theirs = cylinder_contacts(fx, a), cylinder_contacts(twin, b)
        for owner in {c.owner for c in mine} | {c.owner for c in theirs}:
            gaps = [sorted(c.gap_m for c in found if c.owner == owner) for found in (mine, theirs)]
            assert gaps[1][0] == pytest.approx(gaps[0][0], abs=1e-12)
            for one, other in ((gaps[0], gaps[1]), (gaps[1], gaps[0])):  # each near gap is found in the other
                for g in one:
                    if g <= 2e-4:
                        assert min(abs(g - h) for h in other) <= 1e-12, (owner, g, other)
        by_name = {loc.name: loc for loc in twin.locators}
        twin_rests = [by_name[mapping.get(loc.name, loc.name)] for loc in fx.locators]
        np.testing.assert_allclose(
            locator_gaps(twin.workpiece, b, twin_rests), locator_gaps(fx.workpiece, a, fx.locators), rtol=0, atol=1e-12
        )


def test_a_mirror_flips_the_holes_with_the_body() -> None:
    """The housing mirrored through y = 0: the body's y axis flips, and so do its holes' mouths and axes along y."""
    text = (PROBLEMS / "housing-2-pins.toml").read_text()
    doc = twins.mirror_world(parse_toml(text, "housing"), [0.0, 1.0, 0.0])
    mouths = {h["name"]: h for h in doc["workpiece"]["hole"]}
    original_holes = {h["name"]: h for h in parse_toml(text, "housing")["workpiece"]["hole"]}
    for name, h in mouths.items():
        o = original_holes[name]
        assert h["position"] == [o["position"][0], -o["position"][1], o["position"][2]]
        assert h["axis"] == [o["axis"][0], -o["axis"][1], o["axis"][2]]
    pins = {p["name"]: p for p in doc["pin"]}
    assert pins["P2"]["land_direction"] == [0.0, -1.0, 0.0]  # a direction: reflected, the lands unchanged


def test_a_robot_has_no_mirror_twin() -> None:
    text = (PROBLEMS / "box-3-2-1-panda.toml").read_text()
    with pytest.raises(fixplan.InputError, match=r"cannot mirror a fixture with a \[robot\]"):
        twins.mirror_world(parse_toml(text, "panda"), [0.0, 1.0, 0.0])


def test_rotating_the_world_turns_a_robots_base() -> None:
    doc = parse_toml((PROBLEMS / "box-3-2-1-panda.toml").read_text(), "panda")
    R = twins.random_rotation(np.random.default_rng(5), 3)
    turned = twins.rotate_world(doc, R)
    base, new = doc["robot"]["base"], turned["robot"]["base"]
    np.testing.assert_allclose(new["position"], R @ np.asarray(base["position"]), atol=1e-15)
    R_base = matrix_from_rpy(np.radians(base.get("rpy_deg", [0.0, 0.0, 0.0])))
    np.testing.assert_allclose(matrix_from_rpy(np.radians(new["rpy_deg"])), R @ R_base, atol=1e-12)
    assert turned["robot"]["grasp"] == doc["robot"]["grasp"]  # body frame
