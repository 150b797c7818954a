"""Generated fixture families: seeded random fixtures, so the planner is judged on cases it was not tuned on.

A family draws every number of a fixture file (sizes, mass, the locator layout, tip radii,
friction, soft fingers, the start pose, the hand's limits) from
``numpy.random.default_rng([seed, index])``: fixture ``index`` of a seed is the same text
whatever ``count`` is asked for.

The located (goal) pose is simple, the part in the corner of the world axes and unrotated, so
the locators are placed exactly on the faces there and the file states the goal. The start pose
is then built exactly: resting on the base locators with zero gap, clear of the others. Every
draw is loaded with :func:`fixplan.fixture.loads` and checked with the gap functions of
:mod:`fixplan.locating` (no penetration, the resting locators touch, the others are clear,
rank-full ``G`` at the goal, the goal found again from the start); a draw that fails a check is
replaced by the next draw from the same generator, so no invalid file is produced. The header
comment of each file records the family, seed, index, draw and the drawn parameters.

Families (ranges below are module constants)
---------------------------------------------
box-321
    A box, edges log-uniform in 4–40 cm, of a solid's density (500–8000 kg/m³). Locators
    B1, B2, B3 under the -z face, their triangle containing the centre of mass with a margin at
    the goal and at the start; S1, S2 on the -y face; E1 on the -x face. Start: slid by
    ``(dx, dy)`` (2–30 mm each, at most a quarter of the box along that axis) away from S and E
    and turned by a yaw of ±(0–10)° about z, resting flat on B1, B2, B3.
plate-2d
    A rectangle, trapezoid or pentagon (side edges slanted −30° to 40° from vertical), width
    and height log-uniform in 4–40 cm, a plate 5–30 mm thick. Locators B1, B2 under the bottom
    edge (gravity −y) on either side of the centre of mass, S on the left edge (slanted on
    trapezoids and pentagons). Start: slid 2–30 mm (at most a quarter of the width) along the
    bottom, away from S, and tilted 0–10° about ONE base locator it rests on: counter-clockwise
    on B1 (B2 below with a gap) or clockwise on B2 (B1 below with a gap).
box-321-free
    A box, footprint edges log-uniform in 4–40 cm and the height ``HEIGHT_PER_FOOTPRINT`` (0.25–4)
    × √(a b) (flat to tall). B1, B2, B3 under -z as box-321 (no start offset), S1, S2 on the -y
    or the +y face and E1 on the -x or the +x face (the layout mirrored, drawn per fixture),
    point tips for a quarter of the fixtures, μ in ``FREE_FRICTION``. Start in free space:
    tilted by roll, pitch, yaw each uniform in ±``FREE_TILT_DEG`` about the centre of mass and
    moved along a random direction up and away from S and E (each direction cosine ≥
    ``AWAY_MIN_COSINE``) until the nearest locator's gap is the drawn 5–80 mm (log-uniform,
    ``START_GAP_M``); nothing touches. The goal is written in the file for half the fixtures.
plate-2d-free
    The plate-2d outlines, B1 and B2 on either side of the centre of mass, S on the left or the
    right edge (the outline mirrored); start turned ±15° about the centre of mass and moved up
    and away from S until the nearest locator is 5–80 mm away; goal written for half. The hand
    must hold the part there: ``max_torque`` ≥ ``HOLD_MARGIN`` × the weight's moment about the
    body origin (a polygon's origin is a corner; draws that cannot are redrawn).

mesh-321
    A CAD-like mesh part (``MESH_PARTS``: an L-bracket, a slotted block or a housing with a pocket,
    a third each), whole-millimetre dimensions log-uniform in ``MESH_EXTENT_MM``, walls in
    ``MESH_WALL_MM``, built by :mod:`fixplan.geometry.cells` and written as a binary STL in mm
    beside the fixture (:attr:`GeneratedFixture.files`). B1, B2, B3 under the flat bottom, S1, S2
    on the -y face, E1 on the face inside the concave region (the L's inner wall, a slot wall, the
    pocket's inner wall; its outward normal +x): its centre is inside the convex hull, so the hull
    would be wrong there. Goal: the file's frame, written in half the files (the loader finds it
    on the real surface in the others). Start: slid off S (+y) and E1 (-x, within the slot or
    pocket) and turned ±``MESH_TILT_DEG`` about z through the centre of mass, resting on B1, B2,
    B3. Checked as box-321 (the goal found again from the start), and each locator touches one
    face at the goal.

plane-2-pins
    A box on 3 rests B1, B2, B3 under -z, located by a round pin P1 and a diamond pin P2 in two
    through holes of its bottom (``PIN_*``); goal written, seated toward P1's contact; start above
    the pins, each hole within ``PIN_CAPTURE_CHECK`` of the capture of its pin.
plane-2-pins-mesh
    plane-2-pins' draws, seed for seed, with the box written as a mesh part (binary STL in mm,
    body frame at the box's centre) whose bores are modelled: a square through channel around
    each hole (half side: the chamfered mouth's radius, up to the next 0.1 mm). The holes stay
    analytic ``[[workpiece.hole]]``s, so the pins' contacts are the closed forms', as for the box.
plane-pin-stop
    A plate on 3 rests under -z (mirrored in x in half), located by one round pin P1 in a through
    hole drawn anywhere and a stop S1 on a drawn side face that takes the turn about the pin
    (``STOP_*``; a point or a spherical tip); goal written, seated toward P1's contact. Start above
    the pin's tip and the stop's top (``PIN_STOP_RISE_M``), off by up to ``PIN_STOP_OFFSET_M`` and
    tilted by roll, pitch, yaw each uniform in ±``PIN_STOP_TILT_DEG``: the approach must bring
    the hole over the pin and the seating must press the stop.
shaft-bore
    A shaft (``shape = "cylinder"``, radius log-uniform in ``SHAFT_RADIUS_M``, length
    ``SHAFT_LENGTH_PER_DIAMETER`` × its diameter, of a solid's density) loaded into a blind
    ``[[bore]]`` B1 at the origin, its axis +z (radial play ``BORE_PLAY_M``, log-uniform; a 45°
    mouth chamfer in ``BORE_CHAMFER_M``, none in ``BORE_SHARP_SHARE`` of them; depth
    ``BORE_DEPTH_FRACTION`` of the shaft's length). No goal in the file: the loader derives the
    located pose (coaxial, the leading end on the bottom). Start above the bore: tilted by roll and
    pitch each uniform in ±``SHAFT_START_TILT_DEG``, any yaw, its leading end's centre within
    ``SHAFT_START_OFFSET_M`` of the bore's axis and its lowest point ``SHAFT_START_RISE_M`` above
    the mouth's plane; nothing touches. ``--rotate-world`` tilts the bore's axis with the world.

The free families are checked on their goal known by construction (every gap 0 within
``EXACT_M``, rank-full ``G``), never by searching for it. ``rotate_world=True`` (``fixplan generate
--rotate-world``) turns any family's fixture rigidly by :func:`fixplan.twins.random_rotation`.
"""

from __future__ import annotations

import math
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fixplan import twins
from fixplan.errors import FixtureError, InfeasibleError, InputError
from fixplan.files import write_output
from fixplan.fixture import loads, parse_toml
from fixplan.geometry import Box, Cylinder, Polygon, Rectangle
from fixplan.geometry.cells import (
    cell_mass_properties,
    cell_surface,
    housing_cells,
    l_bracket_cells,
    slotted_block_cells,
)
from fixplan.geometry.collision import collision_points
from fixplan.geometry.mesh import stl_bytes
from fixplan.locating import contact_set, locator_gaps, solve_goal
from fixplan.model import Fixture, Locator, Workpiece
from fixplan.settings import DEFAULT
from fixplan.spatial import Pose, cross2, matrix_from_rpy, rot2, rpy_from_matrix

FAMILIES: dict[str, str] = {
    "box-321": (
        "3D boxes (edges 4-40 cm) on 3 base, 2 side and 1 end locator; start slid 2-30 mm off the side "
        "and end locators and turned up to 10 deg about z, resting on the base"
    ),
    "plate-2d": (
        "2D rectangles, trapezoids and pentagons on 2 base locators and 1 side locator (often on a slanted "
        "edge); start slid 2-30 mm along the bottom and tilted up to 10 deg, resting on one base locator"
    ),
    "box-321-free": (
        "3D flat to tall boxes on 3 base, 2 side (+y or -y face) and 1 end (+x or -x face) locator, point or "
        "spherical tips, mu 0.05-0.8; start in free space 5-80 mm from the nearest locator, moved up and away "
        "from the side and end locators and tilted up to 15 deg about every axis; goal written in half the files"
    ),
    "plate-2d-free": (
        "2D rectangles, trapezoids and pentagons on 2 base locators and 1 side locator (left or right edge), "
        "mu 0.05-0.8; start in free space 5-80 mm from the nearest locator, moved up and away from the side "
        "locator and tilted up to 15 deg; goal written in half the rectangles and every polygon"
    ),
}

# Families whose fixtures come with a mesh file (GeneratedFixture.files): listed apart, since a
# fixture of theirs loads only beside its mesh file.
MESH_FAMILIES: dict[str, str] = {
    "mesh-321": (
        "3D CAD-like mesh parts (binary STL in mm, whole-mm dimensions): L-brackets, slotted blocks and "
        "housings with a pocket, 30-200 mm, on 3 base, 2 side and 1 end locator, the end locator inside the "
        "concave region (the L's inner wall, a slot wall, the pocket's inner wall); start slid 2-30 mm off the "
        "side and end locators and turned up to 5 deg about z around the centre of mass, resting on the base; "
        "goal written in half the files (the loader computes it on the real surface in the others)"
    ),
}
# Families with pins and holes (a plane and two pins): listed apart, since only the commands that take
# pins take them (map and verify do not model pins yet).
PIN_FAMILIES: dict[str, str] = {
    "plane-2-pins": (
        "3D boxes (edges 6-30 cm by 4-20 cm, 2-6 cm thick) on 3 rests under -z and two bored through holes "
        "(D 6-16 mm, mouth chamfers 0-2 mm) on a round pin and a diamond pin (radial play 0.02-0.2 mm, tip "
        "chamfers 0-2 mm, each pin 0.4-0.9 x the thickness long, lands across the line between the pins); goal written (seated toward the round pin's "
        "contact); start above the pins, tilted up to 0.5 deg about each axis, each hole within 80 % of the capture "
        "(play + chamfers) of its pin"
    ),
    "plane-2-pins-mesh": (
        "plane-2-pins' fixtures (the same draws, seed for seed) with the box written as a mesh part: a binary STL "
        "in mm beside the fixture, each hole's bore modelled as a square through channel around it (side: the "
        "chamfered mouth's diameter); the holes stay analytic [[workpiece.hole]]s"
    ),
    "plane-pin-stop": (
        "3D plates (edges 6-30 cm by 4-20 cm, 2-6 cm thick) on 3 rests under -z (mirrored in x in half), one bored "
        "through hole (D 6-16 mm, mouth chamfer 0-2 mm) anywhere on a round pin (radial play 0.02-0.2 mm, tip "
        "chamfer 0-2 mm, 0.4-0.9 x the thickness long) and a stop on a drawn side face taking the turn about the "
        "pin (a point or a 0.5-4 mm tip, 25-75 % up the face); goal written (seated along a drawn heading against "
        "the pin); start above the pin's tip and the stop, off by up to 5 mm and tilted up to 10 deg about every axis"
    ),
    "shaft-bore": (
        "3D shafts (diameter 8-50 mm, 1.5-6 diameters long) into a blind bore (radial play 0.01-0.1 mm, mouth chamfer "
        "0-2 mm, sharp in a quarter of them, 0.3-0.7 of the shaft deep); no goal in the file (the loader derives it: "
        "coaxial, on the bottom); start above the bore, tilted up to 10 deg about each horizontal axis, its leading "
        "end within 5 mm of the bore's axis, its lowest point 2-20 mm above the mouth"
    ),
}
ALL_FAMILIES: dict[str, str] = {**FAMILIES, **MESH_FAMILIES, **PIN_FAMILIES}
# The families whose fixtures come with a mesh file written beside them (GeneratedFixture.files).
MESH_FILE_FAMILIES: tuple[str, ...] = (*MESH_FAMILIES, "plane-2-pins-mesh")

# What the families draw from (the README lists them; tests/test_generate.py checks them).
EDGE_M = (0.04, 0.40)  # box edges, plate width and height [m], log-uniform
DENSITY_KG_M3 = (500.0, 8000.0)  # wood to steel, log-uniform
PLATE_THICKNESS_M = (0.005, 0.030)  # plate-2d: mass = area × thickness × density
TIP_RADIUS_M = (0.0, 0.006)
FRICTION = (0.1, 0.6)  # per fixture; half the fixtures vary it per locator by ±FRICTION_SPREAD
FRICTION_SPREAD = 0.05
TORSION_M = (0.0005, 0.003)  # box-321: soft-finger torsional radius, half the fixtures
OFFSET_M = (0.002, 0.030)  # start offset, and at most OFFSET_MAX_FRACTION of the part along it
OFFSET_MAX_FRACTION = 0.25
TILT_DEG = (0.0, 10.0)  # magnitude of the start tilt
SLANT_DEG = (-30.0, 40.0)  # plate-2d side edges from vertical, positive leaning inwards
FORCE_PER_WEIGHT = (1.5, 8.0)  # manipulator.max_force / (m g)
TORQUE_PER_WEIGHT_LEVER = (0.3, 3.0)  # manipulator.max_torque / (m g × half the bounding-box diagonal)
GRAVITY_M_S2 = 9.81

# The free families (box-321-free, plate-2d-free) draw the above where they do not say otherwise, and:
HEIGHT_PER_FOOTPRINT = (0.25, 4.0)  # box-321-free: c / sqrt(a b), log-uniform (flat to tall); c in EDGE_M
POINT_TIP_SHARE = 0.25  # share of free fixtures with point tips (radius 0); the others draw TIP_RADIUS_M
FREE_FRICTION = (0.05, 0.8)  # per fixture, half varied per locator by ±FRICTION_SPREAD
FREE_FORCE_PER_WEIGHT = (1.5, 6.0)  # manipulator.max_force / (m g); torque as TORQUE_PER_WEIGHT_LEVER
START_GAP_M = (0.005, 0.080)  # the nearest locator's gap at the start, log-uniform; every gap is ≥ the lower end
FREE_TILT_DEG = 15.0  # start tilt: roll, pitch, yaw (2D: the angle) each uniform in ±this
AWAY_MIN_COSINE = 0.2  # the start displacement's direction cosine away from each locator group, at least
GOAL_WRITTEN_SHARE = 0.5  # share of free fixtures whose file states the goal (the others: the loader finds it)
HOLD_MARGIN = 1.5  # free starts: max_torque ≥ this × the torque that holds the part still there (about the body origin)
WORLD_STREAM = 1  # --rotate-world draws the rotation from default_rng([seed, index, WORLD_STREAM])
MESH_PARTS = ("l-bracket", "slotted-block", "housing")  # mesh-321: one drawn per fixture, uniformly
MESH_EXTENT_MM = (30, 200)  # mesh-321: outer dimensions, whole millimetres, log-uniform
MESH_WALL_MM = (5, 20)  # mesh-321: the L's thickness, the housing's wall, whole millimetres
MESH_TILT_DEG = (0.0, 5.0)  # mesh-321: start yaw magnitude about z through the centre of mass
MESH_EDGE_MARGIN = 0.08  # mesh-321: locators this fraction of a face's extent in from its edges
MESH_KIND_ATTEMPTS = 50  # mesh-321: draws of one part kind before the kind is drawn again
FLOOR_BELOW_M = 0.01  # --floor: a collision-only floor this far below the part's lowest point at start and goal

PIN_PART_EDGE_M = ((0.06, 0.30), (0.04, 0.20), (0.02, 0.06))  # plane-2-pins: box a, b, c [m], log-uniform
PIN_HOLE_D_M = (0.006, 0.016)  # plane-2-pins: hole diameter D [m]
PIN_PLAY_M = (2e-5, 2e-4)  # plane-2-pins: radial play (D - d) / 2 [m], log-uniform
PIN_CHAMFER_M = (0.0, 0.002)  # plane-2-pins: hole mouth and pin tip chamfers [m] (a pin's at most 40 % of its radius)
PIN_LENGTH_FRACTION = (0.4, 0.9)  # plane-2-pins: pin length / part thickness c
PIN_LAND_FRACTION = (0.2, 0.5)  # plane-2-pins: diamond land width / pin diameter
PIN_SPAN_FRACTION = 0.4  # plane-2-pins: the holes at least this fraction of a apart along x
PIN_START_RISE_M = (0.002, 0.020)  # plane-2-pins: the holes' mouths this far above the pins' tips at the start
PIN_START_TILT_DEG = 0.5  # plane-2-pins: start roll, pitch, yaw each uniform in ±this
PIN_CAPTURE_SHARE = 0.5  # plane-2-pins: start offset at most this share of the capture (play + both chamfers)
PIN_CAPTURE_CHECK = 0.8  # plane-2-pins: each hole's axis within this share of the capture of its pin's at the start
SHAFT_RADIUS_M = (0.004, 0.025)  # shaft-bore: the shaft's radius [m], log-uniform
SHAFT_LENGTH_PER_DIAMETER = (1.5, 6.0)  # shaft-bore: its length / its diameter, log-uniform
BORE_PLAY_M = (1e-5, 1e-4)  # shaft-bore: radial play (D - d) / 2 [m], log-uniform
BORE_CHAMFER_M = (0.0, 0.002)  # shaft-bore: the mouth's 45° chamfer [m], uniform
BORE_SHARP_SHARE = 0.25  # shaft-bore: share of bores without a chamfer (the play alone captures)
BORE_DEPTH_FRACTION = (0.3, 0.7)  # shaft-bore: the bore's depth / the shaft's length
SHAFT_START_TILT_DEG = 10.0  # shaft-bore: start roll and pitch each uniform in ±this (yaw: any)
SHAFT_START_OFFSET_M = 0.005  # shaft-bore: the leading end's centre within this of the bore's axis at the start
SHAFT_START_RISE_M = (0.002, 0.020)  # shaft-bore: the shaft's lowest point this far above the mouth's plane
STOP_HEIGHT_FRACTION = (0.25, 0.75)  # plane-pin-stop: the stop's contact height / the part's thickness
STOP_LEVER_FRACTION = 0.25  # plane-pin-stop: the stop at least this share of its face's length from the pin along it
STOP_EDGE_FRACTION = 0.08  # plane-pin-stop: the stop at least this share of its face's length in from its ends
STOP_TIP_RADIUS_M = (0.0005, 0.004)  # plane-pin-stop: a spherical stop tip (half the fixtures; the others a point)
PIN_STOP_TILT_DEG = 10.0  # plane-pin-stop: start roll, pitch, yaw each uniform in ±this (about the part's centre)
PIN_STOP_OFFSET_M = 0.005  # plane-pin-stop: start offset along x and y each uniform in ±this
PIN_STOP_RISE_M = (
    0.002,
    0.030,
)  # plane-pin-stop: the part's lowest point this far above the pin's tip and the stop's top

# Checks every generated file passes.
EXACT_M = 1e-9  # resting locators touch within this at the start; nothing penetrates more
CLEARANCE_M = 1e-5  # the other locators are at least this far at the start (10 × the touch tolerance)
MAX_DRAWS = 1000


@dataclass(frozen=True)
class GeneratedFixture:
    """One generated fixture file.

    Attributes
    ----------
    name : str
        ``FAMILY-sSEED-INDEX`` (index zero-padded to 3 digits); also ``scene.name`` and the file stem.
    family, seed, index
        What it was generated from: ``numpy.random.default_rng([seed, index])``.
    params : dict
        The drawn parameters (JSON-ready: numbers, strings, booleans and lists).
    toml_text : str
        The fixture file, a header comment and the TOML.
    draws : int
        Draws it took: the earlier ``draws - 1`` failed a check and were replaced.
    goal : dict
        The goal pose as the file would state it (``position`` and ``rpy_deg`` or ``angle_deg``),
        known by construction, also when the file leaves it out (free families).
    files : tuple of (str, bytes)
        Files the fixture names, to be written beside it: ``(name, bytes)`` (a mesh family's
        mesh file, ``FAMILY-sSEED-NNN.stl``); empty for the other families.
    """

    name: str
    family: str
    seed: int
    index: int
    params: dict[str, Any]
    toml_text: str
    draws: int
    goal: dict[str, Any] | None = None  # the located pose, known by construction, in the file's form
    files: tuple[tuple[str, bytes], ...] = ()  # files the fixture names, written beside it


def fixture_name(family: str, seed: int, index: int, *, rotate_world: bool = False) -> str:
    """The name (and file stem) of fixture ``index`` of ``seed`` in ``family`` (``-rotated``: in a rotated world)."""
    return f"{family}-s{seed}-{index:03d}" + ("-rotated" if rotate_world else "")


def check_family(family: str) -> None:
    """Raise :class:`InputError` naming the known families when ``family`` is not one."""
    if family not in ALL_FAMILIES:
        raise InputError(f"unknown fixture family {family!r} (known: {', '.join(ALL_FAMILIES)})")


def generate(
    family: str, count: int, seed: int, *, rotate_world: bool = False, floor: bool = False
) -> list[GeneratedFixture]:
    """Fixtures ``0 .. count-1`` of ``family`` for ``seed`` (see the module docstring).

    ``rotate_world``: each fixture in a world turned by a random rotation (:func:`generate_one`).
    ``floor``: each with a collision-only floor under it (:func:`generate_one`).
    """
    check_family(family)
    _check_int(count, "count")
    return [generate_one(family, seed, index, rotate_world=rotate_world, floor=floor) for index in range(count)]


def generate_one(
    family: str, seed: int, index: int, *, rotate_world: bool = False, floor: bool = False
) -> GeneratedFixture:
    """Fixture ``index`` of ``family`` for ``seed``: the first draw that passes every check.

    ``rotate_world``: the fixture turned rigidly about the world origin (locators, start, goal,
    gravity) by :func:`fixplan.twins.random_rotation` of ``default_rng([seed, index,
    WORLD_STREAM])``: uniform on SO(3), a uniform angle in 2D. Its name ends in ``-rotated``,
    its params hold ``world_rotation`` (the matrix, by rows), and its gaps at the start and goal
    are checked against the unrotated fixture's. ``floor``: the same draw (same layout, same
    random stream) plus an ``[[obstacle]]`` plane normal to gravity, :data:`FLOOR_BELOW_M` below
    the part's lowest point at its start and goal (collision only: it never locates, so the
    verdicts and plans are those without it unless a push drives the part onto it).
    """
    check_family(family)
    _check_int(seed, "seed")
    _check_int(index, "index")
    name = fixture_name(family, seed, index, rotate_world=rotate_world)
    rng = np.random.default_rng([seed, index])
    with tempfile.TemporaryDirectory(prefix="fixplan-generate-") as folder:
        return _first_valid(family, seed, index, name, rng, Path(folder), rotate_world=rotate_world, floor=floor)


def _first_valid(
    family: str,
    seed: int,
    index: int,
    name: str,
    rng: np.random.Generator,
    folder: Path,
    *,
    rotate_world: bool,
    floor: bool,
) -> GeneratedFixture:
    """The first draw that passes every check (:func:`generate_one`); a draft's files are loaded from ``folder``."""
    reason = ""
    for draw in range(1, MAX_DRAWS + 1):
        draft = _DRAWS[family](rng)
        if isinstance(draft, str):
            reason = draft
            continue
        files = tuple((f"{name}{suffix}", data) for suffix, data in draft.files)
        if files:
            draft.shape["file"] = files[0][0]
        here = folder / f"draw-{draw}"  # each draw's own: a file the loader read is an input, never rewritten
        here.mkdir(exist_ok=True)
        for file_name, data in files:  # beside the text, for the loader's checks

            def write_file(path: Path, data: bytes = data) -> None:
                path.write_bytes(data)

            write_output(here / file_name, write_file)
        body = _render(name, draft, goal=not draft.bores)  # a bore's located pose is the loader's
        try:
            fixture = loads(body, source=name, base_dir=here)
        except FixtureError as exc:
            reason = f"the loader refused it: {exc.issues[0].key}: {exc.issues[0].message}"
            continue
        if draft.pins:
            problem = _check_pins(fixture, draft) if len(draft.pins) > 1 else _check_pin_stop(fixture)
        elif draft.bores:
            problem = _check_bore(fixture, draft)
        else:
            problem = _check_free(fixture, draft) if draft.free else _check(fixture, draft)
        if problem is not None:
            reason = problem
            continue
        params = dict(draft.params)
        goal = _derived_goal(fixture) if draft.bores else dict(draft.goal)
        head = _header(name, family, seed, index, draw, draft, fixture, rotate_world)
        extra = _floor_block(fixture) if floor else ""
        body += extra
        if not rotate_world:
            text = head + (body if draft.goal_written else _render(name, draft, goal=False) + extra)
            return GeneratedFixture(name, family, seed, index, params, text, draw, goal, files)
        R = twins.random_rotation(np.random.default_rng([seed, index, WORLD_STREAM]), draft.dimension)
        doc = twins.rotate_world(parse_toml(body, name), R)
        problem = _check_twin(fixture, doc, name, here, far_pins=draft.far_pins)
        if problem is not None:
            reason = problem
            continue
        if draft.bores:
            goal = _derived_goal(loads(twins.fixture_toml(doc), source=name, base_dir=here))
        else:
            goal = doc["workpiece"]["goal"]
        if not draft.goal_written and "goal" in doc["workpiece"]:
            del doc["workpiece"]["goal"]
        params["world_rotation"] = [[float(v) for v in row] for row in R]
        rows = "; ".join(", ".join(f"{v:.12g}" for v in row) for row in R)
        note = (
            f"World rotated about the origin by R = [{rows}] (default_rng([{seed}, {index}, {WORLD_STREAM}])):\n"
            "the goal, start and layout above are in the unrotated world; this file is that fixture turned by R."
        )
        text = twins.twin_text(head, doc, note)
        return GeneratedFixture(name, family, seed, index, params, text, draw, goal, files)
    raise InfeasibleError(f"{name}: no draw passed the checks in {MAX_DRAWS} draws (last: {reason})")


def _derived_goal(fixture: Fixture) -> dict[str, Any]:
    """The located pose the loader derives for a shaft in its bore, in the file's form."""
    from fixplan.locating import located_pose

    G = located_pose(fixture)
    rpy = np.degrees(rpy_from_matrix(G.R_world_body))
    return {"position": [float(x) for x in G.p_world], "rpy_deg": [float(x) for x in rpy]}


def _check_int(value: Any, what: str) -> None:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 0:
        raise InputError(f"{what} must be an integer ≥ 0, got {value!r}")


# -- drafts: what a family draws, before it is written and checked --------------------------------


@dataclass
class _Draft:
    dimension: int
    shape: dict[str, Any]  # workpiece keys before the mass: shape and size or vertices
    mass_kg: float
    start: dict[str, Any]  # the start pose in the file's form
    goal: dict[str, Any]
    locators: list[dict[str, Any]]  # name, position, radius, friction[, torsion][, face]
    max_force_N: float
    max_torque_Nm: float
    params: dict[str, Any]
    resting: tuple[str, ...]  # locators that touch at the start; the others must be clear
    story: list[str]  # a few lines on the start, for the header
    check: Callable[[Fixture], str | None]  # the family's own geometric check of the loaded file
    free: bool = False  # the start is in free space (START_GAP_M) rather than resting
    goal_written: bool = True  # the file states the goal (free families: GOAL_WRITTEN_SHARE of them)
    files: tuple[tuple[str, bytes], ...] = ()  # (suffix, bytes) of files the fixture names (a mesh)
    holes: tuple[dict[str, Any], ...] = ()  # [[workpiece.hole]] entries (plane-2-pins)
    pins: tuple[dict[str, Any], ...] = ()  # [[pin]] entries (plane-2-pins)
    bores: tuple[dict[str, Any], ...] = ()  # [[bore]] entries (shaft-bore: no goal in the file)
    # the pins start far from their holes and tilted (plane-pin-stop): the closed forms' rim distance there
    # is one of several extremes, picked by the frame, so a rotated twin's is checked clear, not equal
    far_pins: bool = False


def _uniform(rng: np.random.Generator, lo: float, hi: float, decimals: int) -> float:
    return round(float(rng.uniform(lo, hi)), decimals)


def _log_uniform(rng: np.random.Generator, lo: float, hi: float, decimals: int) -> float:
    return round(math.exp(float(rng.uniform(math.log(lo), math.log(hi)))), decimals)


def _offset_cap(length_m: float) -> float:
    """Largest start offset along a part of this length [m], floored to 0.1 mm."""
    return math.floor(min(OFFSET_M[1], OFFSET_MAX_FRACTION * length_m) * 1e4) / 1e4


def _frictions(
    rng: np.random.Generator, n: int, bounds: tuple[float, float] = FRICTION
) -> tuple[float, bool, list[float]]:
    """The fixture's μ, whether it varies per locator, and the n locators' μ."""
    mu = _uniform(rng, *bounds, 3)
    varied = bool(rng.random() < 0.5)
    if not varied:
        return mu, False, [mu] * n
    spread = rng.uniform(-FRICTION_SPREAD, FRICTION_SPREAD, n)
    return mu, True, [round(float(np.clip(mu + s, *bounds)), 3) for s in spread]


def _hand(
    rng: np.random.Generator, weight_N: float, lever_m: float, force: tuple[float, float] = FORCE_PER_WEIGHT
) -> tuple[float, float, float, float]:
    """Force and torque factors and the limits they give, weak to strong relative to the weight."""
    kf = _uniform(rng, *force, 3)
    kt = _uniform(rng, *TORQUE_PER_WEIGHT_LEVER, 3)
    return kf, kt, kf * weight_N, kt * weight_N * lever_m


def _sig(x: float, digits: int) -> float:
    return float(f"{x:.{digits}g}")


# -- box-321 ----------------------------------------------------------------------------------------


def _draw_box(rng: np.random.Generator) -> _Draft | str:
    a, b, c = (_log_uniform(rng, *EDGE_M, 4) for _ in range(3))
    density = round(_log_uniform(rng, *DENSITY_KG_M3, 0))
    mass = _sig(density * a * b * c, 4)
    rho = _uniform(rng, *TIP_RADIUS_M, 4)
    mu, varied, mus = _frictions(rng, 6)
    soft = bool(rng.random() < 0.5)
    torsion = _uniform(rng, *TORSION_M, 4) if soft else 0.0
    dx = _uniform(rng, OFFSET_M[0], _offset_cap(a), 4)
    dy = _uniform(rng, OFFSET_M[0], _offset_cap(b), 4)
    tilt = _uniform(rng, *TILT_DEG, 2)
    yaw = tilt if rng.random() < 0.5 else -tilt

    # At the goal the box fills [0, a] x [0, b] x [0, c]; at the start (before the yaw) it is
    # shifted by (dx, dy). Base locators are drawn in the part of the bottom face under the box at
    # both, 8 % in from its edges, around the midpoint of the two centres of mass: B1 left and
    # B2 right on the near (-y) side, B3 on the far side.
    lo_x, hi_x = dx + 0.08 * a, 0.92 * a
    lo_y, hi_y = dy + 0.08 * b, 0.92 * b

    def base(u: tuple[float, float], v: tuple[float, float]) -> tuple[float, float]:
        x = _uniform(rng, lo_x + (u[0] + 1) / 2 * (hi_x - lo_x), lo_x + (u[1] + 1) / 2 * (hi_x - lo_x), 4)
        y = _uniform(rng, lo_y + (v[0] + 1) / 2 * (hi_y - lo_y), lo_y + (v[1] + 1) / 2 * (hi_y - lo_y), 4)
        return x, y

    def along(lo: float, hi: float, length: float) -> float:
        return _uniform(rng, lo * length, hi * length, 4)

    b1 = base((-1.0, -0.7), (-1.0, -0.6))
    b2 = base((0.7, 1.0), (-1.0, -0.6))
    b3 = base((-0.2, 0.3), (0.6, 1.0))
    s1 = (along(0.1, 0.4, a), along(0.2, 0.8, c))
    s2 = (along(0.6, 0.9, a), along(0.2, 0.8, c))
    e1 = (along(0.2, 0.8, b), along(0.2, 0.8, c))
    tri = np.array([b1, b2, b3])
    need = 0.05 * min(a, b)
    for centre in ((a / 2, b / 2), (a / 2 + dx, b / 2 + dy)):
        if _triangle_margin(np.array(centre), tri) < need:
            return "the base triangle does not hold the centre of mass with a margin"
    weight = mass * GRAVITY_M_S2
    half_diagonal = 0.5 * math.sqrt(a * a + b * b + c * c)
    kf, kt, max_force, max_torque = _hand(rng, weight, half_diagonal)

    spots = {
        "B1": ([b1[0], b1[1], -rho], "-z"),
        "B2": ([b2[0], b2[1], -rho], "-z"),
        "B3": ([b3[0], b3[1], -rho], "-z"),
        "S1": ([s1[0], -rho, s1[1]], "-y"),
        "S2": ([s2[0], -rho, s2[1]], "-y"),
        "E1": ([-rho, e1[0], e1[1]], "-x"),
    }
    locators = []
    for (name, (position, face)), mu_i in zip(spots.items(), mus, strict=True):
        entry: dict[str, Any] = {"name": name, "position": position, "radius": rho, "friction": mu_i}
        if soft:
            entry["torsion"] = torsion
        entry["face"] = face
        locators.append(entry)
    goal_c = [a / 2, b / 2, c / 2]
    start_c = [a / 2 + dx, b / 2 + dy, c / 2]
    params = {
        "size_m": [a, b, c],
        "density_kg_m3": density,
        "mass_kg": mass,
        "tip_radius_m": rho,
        "friction": mu,
        "friction_per_locator": varied,
        "soft_fingers": soft,
        "torsion_m": torsion,
        "offset_m": [dx, dy],
        "yaw_deg": yaw,
        "force_per_weight": kf,
        "torque_per_weight_lever": kt,
    }
    story = [
        f"Goal: the box fills [0, {a:g}] x [0, {b:g}] x [0, {c:g}] m, unrotated; every locator touches a face there.",
        f"Start: slid by ({dx * 1e3:g}, {dy * 1e3:g}) mm off S1, S2 and E1 and turned {yaw:g} deg about z,",
        "resting flat on B1, B2, B3 (gap 0); their triangle holds the centre of mass at the goal and the start.",
    ]
    return _Draft(
        dimension=3,
        shape={"shape": "box", "size": [a, b, c]},
        mass_kg=mass,
        start={"position": start_c, "rpy_deg": [0.0, 0.0, yaw]},
        goal={"position": goal_c, "rpy_deg": [0.0, 0.0, 0.0]},
        locators=locators,
        max_force_N=max_force,
        max_torque_Nm=max_torque,
        params=params,
        resting=("B1", "B2", "B3"),
        story=story,
        check=_check_box,
    )


def _triangle_margin(p: np.ndarray, tri: np.ndarray) -> float:
    """Signed distance from ``p`` to the nearest side of a triangle (positive inside) [m]."""
    area2 = cross2(tri[1] - tri[0], tri[2] - tri[0])
    if abs(area2) <= 1e-15:
        return -math.inf
    sign = 1.0 if area2 > 0 else -1.0
    margins = []
    for i in range(3):
        u, v = tri[i], tri[(i + 1) % 3]
        margins.append(sign * cross2(v - u, p - u) / float(np.linalg.norm(v - u)))
    return min(margins)


def _check_box(fixture: Fixture) -> str | None:
    size = np.asarray(fixture.workpiece.shape.size)  # type: ignore[attr-defined]
    half = size / 2.0
    base = [fixture.locator(n) for n in ("B1", "B2", "B3")]
    for loc in base:
        p_body = fixture.start.point_body_from_world(loc.p_world)
        if np.any(np.abs(p_body[:2]) > half[:2] - 0.05 * size[:2]):
            return f"{loc.name} is not under the bottom face at the start (body point {p_body[:2]})"
    tri = np.array([loc.p_world[:2] for loc in base])
    need = 0.05 * float(min(size[0], size[1]))
    for which, pose in (("goal", fixture.goal), ("start", fixture.start)):
        margin = _triangle_margin(pose.p_world[:2], tri)
        if margin < need:
            return f"the centre of mass is {margin:.3g} m inside the base triangle at the {which} (need {need:.3g} m)"
    return None


# -- plate-2d ---------------------------------------------------------------------------------------


def _turns_ok(vertices: list[tuple[float, float]], min_turn_deg: float = 5.0) -> bool:
    """Counter-clockwise and convex, each vertex turning by at least ``min_turn_deg``."""
    V = np.array(vertices)
    E = np.roll(V, -1, axis=0) - V
    F = np.roll(E, -1, axis=0)
    cross = E[:, 0] * F[:, 1] - E[:, 1] * F[:, 0]
    dot = np.einsum("ij,ij->i", E, F)
    turns = np.degrees(np.arctan2(cross, dot))
    return bool(np.all(turns >= min_turn_deg))


def _plate_outline(
    rng: np.random.Generator,
) -> tuple[str, float, float, list[float], list[tuple[float, float]]] | str:
    """Kind, width, height, side slants and counter-clockwise vertices of a plate (bottom edge (0, 0)-(L, 0))."""
    kind = ("rectangle", "trapezoid", "pentagon")[int(rng.integers(3))]
    L = _log_uniform(rng, *EDGE_M, 4)
    H = _log_uniform(rng, *EDGE_M, 4)
    slants = [0.0, 0.0]
    # Vertices in the plate frame: the bottom edge from (0, 0) to (L, 0), counter-clockwise, the
    # left (side) edge last, from vertices[-1] down to (0, 0).
    if kind == "rectangle":
        vertices = [(0.0, 0.0), (L, 0.0), (L, H), (0.0, H)]
    else:
        slants = [_uniform(rng, *SLANT_DEG, 1), _uniform(rng, *SLANT_DEG, 1)]
        hl, hr = (
            (H, H) if kind == "trapezoid" else (_uniform(rng, 0.3 * H, 0.8 * H, 4), _uniform(rng, 0.3 * H, 0.8 * H, 4))
        )
        d_left = round(hl * math.tan(math.radians(slants[0])), 4)
        d_right = round(hr * math.tan(math.radians(slants[1])), 4)
        if kind == "trapezoid":
            vertices = [(0.0, 0.0), (L, 0.0), (L - d_right, H), (d_left, H)]
        else:
            apex = _uniform(rng, 0.3 * L, 0.7 * L, 4)
            vertices = [(0.0, 0.0), (L, 0.0), (L - d_right, hr), (apex, H), (d_left, hl)]
        if not _turns_ok(vertices):
            return f"the {kind} is not convex with every corner turning at least 5 deg"
    return kind, L, H, slants, vertices


def _draw_plate(rng: np.random.Generator) -> _Draft | str:
    outline = _plate_outline(rng)
    if isinstance(outline, str):
        return outline
    kind, L, H, slants, vertices = outline
    polygon = Polygon(tuple(vertices))
    area = polygon.area
    cx = float(polygon.com_body[0])
    thickness = _uniform(rng, *PLATE_THICKNESS_M, 4)
    density = round(_log_uniform(rng, *DENSITY_KG_M3, 0))
    mass = _sig(area * thickness * density, 4)
    rho = _uniform(rng, *TIP_RADIUS_M, 4)
    mu, varied, mus = _frictions(rng, 3)
    shift = _uniform(rng, OFFSET_M[0], _offset_cap(L), 4)
    # Base locators on either side of the centre of mass, on the part of the bottom edge that
    # stays under the part when it has slid by `shift`.
    lo1, hi1 = max(0.1 * L, 0.05 * L + shift), cx - 0.08 * L
    lo2, hi2 = cx + 0.08 * L, 0.9 * L
    if lo1 >= hi1 or lo2 >= hi2:
        return f"no room for the base locators (centre of mass at x = {cx:.4g} m on a {L:g} m bottom edge)"
    x1 = _uniform(rng, lo1, hi1, 4)
    x2 = _uniform(rng, lo2, hi2, 4)
    t_side = _uniform(rng, 0.25, 0.75, 3)
    pivot = "B1" if rng.random() < 0.5 else "B2"
    tilt = _uniform(rng, *TILT_DEG, 2)
    angle = tilt if pivot == "B1" else -tilt  # B1: right end up; B2: left end up
    xs, ys = vertices[-1]
    side_len = math.hypot(xs, ys)
    n_out = (-ys / side_len, xs / side_len)  # outward normal of the edge vertices[-1] -> (0, 0)
    side = [t_side * xs + rho * n_out[0], t_side * ys + rho * n_out[1]]
    xmin, xmax = min(v[0] for v in vertices), max(v[0] for v in vertices)
    half_diagonal = 0.5 * math.hypot(xmax - xmin, max(v[1] for v in vertices))
    kf, kt, max_force, max_torque = _hand(rng, mass * GRAVITY_M_S2, half_diagonal)

    # The start: the pivot's tip touches the bottom edge at plate-frame (x_pivot - shift, -rho).
    x_pivot = x1 if pivot == "B1" else x2
    R = rot2(math.radians(angle))
    tip = np.array([x_pivot, -rho])
    p_plate = tip - R @ np.array([x_pivot - shift, -rho])
    origin_in_plate = np.array([L / 2, H / 2]) if kind == "rectangle" else np.zeros(2)
    p_start = p_plate + R @ origin_in_plate
    faces = ("-y", "-y", "-x") if kind == "rectangle" else (None, None, None)
    spots = {"B1": [x1, -rho], "B2": [x2, -rho], "S": side}
    locators = []
    for (name, position), mu_i, face in zip(spots.items(), mus, faces, strict=True):
        entry: dict[str, Any] = {"name": name, "position": position, "radius": rho, "friction": mu_i}
        if face is not None:
            entry["face"] = face
        locators.append(entry)
    if kind == "rectangle":
        shape: dict[str, Any] = {"shape": "rectangle", "size": [L, H]}
        goal_p = [L / 2, H / 2]
    else:
        shape = {"shape": "polygon", "vertices": [list(v) for v in vertices]}
        goal_p = [0.0, 0.0]
    other = "B2" if pivot == "B1" else "B1"
    params = {
        "kind": kind,
        "width_m": L,
        "height_m": H,
        "slant_deg": slants,
        "thickness_m": thickness,
        "density_kg_m3": density,
        "mass_kg": mass,
        "tip_radius_m": rho,
        "friction": mu,
        "friction_per_locator": varied,
        "side_fraction": t_side,
        "pivot": pivot,
        "offset_m": shift,
        "tilt_deg": angle,
        "force_per_weight": kf,
        "torque_per_weight_lever": kt,
    }
    turn = "counter-clockwise" if angle >= 0 else "clockwise"
    story = [
        f"Goal: the bottom edge on y = 0 from x = 0 to {L:g} m, unrotated; every locator touches there.",
        f"Start: slid {shift * 1e3:g} mm along the bottom away from S and turned {abs(angle):g} deg {turn},",
        f"resting on {pivot} alone (gap 0) with {other} below the part and S clear.",
    ]
    return _Draft(
        dimension=2,
        shape=shape,
        mass_kg=mass,
        start={"position": [float(x) for x in p_start], "angle_deg": angle},
        goal={"position": goal_p, "angle_deg": 0.0},
        locators=locators,
        max_force_N=max_force,
        max_torque_Nm=max_torque,
        params=params,
        resting=(pivot,),
        story=story,
        check=_check_plate,
    )


def _check_plate(fixture: Fixture) -> str | None:
    com_x = float(fixture.goal.point_world_from_body(fixture.workpiece.com_body)[0])
    x1, x2 = (float(fixture.locator(n).p_world[0]) for n in ("B1", "B2"))
    if not x1 < com_x < x2:
        return f"the centre of mass (x = {com_x:.4g} m) is not between B1 and B2 at the goal"
    return None


# -- free-space starts: box-321-free, plate-2d-free -------------------------------------------------


def _away_direction(rng: np.random.Generator, away: np.ndarray) -> np.ndarray:
    """A unit direction in the cone of ``away`` (±1 per axis): every direction cosine ≥ AWAY_MIN_COSINE."""
    while True:
        e = np.abs(rng.standard_normal(away.shape[0]))
        e /= np.linalg.norm(e)
        if e.min() >= AWAY_MIN_COSINE:
            return away * e


def _tip(rng: np.random.Generator) -> tuple[float, bool]:
    """A tip radius [m]: a point (0) for POINT_TIP_SHARE of the fixtures, else TIP_RADIUS_M."""
    if rng.random() < POINT_TIP_SHARE:
        return 0.0, True
    return _uniform(rng, *TIP_RADIUS_M, 4), False


def _free_offset(
    workpiece: Workpiece, locators: list[Locator], pose_at: Callable[[float], Pose], target_m: float
) -> float | str:
    """The distance ``s`` along the start direction where the nearest locator's gap is ``target_m``.

    ``pose_at(s)`` is the tilted part moved by ``s`` [m] along the direction; the nearest gap is
    continuous in ``s``: bracketed by doubling, then bisected to round-off.
    """

    def nearest(s: float) -> float:
        return float(np.min(locator_gaps(workpiece, pose_at(s), locators)))

    if nearest(0.0) >= target_m:
        return "the tilt alone clears every locator by the target gap"
    hi = 0.01
    while nearest(hi) < target_m:
        hi *= 2.0
        if hi > 4.0:
            return "the part does not clear the locators within 4 m"
    lo = 0.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if mid in (lo, hi):
            break
        lo, hi = (mid, hi) if nearest(mid) < target_m else (lo, mid)
    return hi


def _goal_story(goal: dict[str, Any], written: bool) -> str:
    where = "written in the file" if written else "NOT written in the file (the loader finds it)"
    pose = ", ".join(f"{k} = {_value(v)}" for k, v in goal.items())
    return f"Goal, known by construction and {where}: {pose}."


def _draw_box_free(rng: np.random.Generator) -> _Draft | str:
    a, b = (_log_uniform(rng, *EDGE_M, 4) for _ in range(2))
    aspect = _log_uniform(rng, *HEIGHT_PER_FOOTPRINT, 3)
    c = round(aspect * math.sqrt(a * b), 4)
    if not EDGE_M[0] <= c <= EDGE_M[1]:
        return f"the height {c:g} m (aspect {aspect:g}) is outside {EDGE_M} m"
    density = round(_log_uniform(rng, *DENSITY_KG_M3, 0))
    mass = _sig(density * a * b * c, 4)
    rho, point = _tip(rng)
    mu, varied, mus = _frictions(rng, 6, FREE_FRICTION)
    soft = bool(rng.random() < 0.5)
    torsion = _uniform(rng, *TORSION_M, 4) if soft else 0.0
    side_face = "-y" if rng.random() < 0.5 else "+y"
    end_face = "-x" if rng.random() < 0.5 else "+x"

    # The canonical layout (S on -y, E on -x) of box-321 without a start offset, then mirrored.
    def uni(lo: float, hi: float) -> float:
        return _uniform(rng, lo, hi, 4)

    b1 = (uni(0.08 * a, 0.206 * a), uni(0.08 * b, 0.248 * b))
    b2 = (uni(0.794 * a, 0.92 * a), uni(0.08 * b, 0.248 * b))
    b3 = (uni(0.416 * a, 0.626 * a), uni(0.752 * b, 0.92 * b))
    s1 = (uni(0.1 * a, 0.4 * a), uni(0.2 * c, 0.8 * c))
    s2 = (uni(0.6 * a, 0.9 * a), uni(0.2 * c, 0.8 * c))
    e1 = (uni(0.2 * b, 0.8 * b), uni(0.2 * c, 0.8 * c))
    if _triangle_margin(np.array([a / 2, b / 2]), np.array([b1, b2, b3])) < 0.05 * min(a, b):
        return "the base triangle does not hold the centre of mass with a margin"
    weight = mass * GRAVITY_M_S2
    half_diagonal = 0.5 * math.sqrt(a * a + b * b + c * c)
    kf, kt, max_force, max_torque = _hand(rng, weight, half_diagonal, FREE_FORCE_PER_WEIGHT)
    rpy = [_uniform(rng, -FREE_TILT_DEG, FREE_TILT_DEG, 2) for _ in range(3)]
    sx = 1.0 if end_face == "-x" else -1.0  # away from E
    sy = 1.0 if side_face == "-y" else -1.0  # away from S
    u = _away_direction(rng, np.array([sx, sy, 1.0]))
    target = _log_uniform(rng, *START_GAP_M, 4)

    def fx(x: float) -> float:
        return x if end_face == "-x" else round(a - x, 4)

    def fy(y: float) -> float:
        return y if side_face == "-y" else round(b - y, 4)

    spots = {
        "B1": ([fx(b1[0]), fy(b1[1]), -rho], "-z"),
        "B2": ([fx(b2[0]), fy(b2[1]), -rho], "-z"),
        "B3": ([fx(b3[0]), fy(b3[1]), -rho], "-z"),
        "S1": ([fx(s1[0]), fy(-rho), s1[1]], side_face),
        "S2": ([fx(s2[0]), fy(-rho), s2[1]], side_face),
        "E1": ([fx(-rho), fy(e1[0]), e1[1]], end_face),
    }
    locators = []
    for (name, (position, face)), mu_i in zip(spots.items(), mus, strict=True):
        entry: dict[str, Any] = {"name": name, "position": position, "radius": rho, "friction": mu_i}
        if soft:
            entry["torsion"] = torsion
        entry["face"] = face
        locators.append(entry)
    shape = Box((a, b, c))
    workpiece = Workpiece(shape, mass, shape.inertia_body(mass), shape.com_body)
    models = [Locator(e["name"], np.array(e["position"]), rho, e["friction"]) for e in locators]
    goal_c = np.array([a / 2, b / 2, c / 2])
    R_tilt = matrix_from_rpy(np.radians(rpy))
    s = _free_offset(workpiece, models, lambda s: Pose(R_tilt, goal_c + s * u), target)
    if isinstance(s, str):
        return s
    start_c = [float(v) for v in goal_c + s * u]
    goal = {"position": [float(v) for v in goal_c], "rpy_deg": [0.0, 0.0, 0.0]}
    written = bool(rng.random() < GOAL_WRITTEN_SHARE)
    params = {
        "size_m": [a, b, c],
        "height_per_footprint": aspect,
        "density_kg_m3": density,
        "mass_kg": mass,
        "tip_radius_m": rho,
        "point_tips": point,
        "friction": mu,
        "friction_per_locator": varied,
        "soft_fingers": soft,
        "torsion_m": torsion,
        "side_face": side_face,
        "end_face": end_face,
        "start_rpy_deg": rpy,
        "start_direction": [round(float(v), 6) for v in u],
        "start_distance_m": round(s, 9),
        "nearest_gap_m": target,
        "goal_in_file": written,
        "force_per_weight": kf,
        "torque_per_weight_lever": kt,
    }
    story = [
        f"Goal: the box fills [0, {a:g}] x [0, {b:g}] x [0, {c:g}] m, unrotated; every locator touches a face there",
        f"(S1, S2 on the {side_face} face, E1 on the {end_face} face).",
        _goal_story(goal, written),
        f"Start: in free space, tilted by rpy {rpy} deg about the centre of mass and moved {s * 1e3:.3f} mm along",
        f"{[round(float(v), 4) for v in u]} (up, away from S and E), where the nearest locator is {target * 1e3:g} mm away.",
    ]
    return _Draft(
        dimension=3,
        shape={"shape": "box", "size": [a, b, c]},
        mass_kg=mass,
        start={"position": start_c, "rpy_deg": rpy},
        goal=goal,
        locators=locators,
        max_force_N=max_force,
        max_torque_Nm=max_torque,
        params=params,
        resting=(),
        story=story,
        check=_check_box_free,
        free=True,
        goal_written=written,
    )


def _check_box_free(fixture: Fixture) -> str | None:
    size = np.asarray(fixture.workpiece.shape.size)  # type: ignore[attr-defined]
    base = [fixture.locator(n) for n in ("B1", "B2", "B3")]
    tri = np.array([loc.p_world[:2] for loc in base])
    need = 0.05 * float(min(size[0], size[1]))
    margin = _triangle_margin(fixture.goal.p_world[:2], tri)
    if margin < need:
        return f"the centre of mass is {margin:.3g} m inside the base triangle at the goal (need {need:.3g} m)"
    return None


def _draw_plate_free(rng: np.random.Generator) -> _Draft | str:
    outline = _plate_outline(rng)
    if isinstance(outline, str):
        return outline
    kind, L, H, slants, vertices = outline
    polygon = Polygon(tuple(vertices))
    area = polygon.area
    cx = float(polygon.com_body[0])
    thickness = _uniform(rng, *PLATE_THICKNESS_M, 4)
    density = round(_log_uniform(rng, *DENSITY_KG_M3, 0))
    mass = _sig(area * thickness * density, 4)
    rho, point = _tip(rng)
    mu, varied, mus = _frictions(rng, 3, FREE_FRICTION)
    lo1, hi1 = 0.1 * L, cx - 0.08 * L
    lo2, hi2 = cx + 0.08 * L, 0.9 * L
    if lo1 >= hi1 or lo2 >= hi2:
        return f"no room for the base locators (centre of mass at x = {cx:.4g} m on a {L:g} m bottom edge)"
    x1 = _uniform(rng, lo1, hi1, 4)
    x2 = _uniform(rng, lo2, hi2, 4)
    t_side = _uniform(rng, 0.25, 0.75, 3)
    side_edge = "left" if rng.random() < 0.5 else "right"
    xs, ys = vertices[-1]
    side_len = math.hypot(xs, ys)
    n_out = (-ys / side_len, xs / side_len)  # outward normal of the edge vertices[-1] -> (0, 0)
    side = [t_side * xs + rho * n_out[0], t_side * ys + rho * n_out[1]]
    xmin, xmax = min(v[0] for v in vertices), max(v[0] for v in vertices)
    half_diagonal = 0.5 * math.hypot(xmax - xmin, max(v[1] for v in vertices))
    kf, kt, max_force, max_torque = _hand(rng, mass * GRAVITY_M_S2, half_diagonal, FREE_FORCE_PER_WEIGHT)
    angle = _uniform(rng, -FREE_TILT_DEG, FREE_TILT_DEG, 2)
    u = _away_direction(rng, np.array([1.0 if side_edge == "left" else -1.0, 1.0]))
    target = _log_uniform(rng, *START_GAP_M, 4)
    # a polygon's edges have no names a locator's `face` could give: without its goal a file may
    # have another located pose (a trapezoid resting its slanted edge on B1 and S closes every gap
    # at full rank), so polygons always state it; rectangles in GOAL_WRITTEN_SHARE of the files
    written = bool(rng.random() < GOAL_WRITTEN_SHARE) or kind != "rectangle"

    # Mirrored (S on the right edge): x -> L - x for the outline (order reversed: counter-clockwise) and locators.
    def fx(x: float) -> float:
        return x if side_edge == "left" else round(L - x, 12)

    if side_edge == "right":
        flipped = [(fx(x), y) for x, y in vertices]
        vertices = [flipped[0], *reversed(flipped[1:])]
        polygon = Polygon(tuple(vertices))
    spots = {"B1": [fx(x1), -rho], "B2": [fx(x2), -rho], "S": [fx(side[0]), side[1]]}
    faces = ("-y", "-y", "-x" if side_edge == "left" else "+x") if kind == "rectangle" else (None, None, None)
    locators = []
    for (name, position), mu_i, face in zip(spots.items(), mus, faces, strict=True):
        entry: dict[str, Any] = {"name": name, "position": position, "radius": rho, "friction": mu_i}
        if face is not None:
            entry["face"] = face
        locators.append(entry)
    if kind == "rectangle":
        shape: dict[str, Any] = {"shape": "rectangle", "size": [L, H]}
        model_shape: Rectangle | Polygon = Rectangle((L, H))
        goal_p = np.array([L / 2, H / 2])
    else:
        shape = {"shape": "polygon", "vertices": [list(v) for v in vertices]}
        model_shape = polygon
        goal_p = np.zeros(2)
    com_body = model_shape.com_body
    workpiece = Workpiece(model_shape, mass, model_shape.inertia_body(mass), com_body)
    models = [Locator(e["name"], np.array(e["position"]), rho, e["friction"]) for e in locators]
    R_tilt = rot2(math.radians(angle))
    com_goal = goal_p + com_body

    def pose_at(s: float) -> Pose:
        return Pose(R_tilt, com_goal + s * u - R_tilt @ com_body)

    s = _free_offset(workpiece, models, pose_at, target)
    if isinstance(s, str):
        return s
    # The hand holds the part at the start (nothing else does): the weight's moment about the body
    # origin, where the hand's torque is measured, is within its limit with HOLD_MARGIN.
    hold = mass * GRAVITY_M_S2 * abs(float((R_tilt @ com_body)[0]))
    if max_torque < HOLD_MARGIN * hold:
        return f"the hand cannot hold the part at the start ({max_torque:.3g} N m < {HOLD_MARGIN} x {hold:.3g} N m)"
    goal = {"position": [float(v) for v in goal_p], "angle_deg": 0.0}
    params = {
        "kind": kind,
        "width_m": L,
        "height_m": H,
        "slant_deg": slants,
        "thickness_m": thickness,
        "density_kg_m3": density,
        "mass_kg": mass,
        "tip_radius_m": rho,
        "point_tips": point,
        "friction": mu,
        "friction_per_locator": varied,
        "side_fraction": t_side,
        "side_edge": side_edge,
        "start_angle_deg": angle,
        "start_direction": [round(float(v), 6) for v in u],
        "start_distance_m": round(s, 9),
        "nearest_gap_m": target,
        "goal_in_file": written,
        "force_per_weight": kf,
        "torque_per_weight_lever": kt,
    }
    story = [
        f"Goal: the bottom edge on y = 0 from x = 0 to {L:g} m, unrotated; every locator touches there (S on the {side_edge} edge).",
        _goal_story(goal, written),
        f"Start: in free space, turned {angle:g} deg about the centre of mass and moved {s * 1e3:.3f} mm along",
        f"{[round(float(v), 4) for v in u]} (up, away from S), where the nearest locator is {target * 1e3:g} mm away.",
    ]
    return _Draft(
        dimension=2,
        shape=shape,
        mass_kg=mass,
        start={"position": [float(v) for v in pose_at(s).p_world], "angle_deg": angle},
        goal=goal,
        locators=locators,
        max_force_N=max_force,
        max_torque_Nm=max_torque,
        params=params,
        resting=(),
        story=story,
        check=_check_plate_free,
        free=True,
        goal_written=written,
    )


def _check_plate_free(fixture: Fixture) -> str | None:
    com_x = float(fixture.goal.point_world_from_body(fixture.workpiece.com_body)[0])
    lo, hi = sorted(float(fixture.locator(n).p_world[0]) for n in ("B1", "B2"))
    if not lo < com_x < hi:
        return f"the centre of mass (x = {com_x:.4g} m) is not between B1 and B2 at the goal"
    return None


# -- mesh-321 ---------------------------------------------------------------------------------------


def _mm(rng: np.random.Generator, lo: float, hi: float) -> int:
    """A whole number of millimetres, log-uniform in [lo, hi]."""
    return int(round(math.exp(float(rng.uniform(math.log(lo), math.log(hi))))))


def _mesh_part(
    rng: np.random.Generator, kind: str, rho_mm: float
) -> tuple[tuple[Any, ...], dict[str, Any], dict[str, Any]] | str:
    """``(cells in mm, the part's dimensions, its faces)`` of one drawn part, or why not.

    The faces, in mm: ``footprint`` (x0, x1, y0, y1) of the bottom z = 0; ``side`` the y of the
    -y face and the (x, z) ranges S1 and S2 are drawn in; ``concave`` the x of the face E1
    touches (outward normal +x, inside the concave region), its y and z ranges, and ``room`` how
    far a tip there can move along +x before it meets the part again.
    """
    a, b, c = (_mm(rng, *MESH_EXTENT_MM) for _ in range(3))
    thickest = min(MESH_WALL_MM[1], min(a, b, c) // 4)  # walls at most a quarter of the part
    if thickest < MESH_WALL_MM[0]:
        return "the part is too small for its walls"
    t = int(rng.integers(MESH_WALL_MM[0], thickest + 1))
    m = 1.0  # [mm] a tip's clearance from the edges of a concave face
    dims: dict[str, Any]
    if kind == "l-bracket":
        cells = l_bracket_cells(float(a), float(b), float(c), float(t))
        dims = {"length_mm": a, "width_mm": b, "height_mm": c, "thickness_mm": t}
        faces = {
            "footprint": (0.0, a, 0.0, b),
            "side": (
                0.0,
                [
                    ((t + 0.1 * (a - t), a - 0.1 * (a - t)), (0.3 * t, 0.7 * t)),
                    ((0.3 * t, 0.7 * t), (t + 0.2 * (c - t), c - 0.1 * (c - t))),
                ],
            ),
            "concave": (
                float(t),
                (0.15 * b, 0.85 * b),
                (t + rho_mm + m + 0.1 * (c - t), c - m - 0.1 * (c - t)),
                math.inf,
            ),
        }
    elif kind == "slotted-block":
        narrowest = max(8, math.ceil(2 * rho_mm) + 6)
        if a // 3 < narrowest:
            return "the block is too short for a slot the tip fits in"
        w = int(rng.integers(narrowest, a // 3 + 1))
        d = int(rng.integers(max(4, c // 4), max(5, c // 2) + 1))
        if d < rho_mm + 2 * m + 2:
            return "the slot is too shallow for the tip"
        cells = slotted_block_cells((float(a), float(b), float(c)), float(w), float(d))
        dims = {"size_mm": [a, b, c], "slot_width_mm": w, "slot_depth_mm": d}
        faces = {
            "footprint": (-a / 2, a / 2, -b / 2, b / 2),
            "side": (
                -b / 2,
                [
                    ((-0.45 * a, -w / 2 - 0.1 * a), (0.2 * c, 0.8 * c)),
                    ((w / 2 + 0.1 * a, 0.45 * a), (0.2 * c, 0.8 * c)),
                ],
            ),
            "concave": (-w / 2, (-0.35 * b, 0.35 * b), (c - d + rho_mm + m, c - m), w - 2 * rho_mm),
        }
    else:  # housing
        d = int(rng.integers(max(4, c // 3), max(5, 2 * c // 3) + 1))
        if 2 * t + 2 * rho_mm + 10 > min(a, b) or d < rho_mm + 2 * m + 2 or c - d < 3:
            return "the pocket is too small for the tip, or the floor too thin"
        cells = housing_cells((float(a), float(b), float(c)), float(t), float(d))
        dims = {"size_mm": [a, b, c], "wall_mm": t, "pocket_depth_mm": d}
        inner = b / 2 - t - rho_mm - m
        faces = {
            "footprint": (-a / 2, a / 2, -b / 2, b / 2),
            "side": (-b / 2, [((-0.4 * a, -0.1 * a), (0.2 * c, 0.8 * c)), ((0.1 * a, 0.4 * a), (0.2 * c, 0.8 * c))]),
            "concave": (-a / 2 + t, (-0.7 * inner, 0.7 * inner), (c - d + rho_mm + m, c - m), a - 2 * t - 2 * rho_mm),
        }
    return cells, dims, faces


def _draw_mesh(rng: np.random.Generator) -> _Draft | str:
    """A part kind, then up to :data:`MESH_KIND_ATTEMPTS` draws of that kind (the kinds stay about equally likely)."""
    kind = MESH_PARTS[int(rng.integers(len(MESH_PARTS)))]
    reason = ""
    for _ in range(MESH_KIND_ATTEMPTS):
        draft = _draw_mesh_kind(rng, kind)
        if not isinstance(draft, str):
            return draft
        reason = draft
    return reason


def _draw_mesh_kind(rng: np.random.Generator, kind: str) -> _Draft | str:
    rho = _uniform(rng, *TIP_RADIUS_M, 4)
    drawn = _mesh_part(rng, kind, 1e3 * rho)
    if isinstance(drawn, str):
        return drawn
    cells, dims, faces = drawn
    volume_mm3, com_mm, _ = cell_mass_properties(*cells)
    density = round(_log_uniform(rng, *DENSITY_KG_M3, 0))
    mass = _sig(density * volume_mm3 * 1e-9, 4)
    mu, varied, mus = _frictions(rng, 6)
    soft = bool(rng.random() < 0.5)
    torsion = _uniform(rng, *TORSION_M, 4) if soft else 0.0
    x0, x1, y0, y1 = (1e-3 * v for v in faces["footprint"])
    face_x, e_y, e_z, room = faces["concave"]
    # the start: slid off S (+y) and off E1 (its face's normal is +x: -x), turned about the centre of mass
    cap_x = _offset_cap(x1 - x0)
    if math.isfinite(room):  # a slot or a pocket: the tip must not reach the opposite wall
        cap_x = min(cap_x, math.floor((1e-3 * room - 0.001) * 1e4) / 1e4)
    if cap_x < OFFSET_M[0]:
        return "no room to slide the part off E1 inside the concave region"
    dx = -_uniform(rng, OFFSET_M[0], cap_x, 4)
    dy = _uniform(rng, OFFSET_M[0], _offset_cap(y1 - y0), 4)
    tilt = _uniform(rng, *MESH_TILT_DEG, 2)
    yaw = tilt if rng.random() < 0.5 else -tilt
    # base locators under the bottom at both poses (the footprints' overlap, 8 % in from its edges)
    lo_x, hi_x = x0 + MESH_EDGE_MARGIN * (x1 - x0), x1 + dx - MESH_EDGE_MARGIN * (x1 - x0)
    lo_y, hi_y = y0 + dy + MESH_EDGE_MARGIN * (y1 - y0), y1 - MESH_EDGE_MARGIN * (y1 - y0)

    def base(u: tuple[float, float], v: tuple[float, float]) -> tuple[float, float]:
        x = _uniform(rng, lo_x + u[0] * (hi_x - lo_x), lo_x + u[1] * (hi_x - lo_x), 4)
        y = _uniform(rng, lo_y + v[0] * (hi_y - lo_y), lo_y + v[1] * (hi_y - lo_y), 4)
        return x, y

    com = 1e-3 * np.asarray(com_mm, dtype=float)
    middle = float(np.clip((com[0] + 0.5 * dx - lo_x) / (hi_x - lo_x), 0.2, 0.8))  # B3 about under the mass
    b1, b2 = base((0.0, 0.15), (0.0, 0.2)), base((0.85, 1.0), (0.0, 0.2))
    b3 = base((middle - 0.1, middle + 0.1), (0.8, 1.0))
    tri = np.array([b1, b2, b3])
    need = 0.05 * min(x1 - x0, y1 - y0)
    for centre in (com[:2], com[:2] + np.array([dx, dy])):
        if _triangle_margin(centre, tri) < need:
            return "the base triangle does not hold the centre of mass with a margin"
    side_y, side_boxes = faces["side"]
    (s1x, s1z), (s2x, s2z) = side_boxes
    s1 = (_uniform(rng, 1e-3 * s1x[0], 1e-3 * s1x[1], 4), _uniform(rng, 1e-3 * s1z[0], 1e-3 * s1z[1], 4))
    s2 = (_uniform(rng, 1e-3 * s2x[0], 1e-3 * s2x[1], 4), _uniform(rng, 1e-3 * s2z[0], 1e-3 * s2z[1], 4))
    if e_z[1] <= e_z[0] or e_y[1] <= e_y[0]:
        return "the concave face has no room for the tip"
    e1 = (_uniform(rng, 1e-3 * e_y[0], 1e-3 * e_y[1], 4), _uniform(rng, 1e-3 * e_z[0], 1e-3 * e_z[1], 4))
    spots = {
        "B1": [b1[0], b1[1], -rho],
        "B2": [b2[0], b2[1], -rho],
        "B3": [b3[0], b3[1], -rho],
        "S1": [s1[0], 1e-3 * side_y - rho, s1[1]],
        "S2": [s2[0], 1e-3 * side_y - rho, s2[1]],
        "E1": [1e-3 * face_x + rho, e1[0], e1[1]],
    }
    locators = []
    for (name, position), mu_i in zip(spots.items(), mus, strict=True):
        entry: dict[str, Any] = {"name": name, "position": position, "radius": rho, "friction": mu_i}
        if soft:
            entry["torsion"] = torsion
        locators.append(entry)
    R = matrix_from_rpy(np.radians([0.0, 0.0, yaw]))
    start_p = com + np.array([dx, dy, 0.0]) - R @ com
    weight = mass * GRAVITY_M_S2
    half_diagonal = 0.5e-3 * math.sqrt(sum(float(np.ptp(np.asarray(g))) ** 2 for g in cells[:3]))
    kf, kt, max_force, max_torque = _hand(rng, weight, half_diagonal)
    written = bool(rng.random() < GOAL_WRITTEN_SHARE)
    params = {
        "part": kind,
        **dims,
        "density_kg_m3": density,
        "mass_kg": mass,
        "tip_radius_m": rho,
        "friction": mu,
        "friction_per_locator": varied,
        "soft_fingers": soft,
        "torsion_m": torsion,
        "offset_m": [dx, dy],
        "yaw_deg": yaw,
        "force_per_weight": kf,
        "torque_per_weight_lever": kt,
        "goal_in_file": written,
    }
    concave = {"l-bracket": "the L's inner wall", "slotted-block": "a slot wall", "housing": "the pocket's inner wall"}
    story = [
        f"Part: a {kind.replace('-', ' ')} ({', '.join(f'{k} {v}' for k, v in dims.items())}), binary STL in mm; "
        "goal: the file's frame (the identity pose).",
        f"E1 touches {concave[kind]} (x = {1e-3 * face_x:g} m, normal +x), inside the part's concave region.",
        f"Start: slid by ({dx * 1e3:g}, {dy * 1e3:g}) mm off E1, S1 and S2 and turned {yaw:g} deg about z through "
        "the centre of mass, resting flat on B1, B2, B3 (gap 0).",
        *(["The file leaves the goal out: the loader computes it on the real surface."] if not written else []),
    ]
    V_mm, F = cell_surface(*cells)
    return _Draft(
        dimension=3,
        shape={"shape": "mesh", "file": "", "units": "mm"},
        mass_kg=mass,
        start={"position": [float(v) for v in start_p], "rpy_deg": [0.0, 0.0, yaw]},
        goal={"position": [0.0, 0.0, 0.0], "rpy_deg": [0.0, 0.0, 0.0]},
        locators=locators,
        max_force_N=max_force,
        max_torque_Nm=max_torque,
        params=params,
        resting=("B1", "B2", "B3"),
        story=story,
        check=_check_mesh,
        goal_written=written,
        files=((".stl", stl_bytes(V_mm, F)),),
    )


def _check_mesh(fixture: Fixture) -> str | None:
    """Each locator touches one face at the goal; E1's centre is inside the part's convex hull (a concave region)."""
    from scipy.spatial import ConvexHull

    shape = fixture.workpiece.shape
    for loc in fixture.locators:
        found = shape.contacts(fixture.goal.point_body_from_world(loc.p_world))  # type: ignore[attr-defined]
        if len(found) != 1:
            return f"{loc.name} touches {len(found)} faces at the goal (expected one)"
    hull = ConvexHull(np.asarray(shape.vertices))  # type: ignore[attr-defined]
    e1 = fixture.goal.point_body_from_world(fixture.locator("E1").p_world)
    if float(np.max(hull.equations[:, :3] @ e1 + hull.equations[:, 3])) >= 0.0:
        return "E1 is not inside the part's concave region (its centre is outside the convex hull)"
    return None


# -- plane-2-pins ----------------------------------------------------------------------------------


def _draw_plane_2_pins_mesh(rng: np.random.Generator) -> _Draft | str:
    """:func:`_draw_plane_2_pins`'s draw (the same numbers from the same stream), the box written as a mesh (module text)."""
    return _draw_plane_2_pins(rng, mesh=True)


def _bored_box_mm(size_m: list[float], holes: tuple[dict[str, Any], ...]) -> tuple[np.ndarray, np.ndarray]:
    """The box of ``size_m`` centred on the origin with a square through channel along z around each hole, in mm.

    Each channel's half side is the hole's mouth radius with its chamfer (``D/2 + chamfer``, up to
    the next 0.1 mm): the analytic hole lies inside it, as in a CAD part whose bore is modelled.
    """
    a, b, c = size_m
    channels = []
    for hole in holes:
        half = math.ceil((0.5 * hole["diameter"] + hole["chamfer"]) * 1e4) / 1e4
        x, y = hole["position"][0], hole["position"][1]
        channels.append((x - half, x + half, y - half, y + half))
    xs = np.unique(np.round([-a / 2, a / 2, *(v for ch in channels for v in ch[:2])], 10))
    ys = np.unique(np.round([-b / 2, b / 2, *(v for ch in channels for v in ch[2:])], 10))
    zs = np.array([-c / 2, c / 2])
    filled = np.ones((len(xs) - 1, len(ys) - 1, 1), dtype=bool)
    for i in range(len(xs) - 1):
        for j in range(len(ys) - 1):
            mx, my = 0.5 * (xs[i] + xs[i + 1]), 0.5 * (ys[j] + ys[j + 1])
            if any(x0 < mx < x1 and y0 < my < y1 for x0, x1, y0, y1 in channels):
                filled[i, j, 0] = False
    return cell_surface(1e3 * xs, 1e3 * ys, 1e3 * zs, filled)


def _draw_plane_2_pins(rng: np.random.Generator, mesh: bool = False) -> _Draft | str:
    """A box on 3 rests and a round and a diamond pin in two through holes of its bottom (module text).

    ``mesh``: the box written as a mesh part (plane-2-pins-mesh), its bores modelled; the draw is the same.
    """
    a, b, c = (_log_uniform(rng, lo, hi, 4) for lo, hi in PIN_PART_EDGE_M)
    density = round(_log_uniform(rng, *DENSITY_KG_M3, 0))
    mass = _sig(density * a * b * c, 4)
    D = _uniform(rng, *PIN_HOLE_D_M, 4)
    play = _sig(_log_uniform(rng, *PIN_PLAY_M, 7), 3)
    d = round(D - 2.0 * play, 7)
    hole_chamfer = _uniform(rng, *PIN_CHAMFER_M, 4)
    pin_chamfer = round(min(_uniform(rng, *PIN_CHAMFER_M, 4), 0.4 * d / 2), 4)
    # each pin's length on its own: the longer engages first (equal lengths: both in one transition)
    lengths = tuple(round(_uniform(rng, *PIN_LENGTH_FRACTION, 3) * c, 4) for _ in range(2))
    land = round(_uniform(rng, *PIN_LAND_FRACTION, 3) * d, 5)
    mu, varied, mus = _frictions(rng, 5)
    # the holes along x, at least PIN_SPAN_FRACTION of a apart, their mouths (with the chamfer) 2 D in
    # from the edges; the round pin's at H1, the diamond's at H2
    edge = 2.0 * D + hole_chamfer
    if a - 2 * edge < PIN_SPAN_FRACTION * a or b < 2 * edge:
        return "the part is too small for two holes of this diameter"
    x1 = _uniform(rng, edge, a / 2 - PIN_SPAN_FRACTION * a / 2, 4)
    x2 = _uniform(rng, max(x1 + PIN_SPAN_FRACTION * a, a / 2), a - edge, 4)
    y1, y2 = (_uniform(rng, edge, b - edge, 4) for _ in range(2))
    # seated toward the round pin's contact: P1 stands `play` off H1's axis against the seating
    # direction s (a heading drawn in the plane), so the part seated along s touches it; P2 centred
    heading = _uniform(rng, 0.0, 360.0, 1)
    s = np.array([math.cos(math.radians(heading)), math.sin(math.radians(heading))])
    p1 = (round(x1 - play * float(s[0]), 10), round(y1 - play * float(s[1]), 10))
    between = np.array([x2 - x1, y2 - y1])
    across = np.array([-between[1], between[0]]) / float(np.linalg.norm(between))  # the diamond's lands
    # rests: B1, B2 near x = 0, B3 near x = a, clear of the holes by 2 D; their triangle holds the centre
    b1 = (_uniform(rng, 0.08 * a, 0.3 * a, 4), _uniform(rng, 0.08 * b, 0.3 * b, 4))
    b2 = (_uniform(rng, 0.08 * a, 0.3 * a, 4), _uniform(rng, 0.7 * b, 0.92 * b, 4))
    b3 = (_uniform(rng, 0.7 * a, 0.92 * a, 4), _uniform(rng, 0.35 * b, 0.65 * b, 4))
    for rest in (b1, b2, b3):
        for hx, hy in ((x1, y1), (x2, y2)):
            if math.hypot(rest[0] - hx, rest[1] - hy) < 2.0 * D + hole_chamfer:
                return "a rest under a hole"
    if _triangle_margin(np.array([a / 2, b / 2]), np.array([b1, b2, b3])) < 0.05 * min(a, b):
        return "the rests' triangle does not hold the centre of mass with a margin"
    # the start: the holes' mouths PIN_START_RISE_M above the pins' tips, off within the capture, tilted
    rise = _uniform(rng, *PIN_START_RISE_M, 4)
    capture = PIN_CAPTURE_SHARE * (play + hole_chamfer + pin_chamfer)
    off = rng.uniform(-1.0, 1.0, 2)
    off = off / max(1.0, float(np.linalg.norm(off))) * capture
    tilt = [_uniform(rng, -PIN_START_TILT_DEG, PIN_START_TILT_DEG, 3) for _ in range(3)]
    weight = mass * GRAVITY_M_S2
    kf, kt, max_force, max_torque = _hand(rng, weight, 0.5 * math.sqrt(a * a + b * b + c * c))
    locators = [
        {"name": n, "position": [x, y, 0.0], "friction": m}
        for n, (x, y), m in zip(("B1", "B2", "B3"), (b1, b2, b3), mus[:3], strict=True)
    ]
    holes = tuple(
        {"name": n, "position": [x - a / 2, y - b / 2, -c / 2], "axis": [0.0, 0.0, -1.0], "diameter": D,
         "depth": c, "chamfer": hole_chamfer}
        for n, (x, y) in (("H1", (x1, y1)), ("H2", (x2, y2)))
    )  # fmt: skip
    common = {"axis": [0.0, 0.0, 1.0], "diameter": d, "chamfer": pin_chamfer}
    pins = (
        {"name": "P1", "kind": "round", "hole": "H1", "position": [p1[0], p1[1], 0.0], **common,
         "length": lengths[0], "friction": mus[3]},
        {"name": "P2", "kind": "diamond", "hole": "H2", "position": [x2, y2, 0.0], **common,
         "length": lengths[1], "friction": mus[4],
         "land_direction": [round(float(across[0]), 9), round(float(across[1]), 9), 0.0], "land_width": land},
    )  # fmt: skip
    start_c = [a / 2 + float(off[0]), b / 2 + float(off[1]), c / 2 + max(lengths) + rise]
    params = {
        "size_m": [a, b, c],
        "density_kg_m3": density,
        "mass_kg": mass,
        "hole_diameter_m": D,
        "pin_diameter_m": d,
        "radial_play_m": play,
        "hole_chamfer_m": hole_chamfer,
        "pin_chamfer_m": pin_chamfer,
        "pin_lengths_m": list(lengths),
        "land_width_m": land,
        "holes_xy_m": [[x1, y1], [x2, y2]],
        "seating_heading_deg": heading,
        "friction": mu,
        "friction_per_locator": varied,
        "start_rise_m": rise,
        "start_offset_m": [float(off[0]), float(off[1])],
        "start_tilt_deg": tilt,
        "force_per_weight": kf,
        "torque_per_weight_lever": kt,
    }
    story = [
        f"Goal: the box fills [0, {a:g}] x [0, {b:g}] x [0, {c:g}] m on the rests B1, B2, B3; its through holes H1, H2",
        f"(D = {D * 1e3:g} mm) on the round pin P1 and the diamond pin P2 (d = {d * 1e3:g} mm, play {play * 1e6:g} um),",
        f"seated toward heading {heading:g} deg: P1 touches H1's wall, P2 is centred in H2.",
        f"Start: the holes {rise * 1e3:g} mm above the longer pin's tip, off by ({off[0] * 1e3:.3f}, {off[1] * 1e3:.3f}) mm",
        f"(play + chamfers = {2 * capture * 1e3:.3f} mm), tilted (roll, pitch, yaw) = {tilt} deg; each hole within 80 %",
        "of that of its pin's axis (the chamfers capture it).",
    ]
    shape: dict[str, Any] = {"shape": "box", "size": [a, b, c]}
    files: tuple[tuple[str, bytes], ...] = ()
    if mesh:
        V_mm, F = _bored_box_mm([a, b, c], holes)
        shape = {"shape": "mesh", "file": "", "units": "mm"}
        files = ((".stl", stl_bytes(V_mm, F)),)
        story.append(
            f"The box is a mesh part (binary STL in mm, {len(F)} triangles, body frame at its centre) with each "
            "hole's bore modelled as a square through channel; the holes are the analytic [[workpiece.hole]]s."
        )
    return _Draft(
        dimension=3,
        shape=shape,
        mass_kg=mass,
        start={"position": start_c, "rpy_deg": tilt},
        goal={"position": [a / 2, b / 2, c / 2], "rpy_deg": [0.0, 0.0, 0.0]},
        locators=locators,
        max_force_N=max_force,
        max_torque_Nm=max_torque,
        params=params,
        resting=(),
        story=story,
        check=lambda _fixture: None,
        files=files,
        holes=holes,
        pins=pins,
    )


# -- shaft-bore ------------------------------------------------------------------------------------


def _draw_shaft_bore(rng: np.random.Generator) -> _Draft | str:
    """A shaft above a blind bore at the origin (axis +z), tilted, to be loaded to the bottom (module text)."""
    r = _log_uniform(rng, *SHAFT_RADIUS_M, 4)
    length = round(_log_uniform(rng, *SHAFT_LENGTH_PER_DIAMETER, 3) * 2.0 * r, 4)
    density = round(_log_uniform(rng, *DENSITY_KG_M3, 0))
    mass = _sig(density * math.pi * r * r * length, 4)
    play = _sig(_log_uniform(rng, *BORE_PLAY_M, 8), 3)
    D = round(2.0 * (r + play), 8)
    sharp = bool(rng.random() < BORE_SHARP_SHARE)
    chamfer = 0.0 if sharp else _uniform(rng, *BORE_CHAMFER_M, 4)
    depth = round(_uniform(rng, *BORE_DEPTH_FRACTION, 3) * length, 4)
    mu = _uniform(rng, *FRICTION, 3)
    roll, pitch = (_uniform(rng, -SHAFT_START_TILT_DEG, SHAFT_START_TILT_DEG, 2) for _ in range(2))
    yaw = _uniform(rng, 0.0, 360.0, 1)
    rho, phi = SHAFT_START_OFFSET_M * math.sqrt(float(rng.random())), 2.0 * math.pi * float(rng.random())
    off = (round(rho * math.cos(phi), 6), round(rho * math.sin(phi), 6))
    rise = _uniform(rng, *SHAFT_START_RISE_M, 4)
    weight = mass * GRAVITY_M_S2
    kf, kt, max_force, max_torque = _hand(rng, weight, 0.5 * length)
    # the start: the leading (lower) end's centre over (off) the bore's axis, the lowest point of its edge `rise` up
    z_b = matrix_from_rpy(np.radians([roll, pitch, yaw]))[:, 2]
    sin_tilt = math.sqrt(max(0.0, 1.0 - float(z_b[2]) ** 2))
    centre = np.array([off[0], off[1], rise + r * sin_tilt]) + 0.5 * length * z_b
    bore = {"name": "B1", "position": [0.0, 0.0, 0.0], "axis": [0.0, 0.0, 1.0], "diameter": D, "depth": depth,
            "friction": mu, **({} if sharp else {"chamfer": chamfer})}  # fmt: skip
    params = {
        "radius_m": r,
        "length_m": length,
        "density_kg_m3": density,
        "mass_kg": mass,
        "bore_diameter_m": D,
        "radial_play_m": play,
        "bore_chamfer_m": chamfer,
        "bore_depth_m": depth,
        "friction": mu,
        "start_rpy_deg": [roll, pitch, yaw],
        "start_offset_m": list(off),
        "start_rise_m": rise,
        "force_per_weight": kf,
        "torque_per_weight_lever": kt,
    }
    capture = play + chamfer
    story = [
        f"Goal: derived by the loader: the shaft (r = {r * 1e3:g} mm, {length * 1e3:g} mm long) coaxial in the bore B1",
        f"(D = {D * 1e3:.5g} mm, play {play * 1e6:.3g} um, chamfer {chamfer * 1e3:g} mm, {depth * 1e3:g} mm deep), its "
        "leading end on the bottom.",
        f"Start: above the bore, tilted (roll, pitch, yaw) = ({roll:g}, {pitch:g}, {yaw:g}) deg, its leading end's centre",
        f"({off[0] * 1e3:.3f}, {off[1] * 1e3:.3f}) mm off the axis (capture: play + chamfer = {capture * 1e3:.3g} mm),",
        f"its lowest point {rise * 1e3:g} mm above the mouth; nothing touches.",
    ]
    return _Draft(
        dimension=3,
        shape={"shape": "cylinder", "radius": r, "length": length},
        mass_kg=mass,
        start={"position": [float(x) for x in centre], "rpy_deg": [roll, pitch, yaw]},
        goal={},
        locators=[],
        max_force_N=max_force,
        max_torque_Nm=max_torque,
        params=params,
        resting=(),
        story=story,
        check=lambda _fixture: None,
        goal_written=False,
        bores=(bore,),
    )


def _draw_plane_pin_stop(rng: np.random.Generator) -> _Draft | str:
    """A plate on 3 rests, one round pin in a through hole of its bottom and a stop on a side face (module text)."""
    a, b, c = (_log_uniform(rng, lo, hi, 4) for lo, hi in PIN_PART_EDGE_M)
    density = round(_log_uniform(rng, *DENSITY_KG_M3, 0))
    mass = _sig(density * a * b * c, 4)
    D = _uniform(rng, *PIN_HOLE_D_M, 4)
    play = _sig(_log_uniform(rng, *PIN_PLAY_M, 7), 3)
    d = round(D - 2.0 * play, 7)
    hole_chamfer = _uniform(rng, *PIN_CHAMFER_M, 4)
    pin_chamfer = round(min(_uniform(rng, *PIN_CHAMFER_M, 4), 0.4 * d / 2), 4)
    length = round(_uniform(rng, *PIN_LENGTH_FRACTION, 3) * c, 4)
    mu, varied, mus = _frictions(rng, 5)
    # the hole anywhere, its chamfered mouth 2 D in from the edges; P1 stands `play` off its axis
    # against the seating heading s, so the part seated along s touches it
    edge = 2.0 * D + hole_chamfer
    if a < 2 * edge or b < 2 * edge:
        return "the part is too small for a hole of this diameter"
    hx, hy = _uniform(rng, edge, a - edge, 4), _uniform(rng, edge, b - edge, 4)
    heading = _uniform(rng, 0.0, 360.0, 1)
    s = np.array([math.cos(math.radians(heading)), math.sin(math.radians(heading))])
    p1 = (round(hx - play * float(s[0]), 10), round(hy - play * float(s[1]), 10))
    # the stop on one of the four side faces (its outward normal drawn), along the face at least
    # STOP_LEVER_FRACTION of the face's length from the pin (it takes the turn about it), in from the ends
    face = int(rng.integers(4))  # 0: -x, 1: +x, 2: -y, 3: +y
    along_len = b if face < 2 else a
    t = _uniform(rng, STOP_EDGE_FRACTION * along_len, (1.0 - STOP_EDGE_FRACTION) * along_len, 4)
    pin_along = hy if face < 2 else hx
    if abs(t - pin_along) < STOP_LEVER_FRACTION * along_len:
        return "the stop is too near the pin's axis along its face to take the turn"
    z_stop = _uniform(rng, STOP_HEIGHT_FRACTION[0] * c, STOP_HEIGHT_FRACTION[1] * c, 4)
    tip = 0.0 if rng.random() < 0.5 else _uniform(rng, *STOP_TIP_RADIUS_M, 4)
    out = [(-1.0, 0.0), (1.0, 0.0), (0.0, -1.0), (0.0, 1.0)][face]  # the face's outward normal
    on_face = (0.0 if face == 0 else a, t) if face < 2 else (t, 0.0 if face == 2 else b)
    stop = (round(on_face[0] + tip * out[0], 6), round(on_face[1] + tip * out[1], 6), z_stop)
    # rests: B1, B2 near one end of x, B3 near the other (mirrored per fixture), clear of the hole by
    # 2 D; their triangle holds the centre of mass with a margin
    mirrored = bool(rng.random() < 0.5)
    b1 = (_uniform(rng, 0.08 * a, 0.3 * a, 4), _uniform(rng, 0.08 * b, 0.3 * b, 4))
    b2 = (_uniform(rng, 0.08 * a, 0.3 * a, 4), _uniform(rng, 0.7 * b, 0.92 * b, 4))
    b3 = (_uniform(rng, 0.7 * a, 0.92 * a, 4), _uniform(rng, 0.35 * b, 0.65 * b, 4))
    if mirrored:
        b1, b2, b3 = ((round(a - x, 4), y) for x, y in (b1, b2, b3))
    for rest in (b1, b2, b3):
        if math.hypot(rest[0] - hx, rest[1] - hy) < 2.0 * D + hole_chamfer:
            return "a rest under the hole"
    if _triangle_margin(np.array([a / 2, b / 2]), np.array([b1, b2, b3])) < 0.05 * min(a, b):
        return "the rests' triangle does not hold the centre of mass with a margin"
    # the start: above the pin's tip and the stop, tilted about every axis, off to the side
    tilt = [_uniform(rng, -PIN_STOP_TILT_DEG, PIN_STOP_TILT_DEG, 3) for _ in range(3)]
    off = [_uniform(rng, -PIN_STOP_OFFSET_M, PIN_STOP_OFFSET_M, 4) for _ in range(2)]
    rise = _uniform(rng, *PIN_STOP_RISE_M, 4)
    R = matrix_from_rpy(np.radians(tilt))
    below = float(np.abs(R[2, :]) @ np.array([a, b, c])) / 2  # the centre above the part's lowest point
    clear = max(length, z_stop + tip)
    start_c = [a / 2 + off[0], b / 2 + off[1], round(clear + rise + below, 6)]
    weight = mass * GRAVITY_M_S2
    kf, kt, max_force, max_torque = _hand(rng, weight, 0.5 * math.sqrt(a * a + b * b + c * c))
    locators: list[dict[str, Any]] = [
        {"name": n, "position": [x, y, 0.0], "friction": m}
        for n, (x, y), m in zip(("B1", "B2", "B3"), (b1, b2, b3), mus[:3], strict=True)
    ]
    locators.append({"name": "S1", "position": list(stop), **({"radius": tip} if tip else {}), "friction": mus[3]})
    holes = (
        {"name": "H1", "position": [hx - a / 2, hy - b / 2, -c / 2], "axis": [0.0, 0.0, -1.0], "diameter": D,
         "depth": c, "chamfer": hole_chamfer},
    )  # fmt: skip
    pins = (
        {"name": "P1", "kind": "round", "hole": "H1", "position": [p1[0], p1[1], 0.0], "axis": [0.0, 0.0, 1.0],
         "diameter": d, "length": length, "friction": mus[4], "chamfer": pin_chamfer},
    )  # fmt: skip
    face_name = ("-x", "+x", "-y", "+y")[face]
    params = {
        "size_m": [a, b, c],
        "density_kg_m3": density,
        "mass_kg": mass,
        "hole_diameter_m": D,
        "pin_diameter_m": d,
        "radial_play_m": play,
        "hole_chamfer_m": hole_chamfer,
        "pin_chamfer_m": pin_chamfer,
        "pin_length_m": length,
        "hole_xy_m": [hx, hy],
        "seating_heading_deg": heading,
        "stop_face": face_name,
        "stop_along_m": t,
        "stop_height_m": z_stop,
        "stop_tip_radius_m": tip,
        "rests_mirrored": mirrored,
        "friction": mu,
        "friction_per_locator": varied,
        "start_rise_m": rise,
        "start_offset_m": off,
        "start_tilt_deg": tilt,
        "force_per_weight": kf,
        "torque_per_weight_lever": kt,
    }
    story = [
        f"Goal: the plate fills [0, {a:g}] x [0, {b:g}] x [0, {c:g}] m on the rests B1, B2, B3; its through hole H1",
        f"(D = {D * 1e3:g} mm) at ({hx:g}, {hy:g}) on the round pin P1 (d = {d * 1e3:g} mm, play {play * 1e6:g} um),",
        f"seated toward heading {heading:g} deg: P1 touches H1's wall; the stop S1 on the {face_name} face at",
        f"{t:g} m along it and {z_stop:g} m up (tip radius {tip * 1e3:g} mm) takes the turn about P1's axis.",
        f"Start: the part's lowest point {rise * 1e3:g} mm above the pin's tip and the stop's top, off by ({off[0] * 1e3:g},",
        f"{off[1] * 1e3:g}) mm, tilted (roll, pitch, yaw) = {tilt} deg about its centre: nothing touches.",
    ]
    return _Draft(
        dimension=3,
        shape={"shape": "box", "size": [a, b, c]},
        mass_kg=mass,
        start={"position": start_c, "rpy_deg": tilt},
        goal={"position": [a / 2, b / 2, c / 2], "rpy_deg": [0.0, 0.0, 0.0]},
        locators=locators,
        max_force_N=max_force,
        max_torque_Nm=max_torque,
        params=params,
        resting=(),
        story=story,
        check=lambda _fixture: None,
        holes=holes,
        pins=pins,
        far_pins=True,
    )


_DRAWS: dict[str, Callable[[np.random.Generator], _Draft | str]] = {
    "box-321": _draw_box,
    "plate-2d": _draw_plate,
    "box-321-free": _draw_box_free,
    "plate-2d-free": _draw_plate_free,
    "mesh-321": _draw_mesh,
    "plane-2-pins": _draw_plane_2_pins,
    "plane-2-pins-mesh": _draw_plane_2_pins_mesh,
    "shaft-bore": _draw_shaft_bore,
    "plane-pin-stop": _draw_plane_pin_stop,
}


# -- checks and output ------------------------------------------------------------------------------


def _check_pins(fixture: Fixture, draft: _Draft) -> str | None:
    """Why a plane-2-pins draft is not valid, or None: the located pose as built, the start clear above the pins."""
    from fixplan.locating import cylinder_contacts

    if not fixture.is_full:
        return "the rests and pins do not make 6 constraints"
    wp = fixture.workpiece
    goal_gaps = locator_gaps(wp, fixture.goal, fixture.locators)
    if np.max(np.abs(goal_gaps)) > EXACT_M:
        return f"a rest does not touch at the goal (gaps {goal_gaps})"
    play = float(draft.params["radial_play_m"])
    seated: dict[str, float] = {}
    for c in cylinder_contacts(fixture, fixture.goal):
        seated[c.owner] = min(seated.get(c.owner, math.inf), c.gap_m)
    if abs(seated.get("P1", math.inf)) > EXACT_M:
        return f"the round pin does not touch its hole at the goal (gap {seated.get('P1')})"
    if abs(seated.get("P2", math.inf) - play) > EXACT_M:
        return f"the diamond pin is not centred in its hole at the goal (gap {seated.get('P2')}, play {play})"
    start_gaps = locator_gaps(wp, fixture.start, fixture.locators)
    if np.min(start_gaps) < CLEARANCE_M:
        return f"a rest is within {np.min(start_gaps):.3g} m of the part at the start"
    for c in cylinder_contacts(fixture, fixture.start):
        if c.gap_m < CLEARANCE_M:
            return f"{c.name} touches at the start (gap {c.gap_m:.3g} m)"
    capture = play + float(draft.params["hole_chamfer_m"]) + float(draft.params["pin_chamfer_m"])
    for pin in fixture.pins:  # the chamfers capture the start: each hole over its pin, the tilt included
        mouth = fixture.start.point_world_from_body(wp.hole(pin.hole).p_body)
        off = mouth - pin.p_world
        lateral = float(np.linalg.norm(off - float(off @ pin.axis_world) * pin.axis_world))
        if lateral > PIN_CAPTURE_CHECK * capture:
            return f"{pin.hole} is {lateral:.3g} m off {pin.name} at the start (capture {capture:.3g} m)"
    return None  # the rank of the rests' and pins' constraints: the loader's own check


def _check_bore(fixture: Fixture, draft: _Draft) -> str | None:
    """Why a shaft-bore draft is not valid, or None: the derived located pose on the bottom, the start clear above the bore."""
    from fixplan.locating import bottom_gap_m, cylinder_contacts, located_pose

    (bore,) = fixture.bores
    goal = located_pose(fixture)
    if abs(bottom_gap_m(fixture, goal, bore)) > EXACT_M:
        return f"the located shaft is {bottom_gap_m(fixture, goal, bore):.3g} m off the bore's bottom"
    for c in cylinder_contacts(fixture, fixture.start):
        if c.gap_m < CLEARANCE_M:
            return f"{c.name} touches at the start (gap {c.gap_m:.3g} m)"
    shape = fixture.workpiece.shape
    if not isinstance(shape, Cylinder):  # pragma: no cover - the loader refuses a bore for any other part
        return "a bore takes a cylindrical part"
    z = fixture.start.R_world_body[:, 2]
    sin_tilt = math.sqrt(max(0.0, 1.0 - float(z @ bore.axis_world) ** 2))
    ends = [fixture.start.p_world + s * 0.5 * shape.length * z for s in (1.0, -1.0)]
    lowest = min(float((e - bore.p_world) @ bore.axis_world) for e in ends) - shape.radius * sin_tilt
    if lowest < SHAFT_START_RISE_M[0] - EXACT_M:
        return f"the shaft's lowest point is {lowest:.3g} m above the mouth at the start"
    return None


def _check_pin_stop(fixture: Fixture) -> str | None:
    """Why a plane-pin-stop draft is not valid, or None: the located pose as built (S1 a stop), the start clear of everything."""
    from fixplan.locating import cylinder_contacts, insertion_axis, seat_at

    if not fixture.is_full:
        return "the rests, the pin and the stop do not make 6 constraints"
    wp = fixture.workpiece
    goal_gaps = locator_gaps(wp, fixture.goal, fixture.locators)
    if np.max(np.abs(goal_gaps)) > EXACT_M:
        return f"a locator does not touch at the goal (gaps {goal_gaps})"
    seated = min((c.gap_m for c in cylinder_contacts(fixture, fixture.goal)), default=math.inf)
    if abs(seated) > EXACT_M:
        return f"the round pin does not touch its hole at the goal (gap {seated})"
    if seat_at(fixture, fixture.goal, insertion_axis(fixture)).stop_names != ("S1",):
        return "S1 does not face across the pin's axis at the goal"
    start_gaps = locator_gaps(wp, fixture.start, fixture.locators)
    if np.min(start_gaps) < CLEARANCE_M:
        return f"a locator is within {np.min(start_gaps):.3g} m of the part at the start"
    for c in cylinder_contacts(fixture, fixture.start):
        if c.gap_m < CLEARANCE_M:
            return f"{c.name} touches at the start (gap {c.gap_m:.3g} m)"
    return None  # the rank of the rests', the pin's and the stop's constraints: the loader's own check


def _check(fixture: Fixture, draft: _Draft) -> str | None:
    """Why the loaded draft is not a valid generated fixture, or None."""
    if not fixture.is_full:
        return f"only {len(fixture.locators)} locators"
    wp = fixture.workpiece
    names = [loc.name for loc in fixture.locators]
    goal_gaps = locator_gaps(wp, fixture.goal, fixture.locators)
    if np.max(np.abs(goal_gaps)) > EXACT_M:
        return f"a locator does not touch at the goal (gaps {goal_gaps})"
    for name, gap in zip(names, locator_gaps(wp, fixture.start, fixture.locators), strict=True):
        if gap < -EXACT_M:
            return f"{name} penetrates the part at the start by {-gap:.3g} m"
        if name in draft.resting and gap > EXACT_M:
            return f"{name} should touch at the start but has a gap of {gap:.3g} m"
        if name not in draft.resting and gap < CLEARANCE_M:
            return f"{name} should be clear at the start but has a gap of {gap:.3g} m"
    G = contact_set(fixture, "goal", names).G
    rank = int(np.linalg.matrix_rank(G, tol=DEFAULT.numerics.rank_tol))
    if rank < fixture.ndof:
        return f"rank G = {rank} < {fixture.ndof} at the goal"
    found = solve_goal(wp, fixture.locators, fixture.start)
    dp, dang = found.pose.distance_to(fixture.goal)
    if not found.converged or dp > 1e-7 or dang > 1e-7:
        return f"the goal found from the start is not the given goal ({dp:.3g} m, {dang:.3g} rad away)"
    return draft.check(fixture)


def _check_free(fixture: Fixture, draft: _Draft) -> str | None:
    """Why a free-space draft is not valid, or None; its goal is checked as given, never searched for."""
    if not fixture.is_full:
        return f"only {len(fixture.locators)} locators"
    wp = fixture.workpiece
    names = [loc.name for loc in fixture.locators]
    goal_gaps = locator_gaps(wp, fixture.goal, fixture.locators)
    if np.max(np.abs(goal_gaps)) > EXACT_M:
        return f"a locator does not touch at the goal (gaps {goal_gaps})"
    start_gaps = locator_gaps(wp, fixture.start, fixture.locators)
    if np.min(start_gaps) < START_GAP_M[0] - EXACT_M or np.min(start_gaps) > START_GAP_M[1] + EXACT_M:
        return f"the nearest locator is {np.min(start_gaps):.6g} m away at the start (expected {START_GAP_M} m)"
    G = contact_set(fixture, "goal", names).G
    rank = int(np.linalg.matrix_rank(G, tol=DEFAULT.numerics.rank_tol))
    if rank < fixture.ndof:
        return f"rank G = {rank} < {fixture.ndof} at the goal"
    return draft.check(fixture)


def _check_twin(
    fixture: Fixture, doc: dict[str, Any], name: str, folder: Path, *, far_pins: bool = False
) -> str | None:
    """Why the rotated document is not the same fixture (gaps at the start and the goal), or None.

    The gaps: every locator's, and every pin's and bore's least gap to its hole (the pins, bores
    and holes are turned too: :func:`fixplan.twins.rotate_world`). ``far_pins``: at the start the
    pins' gaps are only checked clear (beyond :data:`CLEARANCE_M`) in both.
    """
    from fixplan.locating import cylinder_contacts, located_pose

    try:
        twin = loads(twins.fixture_toml(doc), source=name, base_dir=folder)
    except FixtureError as exc:
        return f"the loader refused the rotated fixture: {exc.issues[0].key}: {exc.issues[0].message}"

    def least(f: Fixture, pose: Pose) -> np.ndarray:
        """Each pin's and bore's least gap (inf: no contact possible at ``pose``)."""
        out = dict.fromkeys([p.name for p in f.pins] + [b.name for b in f.bores], math.inf)
        for c in cylinder_contacts(f, pose):
            out[c.owner] = min(out[c.owner], c.gap_m)
        return np.array(list(out.values()))

    goals = (located_pose(fixture), located_pose(twin)) if fixture.has_pins else (fixture.goal, twin.goal)
    for a, b in ((fixture.start, twin.start), goals):
        diff = locator_gaps(fixture.workpiece, a, fixture.locators) - locator_gaps(twin.workpiece, b, twin.locators)
        if fixture.has_pins and far_pins and a is fixture.start:
            if min(np.min(least(fixture, a)), np.min(least(twin, b))) < CLEARANCE_M:
                return "a pin touches at the rotated fixture's start"
        elif fixture.has_pins:
            mine, theirs = least(fixture, a), least(twin, b)
            if not np.array_equal(np.isinf(mine), np.isinf(theirs)):
                return "the rotated fixture's pins touch where the fixture's cannot (or the other way round)"
            finite = np.isfinite(mine)
            diff = np.concatenate([diff, mine[finite] - theirs[finite]])
        if np.max(np.abs(diff)) > EXACT_M:
            return f"the rotated fixture's gaps differ by {np.max(np.abs(diff)):.3g} m"
    return None


def _floor_block(fixture: Fixture) -> str:
    """An ``[[obstacle]]`` floor normal to gravity, :data:`FLOOR_BELOW_M` below the part at its start and goal."""
    d = fixture.dimension
    from fixplan.locating import located_pose

    pts, radii = collision_points(fixture.workpiece.shape, DEFAULT.engine.rim_points)
    goal = located_pose(fixture) if fixture.bores else fixture.goal  # a bore's located pose is derived
    low = min(
        float(pose.point_world_from_body(b)[d - 1] - r)
        for pose in (fixture.start, goal)
        for b, r in zip(pts, radii, strict=True)
    )
    level = math.floor((low - FLOOR_BELOW_M) * 1e4) / 1e4  # 0.1 mm steps, rounded down (further away)
    point = [0.0] * (d - 1) + [level]
    normal = [0.0] * (d - 1) + [1.0]
    lines = ["", "[[obstacle]]", 'name = "floor"', f'shape = "{"plane" if d == 3 else "line"}"']
    lines += [f"point = {_value(point)}", f"normal = {_value(normal)}", "friction = 0.3"]
    return "\n".join(lines) + "\n"


def _value(x: Any) -> str:
    """A TOML value: numbers with at most 12 significant digits (no binary noise such as 0.30000000000000004)."""
    return twins.toml_value(x, digits=12)


def _render(name: str, draft: _Draft, goal: bool = True) -> str:
    gravity = [0.0, 0.0, -GRAVITY_M_S2] if draft.dimension == 3 else [0.0, -GRAVITY_M_S2]
    lines = [
        "format = 1",
        "",
        "[scene]",
        f"name = {_value(name)}",
        f"dimension = {draft.dimension}",
        f"gravity = {_value(gravity)}",
        "",
        "[workpiece]",
        *(f"{k} = {_value(v)}" for k, v in draft.shape.items()),
        f"mass = {_value(draft.mass_kg)}",
        f"start = {_value(draft.start)}",
        *([f"goal = {_value(draft.goal)}"] if goal else []),
    ]
    for hole in draft.holes:
        lines += ["", "[[workpiece.hole]]", *(f"{k} = {_value(v)}" for k, v in hole.items())]
    for loc in draft.locators:
        lines += ["", "[[locator]]", *(f"{k} = {_value(v)}" for k, v in loc.items())]
    for pin in draft.pins:
        lines += ["", "[[pin]]", *(f"{k} = {_value(v)}" for k, v in pin.items())]
    for bore in draft.bores:
        lines += ["", "[[bore]]", *(f"{k} = {_value(v)}" for k, v in bore.items())]
    lines += [
        "",
        "[manipulator]",
        f"max_force = {_value(draft.max_force_N)}",
        f"max_torque = {_value(draft.max_torque_Nm)}",
    ]
    return "\n".join(lines) + "\n"


def _header(
    name: str, family: str, seed: int, index: int, draw: int, draft: _Draft, fixture: Fixture, rotated: bool = False
) -> str:
    gaps = locator_gaps(fixture.workpiece, fixture.start, fixture.locators)
    gap_text = ", ".join(f"{loc.name} {g * 1e3:.3f}" for loc, g in zip(fixture.locators, gaps, strict=True))
    weight = draft.mass_kg * GRAVITY_M_S2
    lines = [
        f"{name}: generated by `fixplan generate {family} --seed {seed}{' --rotate-world' if rotated else ''}` "
        f"(fixture index {index}).",
        f"Family {family}: {ALL_FAMILIES[family]}.",
        f"Drawn from numpy.random.default_rng([{seed}, {index}]), draw {draw} "
        f"({draw - 1} earlier draws failed a check and were replaced).",
        *draft.story,
        *([f"Start gaps [mm]: {gap_text}."] if fixture.locators else []),
        f"Weight m g = {weight:.4g} N; hand limits {draft.max_force_N:.4g} N, {draft.max_torque_Nm:.4g} N m.",
        "Drawn parameters:",
        *(f"  {k} = {_value(v)}" for k, v in draft.params.items()),
    ]
    return "".join(f"# {line}\n" for line in lines)
