"""Pins in holes and pegs in bores: closed-form contacts, the format's checks, verdicts.

Every expected number is derived here by hand (radial play, the two-point contact of a tilted
peg, Whitney's wedging condition), never by running fixplan.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from conftest import PROBLEMS, run_cli

import fixplan
from fixplan.errors import FixtureError
from fixplan.geometry.pins import HoleBody, PinBody, pin_hole_contacts, radial_play_m
from fixplan.jamming import can_wedge
from fixplan.kinematics import Contact, ContactSet
from fixplan.locating import contact_set
from fixplan.spatial import Pose, exp_so3

HOUSING = PROBLEMS / "housing-2-pins.toml"
R_HOLE, R_PIN = 0.005, 0.0049  # D = 10 mm, d = 9.8 mm


def _hole(depth: float = 0.03, blind: bool = True) -> HoleBody:
    # mouth at the origin, the hole going down (-z): its axis out of the part is +z
    return HoleBody(np.zeros(3), np.array([0.0, 0.0, 1.0]), R_HOLE, depth, 0.0, blind)


# -- radial play -------------------------------------------------------------------------------------
@pytest.mark.parametrize("offset", [0.0, 1e-5, 3e-5, 6e-5, 1e-4, 1.5e-4])
@pytest.mark.parametrize("heading", [0.0, 0.7, 2.0, -2.6])
def test_radial_play_is_half_the_difference_of_diameters(offset: float, heading: float) -> None:
    """An upright pin whose axis is ``e`` off the hole's: rim and mouth gaps are (D - d)/2 - e exactly."""
    assert radial_play_m(2 * R_HOLE, 2 * R_PIN) == pytest.approx(1e-4, abs=1e-18)
    d = np.array([math.cos(heading), math.sin(heading), 0.0])
    pin = PinBody(offset * d + np.array([0.0, 0.0, 0.01]), np.array([0.0, 0.0, -1.0]), R_PIN, 0.02)
    found = {c.kind: c for c in pin_hole_contacts(pin, _hole())}
    assert set(found) == {"rim", "mouth", "bottom"}
    for kind in ("rim", "mouth"):
        c = found[kind]
        assert abs(c.gap_m - (radial_play_m(2 * R_HOLE, 2 * R_PIN) - offset)) <= 1e-12, (kind, c.gap_m)
        if offset > 0.0:  # the nearest side is the offset's, the normal radially outward
            assert np.allclose(c.normal_world, d, atol=1e-9)
        assert abs(np.linalg.norm(c.point_hole_world[:2]) - R_HOLE) <= 1e-12  # on the wall / the edge
    # the tip 0.01 m into a 0.03 m hole: 0.02 m from the bottom
    assert abs(found["bottom"].gap_m - 0.02) <= 1e-12


@pytest.mark.parametrize("tilt", [1e-3, 3e-3, 5e-3])
@pytest.mark.parametrize("offset", [0.0, 2e-5, 5e-5])
def test_tilted_rim_gap_is_the_extreme_of_its_circle(tilt: float, offset: float) -> None:
    """A tilted pin: the rim gap is R minus the largest distance of the rim circle from the hole's axis."""
    rng = np.random.default_rng(24)
    axis = exp_so3(np.array([tilt, 0.0, 0.0])) @ np.array([0.0, 0.0, -1.0])
    pin = PinBody(np.array([offset, 0.0, 0.01]), axis, R_PIN, 0.02)
    rim = next(c for c in pin_hole_contacts(pin, _hole()) if c.kind == "rim")
    centre = pin.base_world + pin.length_m * axis
    e1 = np.cross(axis, [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    phi = np.concatenate([np.linspace(0, 2 * np.pi, 200001), rng.uniform(0, 2 * np.pi, 1000)])
    pts = centre + R_PIN * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2)
    brute = R_HOLE - np.max(np.linalg.norm(pts[:, :2], axis=1))
    assert rim.gap_m <= brute + 1e-15  # the extreme is at least as far out as any sample
    assert brute - rim.gap_m <= 1e-12  # and the samples (spaced 3e-5 rad) come within 1e-12 m of it


# -- the two-point contact of a tilted peg in a bore ----------------------------------------------------
@pytest.mark.parametrize("theta", [2e-3, 4e-3, 8e-3])
def test_two_point_contact_of_a_tilted_peg(theta: float) -> None:
    """Peg radius r, bore R, tilted by θ about x, its leading rim touching the +y wall.

    Leading-end centre (0, y0, -l), axis u = (0, sin θ, -cos θ) (from the trailing end), rim
    extreme x_B = c + r (0, cos θ, sin θ): its gap R - y0 - r cos θ = 0 sets y0 = R - r cos θ.
    The mouth edge's point (0, -R, 0) is at d = |w × u| = (R + y0) cos θ - l sin θ from the axis
    (w = (0, -R - y0, l)): it touches (d = r) at depth l = ((2R - r cos θ) cos θ - r) / sin θ.
    Normals (from the bore into the peg): -y at B, and at A -w⊥/|w⊥|, w⊥ = w - (w·u) u.
    """
    R, r, L = 0.0101, 0.01, 0.3
    y0 = R - r * math.cos(theta)
    depth = ((2 * R - r * math.cos(theta)) * math.cos(theta) - r) / math.sin(theta)
    u = np.array([0.0, math.sin(theta), -math.cos(theta)])
    lead = np.array([0.0, y0, -depth])
    peg = PinBody(lead - L * u, u, r, L)
    bore = HoleBody(np.zeros(3), np.array([0.0, 0.0, 1.0]), R, 0.3, 0.0, True)
    found = {c.kind: c for c in pin_hole_contacts(peg, bore)}
    rim, mouth = found["rim"], found["mouth"]
    x_b = lead + r * np.array([0.0, math.cos(theta), math.sin(theta)])
    assert abs(rim.gap_m) <= 1e-12 and np.allclose(rim.point_pin_world, x_b, atol=1e-12)
    assert np.allclose(-rim.normal_world, [0.0, -1.0, 0.0], atol=1e-12)
    w = np.array([0.0, -R - y0, depth])
    w_perp = w - (w @ u) * u
    assert abs(mouth.gap_m) <= 1e-12
    assert np.allclose(mouth.point_hole_world, [0.0, -R, 0.0], atol=1e-12)
    assert np.allclose(-mouth.normal_world, -w_perp / np.linalg.norm(w_perp), atol=1e-9)
    # the peg's material point: the axis point nearest the edge, r out towards it
    assert np.allclose(mouth.point_pin_world, lead + (w @ u) * u + r * w_perp / np.linalg.norm(w_perp), atol=1e-12)


# -- Whitney: two-point contact wedges iff l < μ h ----------------------------------------------------
def _two_point_set(l_m: float, h_m: float) -> ContactSet:
    """Contacts A (left wall's mouth, normal +y) and B (right wall l below, normal -y), as a bore gives them."""
    A = Contact("A", np.array([0.0, -h_m / 2, 0.0]), np.array([0.0, 1.0, 0.0]), 0.3)
    B = Contact("B", np.array([0.0, h_m / 2, -l_m]), np.array([0.0, -1.0, 0.0]), 0.3)
    return ContactSet((A, B), np.array([0.0, 0.0, 0.04]), np.diag([0.1, 0.1, 0.1, 1e-4, 1e-4, 1e-5]))


@pytest.mark.parametrize("ratio", [0.5, 0.9, 1.1, 2.0])
def test_whitney_wedging_condition(ratio: float) -> None:
    """Two-point contact holds a self-equilibrated pair along AB iff AB lies in both cones: l < μ h (Whitney 1982)."""
    h, mu = 0.02, 0.3
    l_m = ratio * mu * h
    assert bool(can_wedge(_two_point_set(l_m, h))) is (ratio < 1.0)


# -- the diamond pin locates one rotation -------------------------------------------------------------
def _rows(points: list[np.ndarray], normals: list[np.ndarray], c: np.ndarray) -> np.ndarray:
    return np.array([[*n, *np.cross(p - c, n)] for p, n in zip(points, normals, strict=True)])


def test_diamond_pin_locates_the_rotation_about_the_round_pin() -> None:
    """Rests + the round pin leave exactly the turn about P1's axis free; the diamond's land row removes it."""
    fx = fixplan.load(HOUSING)
    c = fx.goal.p_world
    rest_p = [loc.p_world for loc in fx.locators]
    rest_n = [np.array([0.0, 0.0, 1.0])] * 3
    p1 = np.array([-0.04, 0.0, 0.0])
    G = _rows([*rest_p, p1, p1], [*rest_n, np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])], c)
    _, s, vt = np.linalg.svd(G)
    assert s[-1] >= 1e-4 * s[0] and len(s) == 5
    null = vt[-1]  # G is 5 × 6: its one null twist (v, ω) of the centre of mass
    v, w = null[:3], null[3:]
    assert np.allclose(np.cross(w, [0.0, 0.0, 1.0]), 0.0, atol=1e-12)  # a turn about z
    assert np.allclose(v + np.cross(w, p1 - c), 0.0, atol=1e-12)  # P1's axis point stands still
    lands = _rows([np.array([0.04, 0.0, 0.0])], [np.array([0.0, 1.0, 0.0])], c)
    assert np.linalg.matrix_rank(np.vstack([G, lands])) == 6
    # lands along the line of the pins locate nothing new: the loader refuses such a fixture
    text = HOUSING.read_text().replace("land_direction = [0.0, 1.0, 0.0]", "land_direction = [1.0, 0.0, 0.0]")
    with pytest.raises(FixtureError) as exc:
        fixplan.loads(text, source="h.toml")
    assert "pin: the rests and pins leave 1 motion(s) free at the located pose (rank" in str(exc.value)


# -- the format's checks --------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("old", "new", "key", "words"),
    [
        ('diameter = 0.0098\nlength = 0.012\nfriction = 0.2\nchamfer = 0.001\n\n[[pin]]\nname = "P2"',
         'diameter = 0.0102\nlength = 0.012\nfriction = 0.2\nchamfer = 0.001\n\n[[pin]]\nname = "P2"',
         "pin.P1.diameter", "does not fit hole H1"),
        ('hole = "H2"', 'hole = "H9"', "pin.P2.hole", "no hole 'H9' in the part (expected one of: H1, H2)"),
        ("land_width = 0.003", "land_width = 0.011", "pin.P2.land_width", "wider than the pin"),
        ("land_width = 0.003", "land_width = -0.003", "pin.P2.land_width", "expected"),
        ("land_width = 0.003", "land_width = nan", "pin.P2.land_width", "expected"),
        ('position = [-0.0401, 0.0, 0.0]', 'position = [-0.0403, 0.0, 0.0]', "pin.P1.position",
         "cannot reach the pin at the located pose"),
        ('position = [0.04, 0.0, 0.0]', 'position = [0.04, 0.0003, 0.0]', "pin.P2.position",
         "cannot reach the pin at the located pose"),
        ("length = 0.012\nfriction = 0.2\nchamfer = 0.001\n\n[[pin]]", "length = 0.0004\nfriction = 0.2\nchamfer = 0.0001\n\n[[pin]]",
         "pin.P1.position", "does not reach into hole H1"),
    ],
)  # fmt: skip
def test_pin_errors_name_the_key(old: str, new: str, key: str, words: str) -> None:
    text = HOUSING.read_text()
    assert old in text
    with pytest.raises(FixtureError) as exc:
        fixplan.loads(text.replace(old, new, 1), source="h.toml")
    lines = [ln for ln in str(exc.value).splitlines() if f"{key}:" in ln]
    assert lines and words in lines[0], str(exc.value)


def test_cli_validate_names_a_bad_pin_key(tmp_path: Path) -> None:
    """Every command takes pins (map and verify: tests/test_pins_map_verify.py); a bad pin key is one line, exit 2."""
    ok = run_cli("validate", HOUSING)
    assert ok.returncode == 0 and "warning" not in ok.stderr, ok.stderr
    bad = tmp_path / "bad.toml"
    bad.write_text(HOUSING.read_text().replace('hole = "H2"', 'hole = "H9"'))
    proc = run_cli("validate", bad)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert f"{bad}: pin.P2.hole: no hole 'H9'" in proc.stderr
    proc = run_cli("map", bad, "--out", tmp_path / "m.png")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert f"{bad}: pin.P2.hole: no hole 'H9'" in proc.stderr and "not supported" not in proc.stderr


def test_housing_contacts_at_the_located_pose() -> None:
    """Seated toward +x: P1 touches H1's -x wall at its rim (z = 0.011) and mouth edge (z = 0.0005), normal -x."""
    cs = contact_set(fixplan.load(HOUSING), "goal")
    assert cs.names == ["B1", "B2", "B3", "P1", "P1#2"]
    p1 = {c.name: c for c in cs.contacts if c.owner == "P1"}
    assert np.allclose(p1["P1"].point_world, [-0.045, 0.0, 0.011], atol=1e-12)
    assert np.allclose(p1["P1#2"].point_world, [-0.045, 0.0, 0.0005], atol=1e-12)
    for c in p1.values():
        assert np.allclose(c.normal_world, [-1.0, 0.0, 0.0], atol=1e-12) and abs(c.gap_m) <= 1e-12
    named = contact_set(fixplan.load(HOUSING), "goal", names=["P2"])
    # each land on its own: rim and mouth on the +y land, then on the -y land, 0.1 mm of play each
    assert named.names == ["P2", "P2#2", "P2#3", "P2#4"] and {c.owner for c in named.contacts} == {"P2"}
    assert all(abs(c.gap_m - 1e-4) <= 1e-12 for c in named.contacts)
    alpha = math.asin(0.0015 / R_PIN)  # a land's half angle: the normals stay within it of ±y
    ys = [float(c.normal_world[1]) for c in named.contacts]
    assert all(y >= math.cos(alpha) - 1e-9 for y in ys[:2]) and all(y <= -math.cos(alpha) + 1e-9 for y in ys[2:])


# -- the explicit-contact peg-hole problem and its geometric twin ---------------------------------------
SHAFT = PROBLEMS / "shaft-in-bore.toml"


def _to_3d(w: list[float]) -> np.ndarray:
    """peg-hole-mid's plane (x, y) is the shaft's (x, z): (Fx, Fy, M) -> (Fx, 0, Fy, 0, -M, 0)."""
    return np.array([w[0], 0.0, w[1], 0.0, -w[2], 0.0])


def test_peg_hole_mid_and_its_bore_twin_agree() -> None:
    """The same wrenches on peg-hole-mid's explicit contacts and on the bore's computed ones: the same verdict.

    The one difference is the tilt: the mouth edge's normal leans by θ = 2e-3 in the bore, so a
    wrench that normals alone balance in 2D (held) needs a friction of θ N there (jammed).
    """
    flat, twin = fixplan.load(PROBLEMS / "peg-hole-mid.toml"), fixplan.load(SHAFT)
    assert [c.owner for c in contact_set(twin).contacts] == ["B1", "B1"]
    grid = [[fx, fy, m] for fx in (-0.1, 0.0, 0.1) for fy in (-1.0, -0.4, 0.0, 0.3) for m in (-0.01, 0.0, 0.01, 0.02)]
    a = fixplan.classify(flat, np.array(grid))
    b = fixplan.classify(twin, np.array([_to_3d(w) for w in grid]))
    for w, ra, rb in zip(grid, a, b, strict=True):
        if ra.mode == "held":
            assert rb.mode in ("held", "jammed"), (w, ra.mode, rb.mode)
            if rb.mode == "jammed":  # the friction needed is the tilt's share of the normal force
                f = rb.contact_forces
                ratio = max(float(np.linalg.norm(v[1:]) / max(v[0], 1e-300)) for v in f.values() if v[0] > 0.0)
                assert ratio <= 0.3, (w, f)
        elif all(float(np.max(np.abs(v))) == 0.0 for v in ra.contact_forces.values()):
            # a pure lift: in 2D the walls are tangent to it and carry nothing (the peg slides up);
            # the bore's tilted edge opens under it (its normal leans up by θ): the tie broken
            assert rb.mode in (ra.mode, "separates"), (w, ra.mode, rb.mode)
        else:
            assert rb.mode == ra.mode, (w, ra.mode, rb.mode)


# -- Whitney's jamming diagram for the two-point contact, with the real geometry ------------------------
def _balanced_closed_form(fx: float, fy: float, m: float, l_m: float, yc: float, h: float, mu: float) -> bool:
    """Two-point contact A (-h/2, 0) normal +x, B (h/2, -l) normal -x, centre (0, yc); a 2D wrench about it.

    x: Fx + N_A - N_B = 0; y: Fy + T_A + T_B = 0; moment: M + yc N_A - (l + yc) N_B + (h/2)(T_B - T_A) = 0.
    So N_B = N_A + Fx, T_B - T_A = D = (2/h)(l N_A + (l + yc) Fx - M), T_A = -(Fy + D)/2,
    T_B = (D - Fy)/2; balanced iff some N_A >= 0 (N_B >= 0) keeps |T_A| <= mu N_A and
    |T_B| <= mu N_B: four linear inequalities p + q N_A <= 0, an interval of N_A.
    """
    k = 2.0 / h
    d0, d1 = k * ((l_m + yc) * fx - m), k * l_m  # D = d0 + d1 N_A
    rows = [  # p + q N <= 0
        (fy + d0, d1 - 2 * mu),
        (-fy - d0, -d1 - 2 * mu),
        (d0 - fy - 2 * mu * fx, d1 - 2 * mu),
        (fy - d0 - 2 * mu * fx, -d1 - 2 * mu),
        (-fx, -1.0),  # N_B >= 0
        (0.0, -1.0),  # N_A >= 0
    ]
    lo, hi = -math.inf, math.inf
    for p, q in rows:
        if q > 0:
            hi = min(hi, -p / q)
        elif q < 0:
            lo = max(lo, -p / q)
        elif p > 0:
            return False
    return lo <= hi


def _shaft_at(l_m: float, mu: float) -> tuple[fixplan.Fixture, Pose, float]:
    """The shaft of shaft-in-bore.toml cocked to two-point contact at depth ``l_m`` (the tilt from the formula)."""
    from scipy.optimize import brentq

    R, r, L = 0.01001, 0.01, 0.10
    theta = brentq(lambda t: ((2 * R - r * math.cos(t)) * math.cos(t) - r) / math.sin(t) - l_m, 1e-7, 0.5)
    u = np.array([math.sin(theta), 0.0, -math.cos(theta)])
    centre = np.array([R - r * math.cos(theta), 0.0, -l_m]) - 0.5 * L * u
    fx = fixplan.loads(SHAFT.read_text().replace("friction = 0.3", f"friction = {mu}"), source="shaft.toml")
    pose = Pose.from_rpy_deg(list(centre), [0.0, -math.degrees(theta), 0.0])
    return fx, pose, float(centre[2])


@pytest.mark.parametrize("mu", [0.2, 0.5])
@pytest.mark.parametrize("l_m", [0.003, 0.012, 0.03])
def test_whitney_jamming_diagram_with_the_bore(l_m: float, mu: float) -> None:
    """classify on the bore's contacts is balanced exactly where the closed form is, over (direction, M/F).

    Points whose closed-form verdict flips within 5 % of the moment or of the force's direction are
    left out (the real contacts differ from the idealised ones by the tilt, under 1 %).
    """
    fx, pose, yc = _shaft_at(l_m, mu)
    cs = contact_set(fx, pose)
    assert len(cs) == 2 and all(abs(c.gap_m) <= 1e-9 for c in cs.contacts)
    h, r = 0.02002, 0.01
    grid, expect = [], []
    for angle in (-0.3, -0.1, 0.0, 0.1, 0.3):  # the force's direction from straight down [rad]
        for ratio in (-1.0, -0.3, 0.0, 0.3, 0.7, 1.5, 3.0, 6.0):  # M / (F r)
            f = (math.sin(angle), -math.cos(angle))
            m = ratio * r
            verdicts = {
                _balanced_closed_form(f[0] * s, f[1], m * t, l_m, yc, h, mu)
                for s in (0.95, 1.0, 1.05)
                for t in (0.95, 1.0, 1.05)
            } | {
                _balanced_closed_form(math.sin(angle + da), -math.cos(angle + da), m, l_m, yc, h, mu)
                for da in (-0.05, 0.05)
            }
            if len(verdicts) == 1:
                grid.append(_to_3d([f[0], f[1], m]))
                expect.append(verdicts.pop())
    assert len(grid) >= 20
    results = fixplan.classify(fx, np.array(grid), pose=pose)
    got = [res.mode in ("held", "jammed") for res in results]
    assert got == expect, [(list(np.round(g, 4)), e) for g, e, x in zip(grid, expect, got, strict=True) if e != x]
    if l_m < mu * h:  # Whitney's wedging: the two contacts hold any push
        assert all(expect)
        assert bool(can_wedge(cs))
    else:
        assert not bool(can_wedge(cs))


# -- the tip entering the mouth: 45° chamfers ------------------------------------------------------------
CP, CH, L_PIN = 0.001, 0.0005, 0.012  # the pin's tip chamfer, the hole's mouth chamfer, the pin's length
DOWN_AT_45 = np.array([1.0, 0.0, -1.0]) / math.sqrt(2.0)


@pytest.mark.parametrize("offset", [0.0008, 0.0012])
@pytest.mark.parametrize("gap", [-1e-5, 0.0, 2e-5, 1e-4])
def test_mouth_edge_on_the_tip_chamfer(offset: float, gap: float) -> None:
    """A pin e to +x, coming down: the hole's mouth edges meet its tip chamfer on the +x side.

    In the pin's half-plane (t down its axis, ρ from it) the chamfer is the line t + ρ = L - c_p + r
    (free normal (1, 1)/√2); the hole's top edge is at t = z_b (the base's height over the mouth),
    ρ = R + c_h - e; its wall edge at (z_b + c_h, R - e). Both: gap (z_b + R + c_h - e - L + c_p - r)/√2
    (the two 45° faces are parallel), normal (1, 0, -1)/√2.
    """
    z_b = L_PIN - CP + R_PIN - R_HOLE - CH + offset + math.sqrt(2.0) * gap
    pin = PinBody(np.array([offset, 0.0, z_b]), np.array([0.0, 0.0, -1.0]), R_PIN, L_PIN, CP)
    hole = HoleBody(np.zeros(3), np.array([0.0, 0.0, 1.0]), R_HOLE, 0.03, CH, True)
    tips = sorted((c for c in pin_hole_contacts(pin, hole) if c.kind == "tip"), key=lambda c: c.gap_m)
    assert len(tips) >= 2  # the two edges (and the pin's circles on the chamfer's far side, farther)
    for c in tips[:2]:
        assert abs(c.gap_m - gap) <= 1e-12, (c.gap_m, gap)
        # the angle of a least found by golden section is good to √ε (the gap to ε): 1e-7 on the normal
        assert np.allclose(c.normal_world, DOWN_AT_45, atol=1e-7)
        assert c.point_hole_world[0] > R_HOLE - 1e-12 and abs(c.point_hole_world[1]) <= 1e-9  # the +x side
        assert np.allclose(c.point_pin_world + c.gap_m * c.normal_world, c.point_hole_world, atol=1e-15)


@pytest.mark.parametrize("offset", [0.0002, 0.0004])
@pytest.mark.parametrize("gap", [-1e-5, 0.0, 3e-5])
def test_pin_rim_on_the_mouth_chamfer(offset: float, gap: float) -> None:
    """A pin e to +x over a chamfered mouth: its rim's +x point (depth d, ρ = e + r) on the chamfer
    depth + ρ = R + c_h: gap (R + c_h - d - e - r)/√2, normal (from the pin into the part) (1, 0, -1)/√2."""
    depth_rim = R_HOLE + CH - offset - R_PIN - math.sqrt(2.0) * gap
    z_b = L_PIN - CP - depth_rim  # the rim is L - c_p below the base
    pin = PinBody(np.array([offset, 0.0, z_b]), np.array([0.0, 0.0, -1.0]), R_PIN, L_PIN, CP)
    hole = HoleBody(np.zeros(3), np.array([0.0, 0.0, 1.0]), R_HOLE, 0.03, CH, True)
    # the rim's contact (the pin's chamfer, parallel to the hole's, touches the wall edge at the same gap)
    tips = [
        c for c in pin_hole_contacts(pin, hole) if c.kind == "tip" and abs(c.point_pin_world[2] + depth_rim) <= 1e-9
    ]
    assert len(tips) == 1
    best = tips[0]
    assert abs(best.gap_m - gap) <= 1e-12, (best.gap_m, gap)
    assert np.allclose(best.point_pin_world, [offset + R_PIN, 0.0, -depth_rim], atol=1e-9)
    assert np.allclose(best.normal_world, DOWN_AT_45, atol=1e-7)


@pytest.mark.parametrize("offset", [0.0001, 0.0002, 0.0003, 0.00035])
def test_diamond_pin_touches_on_its_lands_only(offset: float) -> None:
    """A diamond pin (lands ±y, width w) e across them (+x), upright: its rim's farthest land point is a
    land's end, (e + w/2, r cos α): gap R - √(r² + e w + e²). A round pin there: R - r - e."""
    w = 0.003
    pin = PinBody(
        np.array([offset, 0.0, 0.01]), np.array([0.0, 0.0, -1.0]), R_PIN, 0.02, 0.0, np.array([0.0, 1.0, 0.0]), w
    )
    rims = [c for c in pin_hole_contacts(pin, _hole()) if c.kind == "rim"]
    assert len(rims) == 2  # one per land
    expected = R_HOLE - math.sqrt(R_PIN**2 + offset * w + offset**2)
    for c in rims:
        assert abs(c.gap_m - expected) <= 1e-12, (c.gap_m, expected)
        assert abs(abs(c.point_pin_world[0] - offset) - w / 2) <= 1e-12  # at a land's end
    assert expected > R_HOLE - R_PIN - offset  # the relief: more room than a round pin has


# -- wedging named by classify, with the bore's real geometry ------------------------------------------------
@pytest.mark.parametrize("scale", [0.95, 1.05])
def test_classify_names_the_bore_wedged_past_whitneys_friction(tmp_path: Path, scale: float) -> None:
    """Two-point contact in the bore: the rim at the +x wall l = 9.98 mm down, the mouth's edge at −x.

    The contacts wedge iff the line joining them lies in both friction cones: its angle from the
    wall's normal is atan(l / 2R) (2R = 20.02 mm), from the mouth edge's normal (tilted by θ = 2e-3
    toward it) that plus θ; so μ* = tan(atan(l / 2R) + θ). Below it classify names no wedging,
    above it it says the part is wedged (JSON ``wedging.wedges``).
    """
    import json

    cs = contact_set(fixplan.load(SHAFT))
    (a, b) = (c.point_world for c in cs.contacts)
    l_m, span_m = abs(a[2] - b[2]), abs(a[0] - b[0])
    mu_star = math.tan(math.atan(l_m / span_m) + 2.0e-3)
    mu = scale * mu_star
    path = tmp_path / "wedge.toml"
    path.write_text(SHAFT.read_text().replace("friction = 0.3", f"friction = {mu!r}"))
    proc = run_cli("classify", path, "--wrench", "0,0,-1,0,0,0", "--json")
    assert proc.returncode == 0, proc.stderr
    wedging = json.loads(proc.stdout)["wedging"]
    assert wedging["contacts"] == ["B1", "B1#2"]
    assert wedging["wedges"] is (scale > 1.0)
    text = run_cli("classify", path, "--wrench", "0,0,-1,0,0,0").stdout
    assert ("wedged: B1, B1#2" in text) is (scale > 1.0)
