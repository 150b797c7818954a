"""Locator contacts at a pose, and the located (goal) pose where every locator touches.

A locator is a sphere of radius ρ centred at ``p_world`` fixed in the world. Its gap to the
workpiece is the shape's signed distance from the tip centre minus ρ, its contact point is the
closest point on the workpiece surface, and its normal is the surface's inward normal.

The goal pose solves ``gap_i(T) = 0`` for all locators with a damped Gauss–Newton iteration
on SE(3) (SE(2) in 2D): the derivative of ``gap_i`` along the world twist ``ν`` of the centre
of mass is the contact's normal row ``G_i`` (a gap opens at the rate ``n_i·(v + ω × r_i)``), so
each step solves ``G Δ = −g`` in the least-squares sense and retracts the pose by ``Δ``.
:func:`solve_goal` is that iteration from one start (local); :func:`find_goal` finds the located
pose from far starts — turned starts, a slide towards the locators, Gauss–Newton on the planes
of the locators' faces, then on the exact gaps — and checks it, or says why there is none
(docs/fixture-format.md).

Pins and bores locate too. A ``[[pin]]`` enters a hole of the part, a ``[[bore]]`` takes the part
(a shaft) as its pin: :func:`pin_and_hole` gives the pair at a pose, :func:`insert_contacts` their
contacts, :func:`engagement` how far the tip has entered its hole, :func:`axis_offsets_m` the
hole's axis from the pin's, :func:`bottom_gap_m` a shaft's end on its bore's bottom, and
:func:`seat_at` / :func:`seated` what the part is seated on: what the insertion planner asks of a
pose, each in one call.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from fixplan.errors import FixplanError, InfeasibleError, InputError
from fixplan.geometry import Box, Cylinder, Mesh, Polygon, Rectangle, Shape
from fixplan.geometry.pins import HoleBody, PinBody, bore_face, pin_hole_contacts, radial_play_m
from fixplan.kinematics import Contact, ContactSet, com_world, mass_matrix, numbered
from fixplan.model import (
    Bore,
    Fixture,
    Hole,
    Locator,
    Pin,
    Workpiece,
    nearest_symmetric_pose,
    require_full,
    symmetry_axes_body,
    symmetry_motions_body,
)
from fixplan.settings import DEFAULT, GoalSettings
from fixplan.spatial import Pose, exp_so3, log_so3, rot2, skew

FloatArray = NDArray[np.float64]


def locator_contact(workpiece: Workpiece, pose: Pose, locator: Locator) -> Contact:
    """The contact a locator would make with the workpiece at ``pose`` (with its gap)."""
    p_body = pose.point_body_from_world(locator.p_world)
    proj = workpiece.shape.project(p_body)
    point_world = pose.point_world_from_body(proj.point_body)
    normal_world = -(pose.R_world_body @ proj.normal_body)
    return Contact(
        name=locator.name,
        point_world=point_world,
        normal_world=normal_world,
        friction=locator.friction,
        torsion_m=locator.torsion_m,
        gap_m=proj.distance - locator.radius_m,
        kind="locator",
    )


def locator_contacts(workpiece: Workpiece, pose: Pose, locator: Locator) -> list[Contact]:
    """Every contact a locator would make with the workpiece at ``pose``, nearest first.

    A convex shape gives one (:func:`locator_contact`). A mesh part gives one per local minimum of
    the distance within ``MeshSettings.contact_band_m`` of the nearest (:meth:`Mesh.contacts`): a
    tip in a concave corner touches two faces. The first keeps the locator's name, the others are
    named ``"<locator>#2"``, ``"<locator>#3"`` ... and carry the locator in ``Contact.locator``.
    """
    shape = workpiece.shape
    if not isinstance(shape, Mesh):
        return [locator_contact(workpiece, pose, locator)]
    found = shape.contacts(pose.point_body_from_world(locator.p_world))
    found = found[:1] + [c for c in found[1:] if c.distance > 0.0]  # a face seen from behind is no contact
    several = len(found) > 1
    out = []
    for k, proj in enumerate(found):
        out.append(
            Contact(
                name=locator.name if k == 0 else f"{locator.name}#{k + 1}",
                point_world=pose.point_world_from_body(proj.point_body),
                normal_world=-(pose.R_world_body @ proj.normal_body),
                friction=locator.friction,
                torsion_m=locator.torsion_m,
                gap_m=proj.distance - locator.radius_m,
                kind="locator",
                locator=locator.name if several else None,
            )
        )
    return out


def _hole_body(workpiece: Workpiece, pose: Pose, hole: Hole) -> HoleBody:
    return HoleBody(
        pose.point_world_from_body(hole.p_body),
        pose.R_world_body @ hole.axis_body,
        0.5 * hole.diameter_m,
        hole.depth_m,
        hole.chamfer_m,
        blind=not hole.through,
    )


def peg_body(workpiece: Workpiece, pose: Pose, bore: Bore) -> PinBody:
    """The cylindrical part as a pin entering ``bore``: from its end farther out of the bore to the deeper one."""
    shape = workpiece.shape
    if not isinstance(shape, Cylinder):
        raise InputError(f"bore {bore.name}: a bore takes a cylindrical part (workpiece.shape = 'cylinder')")
    z = pose.R_world_body[:, 2]
    ends = [pose.p_world + 0.5 * shape.length * z, pose.p_world - 0.5 * shape.length * z]
    deep = [float((bore.p_world - e) @ bore.axis_world) for e in ends]
    lead = int(np.argmax(deep))
    base = ends[1 - lead]
    return PinBody(base, (ends[lead] - base) / shape.length, shape.radius, shape.length)


def pin_and_hole(workpiece: Workpiece, pose: Pose, owner: Pin | Bore) -> tuple[PinBody, HoleBody]:
    """The pin and the hole of a ``[[pin]]`` (the hole is the part's) or of a ``[[bore]]`` (the part is the pin) at ``pose``."""
    if isinstance(owner, Bore):
        bore = HoleBody(owner.p_world, owner.axis_world, 0.5 * owner.diameter_m, owner.depth_m, owner.chamfer_m, True,
                        bore_face(owner.p_world, owner.axis_world))  # fmt: skip
        return peg_body(workpiece, pose, owner), bore
    pin = PinBody(
        owner.p_world,
        owner.axis_world,
        0.5 * owner.diameter_m,
        owner.length_m,
        owner.chamfer_m,
        owner.land_direction_world,
        owner.land_width_m,
    )
    return pin, _hole_body(workpiece, pose, workpiece.hole(owner.hole))


def insert_contacts(workpiece: Workpiece, pose: Pose, owner: Pin | Bore) -> list[Contact]:
    """The contacts of a ``[[pin]]`` with its hole in the part, or of the part (a peg) with a ``[[bore]]``, at ``pose``.

    One pin-in-hole geometry (:func:`~fixplan.geometry.pins.pin_hole_contacts`) on the pair of
    :func:`pin_and_hole`. The workpiece's material point is the part's (the hole's, or the peg's);
    the normal pushes the part away from the pin, or from the bore's wall, edge or bottom. Named
    ``"<owner>"``, ``"<owner>#2"`` ... (rim, mouth, exit, bottom: those the pose makes possible).
    """
    pin, hole = pin_and_hole(workpiece, pose, owner)
    raw = pin_hole_contacts(pin, hole)
    if isinstance(owner, Bore):  # the part is the pin
        found = [
            Contact(owner.name, c.point_pin_world, -c.normal_world, owner.friction, 0.0, c.gap_m, "bore") for c in raw
        ]
    else:
        found = [
            Contact(owner.name, c.point_hole_world, c.normal_world, owner.friction, 0.0, c.gap_m, "pin") for c in raw
        ]
    return numbered(found, owner.name)


def cylinder_contacts(fixture: Fixture, pose: Pose) -> list[Contact]:
    """Every contact of the fixture's pins and bores at ``pose`` (touching or not), pin by pin."""
    owners: list[Pin | Bore] = [*fixture.pins, *fixture.bores]
    return [c for owner in owners for c in insert_contacts(fixture.workpiece, pose, owner)]


def locator_gaps(workpiece: Workpiece, pose: Pose, locators: Sequence[Locator]) -> FloatArray:
    """Signed gaps [m] of the locators at ``pose`` (negative: penetration)."""
    return np.array([locator_contact(workpiece, pose, loc).gap_m for loc in locators])


# -- pins and bores: how far each has entered ---------------------------------------------------------
@dataclass(frozen=True)
class Insert:
    """One thing that enters a hole: a pin in the part's hole, or the part (a shaft) in a bore."""

    name: str  # the pin's or the bore's name: the state element once engaged
    hole: str  # the hole's name (a bore: its own)
    kind: str  # "round", "diamond" or "bore"
    play_m: float  # radial play (D − d)/2
    capture_m: float  # play + both chamfers: the offset a chamfer still guides into the hole
    land_direction_world: FloatArray | None = None  # a diamond pin: the one direction it locates along


def inserts(fixture: Fixture) -> list[Insert]:
    """The fixture's pins (round ones first) and bores as :class:`Insert`."""
    wp = fixture.workpiece
    out = []
    for pin in sorted(fixture.pins, key=lambda p: (p.kind != "round", p.name)):
        hole = wp.hole(pin.hole)
        play = radial_play_m(hole.diameter_m, pin.diameter_m)
        out.append(
            Insert(pin.name, hole.name, pin.kind, play, play + hole.chamfer_m + pin.chamfer_m, pin.land_direction_world)
        )
    for bore in fixture.bores:
        r = float(getattr(wp.shape, "radius", 0.0))
        play = 0.5 * bore.diameter_m - r
        out.append(Insert(bore.name, bore.name, "bore", play, play + bore.chamfer_m))
    return out


def _pair(fixture: Fixture, pose: Pose, ins: Insert) -> tuple[PinBody, HoleBody]:
    """The pin and the hole of ``ins`` at ``pose`` (a bore: the part as the pin)."""
    owners: tuple[Pin | Bore, ...] = fixture.bores if ins.kind == "bore" else fixture.pins
    return pin_and_hole(fixture.workpiece, pose, next(o for o in owners if o.name == ins.name))


@dataclass(frozen=True)
class Engagement:
    """Where a pin's tip is with respect to its hole's mouth at a pose."""

    depth_m: float  # the tip past the mouth, along the hole's axis into it (< 0: still outside)
    offset_m: float  # the tip's centre from the hole's axis
    capture_m: float

    @property
    def engaged(self) -> bool:
        """The tip inside the mouth: past it, within the capture of the hole's axis."""
        return self.depth_m > 0.0 and self.offset_m <= self.capture_m


def engagement(fixture: Fixture, pose: Pose, ins: Insert) -> Engagement:
    """The tip's depth in its hole and its offset from the hole's axis at ``pose``.

    The capture is the insert's (play and chamfers) widened by what a tilt ``θ`` of the pin from the
    hole's axis brings: the tip's face (radius ``r − c_p``) then reaches ``(r − c_p) cos θ`` across
    the axis, so its centre may lie ``(r − c_p)(1 − cos θ)`` farther out with its edge still within
    the mouth (a shaft cocked in its bore, Whitney's two-point contact, has its tip's centre
    ``R − r cos θ`` off the axis), and by the contact tolerance ``touch_m``: a tip touching the wall
    (within what the engine leaves, less than a micrometre) counts as in.
    """
    pin, hole = _pair(fixture, pose, ins)
    tip = pin.base_world + pin.length_m * pin.axis_world
    r = tip - hole.mouth_world
    along = float(r @ hole.axis_world)
    cos_tilt = min(abs(float(pin.axis_world @ hole.axis_world)), 1.0)
    capture = ins.capture_m + (pin.radius_m - pin.chamfer_m) * (1.0 - cos_tilt) + fixture.tolerances.touch_m
    return Engagement(-along, float(np.linalg.norm(r - along * hole.axis_world)), capture)


def axis_offsets_m(fixture: Fixture, pose: Pose, ins: Insert) -> tuple[float, float]:
    """The hole's axis from the pin's at the mouth and at the tip, in the directions the pin locates.

    A round pin (or a bore) locates every direction normal to its axis, a diamond pin only along its
    lands: its offset across them is free by design.
    """
    pin, hole = _pair(fixture, pose, ins)
    a = pin.axis_world
    out = []
    # the pin's axis at the mouth's level and at its tip
    s_mouth = float((hole.mouth_world - pin.base_world) @ a)
    for s in (min(max(s_mouth, 0.0), pin.length_m), pin.length_m):
        q = pin.base_world + s * a
        r = q - hole.mouth_world
        r = r - float(r @ hole.axis_world) * hole.axis_world
        if ins.land_direction_world is not None:
            out.append(abs(float(r @ ins.land_direction_world)))
        else:
            out.append(float(np.linalg.norm(r)))
    return out[0], out[1]


def insertion_axis(fixture: Fixture) -> FloatArray:
    """The unit axis the part is inserted against (pins: their common axis; a bore: its axis).

    :class:`InputError` (one line) when the pins' axes differ: no single straight insertion.
    """
    named = [(f"pin.{p.name}", p.axis_world) for p in fixture.pins] + [
        (f"bore.{b.name}", b.axis_world) for b in fixture.bores
    ]
    u = np.asarray(named[0][1], dtype=float)
    tol = DEFAULT.pins.axis_angle_rad
    for key, axis in named:
        if math.acos(min(1.0, float(axis @ u))) > tol:
            raise InputError(
                f"{fixture.source}: {key}.axis: the pins' axes differ by more than {tol:g} rad "
                "(expected parallel pins: the part is inserted along one axis)"
            )
    return u


def located_pose(fixture: Fixture) -> Pose:
    """The located pose: the file's (pins), or a shaft's in its bore (coaxial, its leading end on the bottom).

    A bore alone is no full fixture of locators, and the loader takes a goal only for those: the
    shaft is turned the least from its start so that its axis lies along the bore's, its end that
    leads into the bore on the bottom ``depth_m`` below the mouth.
    """
    if fixture.goal_pose is not None:
        return fixture.goal_pose
    if not fixture.bores or fixture.pins:
        raise InputError(f"{fixture.source}: workpiece.goal: a fixture with pins needs its located pose")
    bore = fixture.bores[0]
    shape = fixture.workpiece.shape
    u = np.asarray(bore.axis_world, dtype=float)
    R0 = fixture.start.R_world_body
    z = R0[:, 2]
    lead = -1.0 if float(z @ u) >= 0.0 else 1.0  # the body end along lead·z goes in first (it points down the bore)
    want = -lead * u  # where body z must point
    axis = np.cross(z, want)
    s_, c_ = float(np.linalg.norm(axis)), float(z @ want)
    turn = np.zeros(3) if s_ == 0.0 else axis / s_ * math.atan2(s_, c_)
    R = exp_so3(turn) @ R0
    half = 0.5 * float(getattr(shape, "length", 0.0))
    centre = bore.p_world - bore.depth_m * u + half * u
    return Pose(R, centre)


def seating_side_at_start(fixture: Fixture, u: FloatArray) -> FloatArray:
    """The side a part on pins is seated toward when its file gives no located pose (unit, normal to ``u``).

    The side its first round pin's hole lies on at the start, seen from the pin's axis (the part
    stays on the side it comes from); the pin's side toward the centre of mass when the start
    has the hole on the axis; the first body axis normal to ``u`` when both are.
    """
    wp, start = fixture.workpiece, fixture.start
    pin = next((p for p in fixture.pins if p.kind == "round"), fixture.pins[0])
    hole = wp.hole(pin.hole)

    def across(point: FloatArray) -> FloatArray:
        r = point - pin.p_world
        return r - float(r @ u) * u

    tiny = DEFAULT.goal.touch_gap_m
    for r in (across(start.point_world_from_body(hole.p_body)), across(start.point_world_from_body(wp.com_body))):
        n = float(np.linalg.norm(r))
        if n > tiny:
            return r / n
    e = np.eye(3)[int(np.argmin(np.abs(u)))]
    e = e - float(e @ u) * u
    return e / float(np.linalg.norm(e))


def find_pin_goal(fixture: Fixture, settings: GoalSettings = DEFAULT.goal) -> GoalSearch:
    """The located pose of a part on pins, from its geometry (the file gives none).

    Located: every locator touches; every round pin's hole axis lies its radial play ``(D − d)/2``
    from the pin's axis toward the seating side (:func:`seating_side_at_start`), so that the pin
    touches the hole's wall; a diamond pin's hole is centred along the lands. :func:`_gauss_newton` (the
    pins' offsets as point rows of its model) from the start turned the least so that the first hole
    faces its pin, its mouth on the pin's axis. Every residual within ``touch_gap_m`` or the
    search says how far it got.
    """
    wp = fixture.workpiece
    u = insertion_axis(fixture)
    side = seating_side_at_start(fixture, u)
    pins = list(fixture.pins)
    holes = [wp.hole(p.hole) for p in pins]
    plays = [radial_play_m(h.diameter_m, p.diameter_m) for p, h in zip(pins, holes, strict=True)]

    exact = _exact_model(wp, fixture.locators)
    # each pin's rows as contacts of :func:`_gauss_newton`'s model: the offset of the hole's mouth
    # from the pin's axis along a direction e across it moves with the part as a point gap of
    # normal e at the mouth (row [e, (m - c) × e])
    across: list[tuple[int, FloatArray, float]] = []  # (pin index, direction, target offset [m])
    for i, (pin, play) in enumerate(zip(pins, plays, strict=True)):
        if pin.land_direction_world is not None:
            across.append((i, np.asarray(pin.land_direction_world, dtype=float), 0.0))
        else:
            e1 = side - float(side @ u) * u
            for e in (e1, np.cross(u, e1)):
                across.append((i, e, play * float(side @ e)))

    def model(pose: Pose) -> tuple[FloatArray, FloatArray, FloatArray]:
        gaps, points, normals = exact(pose)
        rows_g, rows_p, rows_n = [gaps], [points], [normals]
        for i, e, target in across:
            m = pose.point_world_from_body(holes[i].p_body)
            rows_g.append(np.array([float((m - pins[i].p_world) @ e) - target]))
            rows_p.append(m[None, :])
            rows_n.append(e[None, :])
        return np.concatenate(rows_g), np.vstack(rows_p), np.vstack(rows_n)

    # the first start: turned the least so that the first hole's axis points against the pin's,
    # its mouth on the pin's axis play toward the side, the pin's length in; then that start turned
    # about the pin's axis by each of ``settings.turns_deg`` (a stop the start's turn puts beyond
    # its face's edge pulls the first one astray)
    start = fixture.start
    a = start.R_world_body @ holes[0].axis_body
    want = -u
    axis = np.cross(a, want)
    s_, c_ = float(np.linalg.norm(axis)), float(a @ want)
    R0 = (exp_so3(axis / s_ * math.atan2(s_, c_)) if s_ > 0.0 else np.eye(3)) @ start.R_world_body
    mouth = pins[0].p_world + 0.5 * pins[0].length_m * u + plays[0] * side

    turns = [0.0, *(t for deg in settings.turns_deg for t in (deg, -deg))]
    least = math.inf  # the largest residual at the best start so far
    tried = 0
    for deg in turns:
        tried += 1
        R = exp_so3(u * math.radians(deg)) @ R0
        result = _gauss_newton(
            model, wp, Pose(R, mouth - R @ holes[0].p_body), tol_m=settings.stop_gap_m,
            max_iterations=settings.max_iterations, settings=settings,
        )  # fmt: skip
        worst = result.max_gap_m
        if result.converged:
            return GoalSearch(True, result.pose, worst, result.rank, tried)
        least = min(least, worst)
    worst = least
    reason = (
        f"no located pose found with the pins (every locator touching, each round pin against its hole's wall "
        f"toward the side the part starts on): largest residual {worst:.3g} m at the best of {tried} starts; "
        "give workpiece.goal (the located pose)"
    )
    return GoalSearch(False, None, worst, 0, tried, reason)


def bottom_gap_m(fixture: Fixture, pose: Pose, bore: Bore) -> float:
    """The gap of the shaft's leading end face on the bore's (flat) bottom, in closed form.

    The face's deepest point lies ``r sin φ`` beyond its centre along the bore's axis (``φ`` the
    angle between the shaft's and the bore's axes): gap ``depth − (d_E + r sin φ)``, ``d_E`` the
    centre's depth below the mouth.
    """
    pin = peg_body(fixture.workpiece, pose, bore)
    u = np.asarray(bore.axis_world, dtype=float)
    end = pin.base_world + pin.length_m * pin.axis_world
    d_end = float((bore.p_world - end) @ u)
    c = min(abs(float(pin.axis_world @ u)), 1.0)
    return bore.depth_m - (d_end + pin.radius_m * math.sqrt(max(1.0 - c * c, 0.0)))


def seat_gaps_m(fixture: Fixture, pose: Pose) -> dict[str, float]:
    """The gap [m] of every rest and of every bore's bottom (``"<bore>.bottom"``) at ``pose``: what closes as the part seats."""
    locators = fixture.locators
    gaps = dict(
        zip([loc.name for loc in locators], map(float, locator_gaps(fixture.workpiece, pose, locators)), strict=True)
    )
    for b in fixture.bores:
        gaps[f"{b.name}.bottom"] = bottom_gap_m(fixture, pose, b)
    return gaps


def seated(fixture: Fixture, pose: Pose) -> bool:
    """Every rest (and every bore's bottom) touching at ``pose``."""
    tol = fixture.tolerances.touch_m
    return all(abs(g) <= tol for g in seat_gaps_m(fixture, pose).values())


# a contact whose normal is at most this cosine from the insertion axis faces across it (a pin's side,
# a stop), not along it (a rest): the descent along the axis does not close it
_ACROSS_COS = 0.5


@dataclass(frozen=True)
class Seat:
    """What the part sits on at a pose, the side it is seated toward, and the stops it is pressed into."""

    contacts: ContactSet  # every rest, pin and bore touching
    side_world: FloatArray  # unit, normal to the insertion axis, toward the round pin's contact; zero when none touches
    at_world: FloatArray  # where it is pressed: the mean of those contacts' points (the centre of mass when none)
    # the touching locators whose normal lies across the axis (a stop taking the turn about a round pin):
    # the descent does not close them, a push across the axis does
    stops: tuple[Contact, ...] = ()

    @property
    def stop_names(self) -> tuple[str, ...]:
        """The stops' locators, each once, in the file's order."""
        return tuple(dict.fromkeys(c.owner for c in self.stops))


def seat_at(fixture: Fixture, pose: Pose, u: FloatArray) -> Seat:
    """The rests', pins' and bores' touching contacts at ``pose``, the side the round pin (or bore) seats the part toward, and the stops.

    The side is the sum of the first round pin's touching contact normals across ``u`` (they push
    the part away from the pin), reversed; it is pressed at the mean of those contacts' points. A
    stop is a touching locator whose normal lies across ``u`` (``|n·u| < 0.5``): moving along the
    axis does not close it.
    """
    round_first = [i.name for i in inserts(fixture) if i.kind != "diamond"]
    names = [loc.name for loc in fixture.locators] + [p.name for p in fixture.pins] + [b.name for b in fixture.bores]
    cs = contact_set(fixture, pose, names).touching(fixture.tolerances.touch_m)
    stops = tuple(c for c in cs.contacts if c.kind == "locator" and abs(float(c.normal_world @ u)) < _ACROSS_COS)
    for owner in round_first:
        side = [c for c in cs.contacts if c.owner == owner and abs(float(c.normal_world @ u)) < _ACROSS_COS]
        n = sum((c.normal_world for c in side), np.zeros(3))
        n = n - float(n @ u) * u
        norm = float(np.linalg.norm(n))
        if norm > 0.0:
            return Seat(cs, -n / norm, np.mean([c.point_world for c in side], axis=0), stops)
    return Seat(cs, np.zeros(3), pose.point_world_from_body(fixture.workpiece.com_body), stops)


def start_state(fixture: Fixture, kinds: Sequence[str] = ("locator",)) -> frozenset[str]:
    """Who touches the part at its start pose: the locators (``kinds``: also ``"pin"``, ``"bore"``).

    Every plan's sequence starts here; a part in free space starts in the empty state.
    """
    touching = contact_set(fixture, "start")
    return frozenset(c.owner for c in touching.contacts if c.kind in kinds)


def contact_set(
    fixture: Fixture,
    pose: Pose | str | None = None,
    names: Sequence[str] | None = None,
) -> ContactSet:
    """The contacts of ``fixture`` at ``pose`` (default: the start pose).

    Parameters
    ----------
    pose : Pose or "start" or "goal", optional
        Configuration of the workpiece. Explicit ``[[contact]]`` entries are given at the start
        pose and are used as they are.
    names : sequence of str, optional
        Contacts to use, by locator, pin, bore or contact name, in this order; each brings every
        contact it makes at ``pose``. A named locator that does not touch is used all the same (a
        hypothetical contact state; its gap is reported). Default: the locators, pins and bores
        touching at ``pose`` plus every explicit contact.
    """
    if pose is None or pose == "start":
        pose = fixture.start
    elif pose == "goal":
        pose = fixture.goal
    if not isinstance(pose, Pose):
        raise InputError(f"pose must be 'start', 'goal' or a Pose, got {pose!r}")
    wp = fixture.workpiece
    locators = {loc.name: loc for loc in fixture.locators}
    explicits = {c.name: c for c in fixture.contacts}
    cylinders: list[Pin | Bore] = [*fixture.pins, *fixture.bores]
    owners = {o.name: o for o in cylinders}
    if names is None:
        wanted: Sequence[str] = [*locators, *explicits, *owners]
    else:
        known = dict.fromkeys([*locators, *explicits, *owners])
        unknown = [n for n in names if n not in known]
        if unknown:
            raise InputError(f"unknown contact {unknown[0]!r} (known: {', '.join(known)})")
        if len(set(names)) != len(names):
            raise InputError(f"contact names repeat: {', '.join(names)}")
        wanted = names
    # one path for both: every contact of each wanted name (a mesh's locator in a concave corner
    # has several, a pin its rim and wall); an explicit contact wins over a locator of its name
    chosen: list[Contact] = []
    for n in wanted:
        if n in explicits:
            e = explicits[n]
            chosen.append(Contact(e.name, e.point_world, e.normal_world, e.friction, e.torsion_m, 0.0, "explicit"))
        elif n in locators:
            chosen += locator_contacts(wp, pose, locators[n])
        else:
            chosen += insert_contacts(wp, pose, owners[n])
    if names is None:  # those touching, and every explicit contact
        tol = fixture.tolerances.touch_m
        chosen = [c for c in chosen if c.kind == "explicit" or c.gap_m <= tol]
    c = com_world(pose, wp.com_body)
    M = mass_matrix(wp.mass_kg, wp.inertia_body, pose.R_world_body)
    return ContactSet(tuple(chosen), c, M, pose.p_world.copy())


# -- the located pose --------------------------------------------------------------------------------
# A contact model gives every locator's gap, contact point and inward normal (world) at a pose: the
# exact one (the shape's signed distance), or one where each locator touches the plane of a named
# face (a cylinder's side: the side's surface), which Gauss–Newton follows well from far away.
ContactModel = Callable[[Pose], tuple[FloatArray, FloatArray, FloatArray]]


def _exact_model(workpiece: Workpiece, locators: Sequence[Locator]) -> ContactModel:
    shape = workpiece.shape
    if isinstance(shape, Box | Rectangle):
        return _box_model(shape.half, locators)
    tips = [(loc.p_world, loc.radius_m) for loc in locators]

    def model(pose: Pose) -> tuple[FloatArray, FloatArray, FloatArray]:
        projections = [(shape.project(pose.point_body_from_world(p)), rho) for p, rho in tips]
        gaps = np.array([proj.distance - rho for proj, rho in projections])
        points_body = np.array([proj.point_body for proj, _ in projections]).reshape(len(tips), -1)
        normals_body = np.array([proj.normal_body for proj, _ in projections]).reshape(len(tips), -1)
        return gaps, points_body @ pose.R_world_body.T + pose.p_world, -(normals_body @ pose.R_world_body.T)

    return model


def _box_model(half: FloatArray, locators: Sequence[Locator]) -> ContactModel:
    """The exact model of a box (rectangle), every locator at once: :meth:`Box.project` row by row."""
    P_world = np.array([loc.p_world for loc in locators]).reshape(len(locators), -1)
    radii = np.array([loc.radius_m for loc in locators])
    rows = np.arange(len(locators))
    outside_from = 1e-12 * float(half.max())  # as in the shape's projection

    def model(pose: Pose) -> tuple[FloatArray, FloatArray, FloatArray]:
        R = pose.R_world_body
        P = (P_world - pose.p_world) @ R
        q = np.abs(P) - half
        sign = np.where(P >= 0.0, 1.0, -1.0)
        outside = np.maximum(q, 0.0)
        n_out = np.sqrt(np.einsum("ij,ij->i", outside, outside))
        out = n_out > outside_from
        k = np.argmax(q, axis=1)
        points = P.copy()
        points[rows, k] = sign[rows, k] * half[k]
        normals = np.zeros_like(P)
        normals[rows, k] = sign[rows, k]
        dist = q[rows, k]
        if np.any(out):
            points[out] = np.clip(P[out], -half, half)
            normals[out] = sign[out] * outside[out] / n_out[out, None]
            dist = np.where(out, n_out, dist)
        return dist - radii, points @ R.T + pose.p_world, -(normals @ R.T)

    return model


def named_faces(shape: Shape) -> tuple[str, ...]:
    """The faces a locator may name (``face = "-z"``): a box's and a rectangle's sides, a cylinder's ends and side."""
    if isinstance(shape, Box):
        return ("+x", "-x", "+y", "-y", "+z", "-z")
    if isinstance(shape, Rectangle):
        return ("+x", "-x", "+y", "-y")
    if isinstance(shape, Cylinder):
        return ("+z", "-z", "side")
    return ()


def _face_axis(shape: Shape, face: str) -> tuple[int, float, float]:
    """A planar face's body axis, its sign and its distance from the body origin [m]."""
    k = "xyz".index(face[1])
    sign = 1.0 if face[0] == "+" else -1.0
    if isinstance(shape, Cylinder):
        return k, sign, shape.length / 2.0
    if not isinstance(shape, Box | Rectangle):
        raise FixplanError(f"a {type(shape).__name__} has no planar face {face!r}")
    return k, sign, float(shape.half[k])


def _face_normal_body(shape: Shape, face: str, point_body: FloatArray) -> FloatArray:
    """The outward normal of ``face`` at a point on it (body axes)."""
    if face == "side":
        radial = np.array([point_body[0], point_body[1], 0.0])
        return radial / max(float(np.linalg.norm(radial)), 1e-300)
    k, sign, _ = _face_axis(shape, face)
    normal = np.zeros(shape.dimension)
    normal[k] = sign
    return normal


def _face_model(workpiece: Workpiece, locators: Sequence[Locator], faces: Sequence[str]) -> ContactModel:
    """Each locator touching the plane of its face (a cylinder's side: the infinite side)."""
    shape = workpiece.shape
    d = shape.dimension
    rows = []
    for loc, face in zip(locators, faces, strict=True):
        if face == "side":
            if not isinstance(shape, Cylinder):
                raise FixplanError(f"a {type(shape).__name__} has no side face")
            rows.append((loc.p_world, loc.radius_m, -1, 1.0, shape.radius))
        else:
            k, sign, offset = _face_axis(shape, face)
            rows.append((loc.p_world, loc.radius_m, k, sign, offset))

    def model(pose: Pose) -> tuple[FloatArray, FloatArray, FloatArray]:
        gaps = np.empty(len(rows))
        points = np.empty((len(rows), d))
        normals = np.empty((len(rows), d))
        for i, (p_world, rho, k, sign, offset) in enumerate(rows):
            q = pose.point_body_from_world(p_world)
            if k < 0:  # the cylinder's side: radial
                u = np.array([q[0], q[1], 0.0])
                u /= max(float(np.linalg.norm(u)), 1e-300)
            else:
                u = np.zeros(d)
                u[k] = sign
            dist = float(u @ q) - offset
            gaps[i] = dist - rho
            points[i] = pose.point_world_from_body(q - dist * u)
            normals[i] = -(pose.R_world_body @ u)
        return gaps, points, normals

    return model


@dataclass(frozen=True)
class GoalResult:
    """The pose one Gauss–Newton run reaches and how well every locator touches there."""

    pose: Pose
    max_gap_m: float  # largest |gap| over the locators at ``pose``
    iterations: int
    rank: int  # rank of G at the goal: 6 (3D) / 3 (2D) for a deterministic location
    converged: bool


def _gauss_newton(
    model: ContactModel,
    workpiece: Workpiece,
    start: Pose,
    *,
    tol_m: float,
    max_iterations: int,
    translation_only: bool = False,
    settings: GoalSettings = DEFAULT.goal,
) -> GoalResult:
    """Damped Gauss–Newton on ``model``'s gaps from ``start`` (see the module docstring)."""
    pose = start
    d = start.dimension
    scale = max(workpiece.shape.bounding_radius, 1e-9)

    def residual(p: Pose) -> tuple[FloatArray, FloatArray]:
        gaps, points, n = model(p)
        # the normal rows [n, r × n] of the contact Jacobians (written out: np.cross per row is slow)
        r = points - com_world(p, workpiece.com_body)
        if d == 2:
            moment = (r[:, 0] * n[:, 1] - r[:, 1] * n[:, 0])[:, None]
        else:
            moment = np.cross(r, n)
        return gaps, np.hstack([n, moment])

    gaps, G = residual(pose)
    it = 0
    for it in range(1, max_iterations + 1):  # noqa: B007 - used after the loop
        if len(gaps) == 0 or np.max(np.abs(gaps)) <= tol_m:
            break
        step: FloatArray = np.zeros(G.shape[1])
        if translation_only:
            step[:d] = -np.linalg.lstsq(G[:, :d], gaps, rcond=DEFAULT.numerics.rcond)[0]
        else:
            step[:] = -np.linalg.lstsq(G, gaps, rcond=DEFAULT.numerics.rcond)[0]
        # Limit rotations per step to keep far starts on the right faces.
        ang = float(np.linalg.norm(step[d:]))
        lin = float(np.linalg.norm(step[:d]))
        limit = max(ang / settings.max_turn_rad, lin / (settings.max_shift_rel * scale), 1.0)
        step /= limit
        f0 = float(gaps @ gaps)
        alpha = 1.0
        while True:
            trial = pose.retract(alpha * step, workpiece.com_body)
            g_trial = model(trial)[0]
            if float(g_trial @ g_trial) < f0 or alpha < DEFAULT.numerics.line_search_min_step:
                break
            alpha /= 2.0
        f1 = float(g_trial @ g_trial)
        if not f1 < f0:
            break  # no step decreases the gaps: a least-squares minimum, not a pose touching every locator
        pose = trial
        gaps, G = residual(pose)
        if f1 > (1.0 - DEFAULT.numerics.stall_rel) * f0 and f1 > tol_m**2:
            break  # stalled at a least-squares minimum (more locators than the pose can satisfy)
    max_gap = float(np.max(np.abs(gaps))) if len(gaps) else 0.0
    rank = int(np.linalg.matrix_rank(G, tol=DEFAULT.numerics.rank_tol)) if len(gaps) else 0
    return GoalResult(pose, max_gap, it, rank, converged=max_gap <= max(tol_m, settings.touch_gap_m))


def solve_goal(
    workpiece: Workpiece,
    locators: Sequence[Locator],
    start: Pose,
    *,
    tol_m: float = DEFAULT.goal.stop_gap_m,
    max_iterations: int = DEFAULT.goal.max_iterations,
) -> GoalResult:
    """Damped Gauss–Newton from ``start`` for a nearby pose where every locator touches (local).

    The exact gaps; no check of faces. :func:`find_goal` finds the located pose from far starts.
    """
    return _gauss_newton(
        _exact_model(workpiece, locators), workpiece, start, tol_m=tol_m, max_iterations=max_iterations
    )


@dataclass(frozen=True)
class GoalSearch:
    """The located pose found from a start by :func:`find_goal`, or why there is none.

    Attributes
    ----------
    found : bool
        A pose touches every locator (each |gap| ≤ ``GoalSettings.touch_gap_m``, none penetrating)
        from outside, every locator that names a face on that face.
    pose : Pose or None
        The located pose (the nearest to the start, in the mass-weighted metric, of those found).
    max_gap_m : float
        Largest |gap| at ``pose``, or at the best pose reached when none was found [m].
    rank : int
        Rank of ``G`` at ``pose`` (6 in 3D, 3 in 2D: the locators determine the pose).
    starts : int
        Starts tried: 1 when Gauss–Newton from the start pose found it.
    reason : str
        Why there is no located pose (empty when found): a proof when ``proven``, else that the
        search did not converge.
    proven : bool
        ``reason`` proves that no pose touches every locator.
    face_mismatches : tuple of (str, str)
        When a pose touches every locator but not on the faces the locators name: each such
        locator's name and what it touches there (``face '+z'``, ``the edge of face '-z'``).
    """

    found: bool
    pose: Pose | None
    max_gap_m: float
    rank: int
    starts: int
    reason: str = ""
    proven: bool = False
    face_mismatches: tuple[tuple[str, str], ...] = ()

    @property
    def message(self) -> str:
        """One line for people: why no pose is located (empty when found)."""
        if self.found:
            return ""
        if self.proven:
            return f"no pose touches every locator: {self.reason}"
        if self.face_mismatches:
            touched = ", ".join(f"{name} touches {what}" for name, what in self.face_mismatches)
            return f"at the located pose {touched}, not the face named"
        return self.reason


def _diameter(shape: Shape) -> float:
    """The largest distance between two points of the shape [m] (an upper bound for unknown shapes)."""
    if isinstance(shape, Polygon):
        V = shape.array
        return float(np.max(np.linalg.norm(V[:, None, :] - V[None, :, :], axis=2)))
    if isinstance(shape, Box | Rectangle):
        return 2.0 * float(np.linalg.norm(shape.half))
    if isinstance(shape, Cylinder):
        return 2.0 * float(np.hypot(shape.radius, shape.length / 2.0))
    return 2.0 * shape.bounding_radius


def _face_width(shape: Shape, face: str) -> float | None:
    """The largest distance between two points of a planar face [m] (None: not planar)."""
    if face == "side":
        return None
    if isinstance(shape, Cylinder):
        return 2.0 * shape.radius
    if not isinstance(shape, Box | Rectangle):
        raise FixplanError(f"a {type(shape).__name__} has no planar face {face!r}")
    k, _, _ = _face_axis(shape, face)
    others = np.delete(np.asarray(shape.size, dtype=float), k)
    return float(np.linalg.norm(others))


def no_pose_proof(workpiece: Workpiece, locators: Sequence[Locator], settings: GoalSettings = DEFAULT.goal) -> str:
    """Why no pose can touch every locator, proved from distances alone; empty when no proof is found.

    Two tips farther apart than the part is wide plus their radii; two tips on opposite faces
    closer than the faces are apart plus their radii; two tips on one face farther apart than
    the face is wide; tips of one radius on one plane face not on one plane (a line in 2D).
    """
    shape = workpiece.shape
    slack = 2.0 * settings.touch_gap_m
    width = _diameter(shape)
    for i, a in enumerate(locators):
        for b in locators[i + 1 :]:
            dist = float(np.linalg.norm(a.p_world - b.p_world))
            radii = a.radius_m + b.radius_m
            if dist > width + radii + slack:
                return (
                    f"{a.name} and {b.name} are {dist:.4g} m apart, more than the part's width {width:.4g} m "
                    f"plus their tip radii {radii:.4g} m"
                )
            if a.face is None or b.face is None or "side" in (a.face, b.face):
                continue
            ka, sa, ha = _face_axis(shape, a.face)
            kb, sb, hb = _face_axis(shape, b.face)
            if ka == kb and sa != sb and dist < ha + hb + radii - slack:
                return (
                    f"{a.name} on face {a.face} and {b.name} on face {b.face} are {dist:.4g} m apart, less than "
                    f"the {ha + hb:.4g} m between these faces plus their tip radii {radii:.4g} m"
                )
            face_width = _face_width(shape, a.face)
            if a.face == b.face and face_width is not None:
                reach = float(np.hypot(face_width, a.radius_m - b.radius_m))
                if dist > reach + slack:
                    return (
                        f"{a.name} and {b.name} on face {a.face} are {dist:.4g} m apart, more than the face is "
                        f"wide ({face_width:.4g} m)"
                    )
    d = shape.dimension
    for face in named_faces(shape):
        on = [loc for loc in locators if loc.face == face]
        if face == "side" or len(on) <= d or len({loc.radius_m for loc in on}) != 1:
            continue
        P = np.array([loc.p_world for loc in on])
        centred = P - P.mean(axis=0)
        normal = np.linalg.svd(centred)[2][-1]  # of the best plane (line in 2D) through the tips
        off = float(np.max(np.abs(centred @ normal)))
        if off > slack:
            where = "one plane" if d == 3 else "one line"
            return (
                f"{', '.join(loc.name for loc in on)} on face {face} are not on {where} ({off:.3g} m off the best one)"
            )
    return ""


def _symmetry_turns(d: int) -> list[FloatArray]:
    """The rotations mapping a box (rectangle) onto itself, but the identity: 23 in 3D, 3 in 2D."""
    if d == 2:
        return [rot2(np.pi / 2.0 * k) for k in (1, 2, 3)]
    out = []
    for perm in itertools.permutations(range(3)):
        for signs in itertools.product((1.0, -1.0), repeat=3):
            R = np.zeros((3, 3))
            for row, (col, s) in enumerate(zip(perm, signs, strict=True)):
                R[row, col] = s
            if np.linalg.det(R) > 0.0 and not np.array_equal(R, np.eye(3)):
                out.append(R)
    return out


def _turn_rings(d: int, settings: GoalSettings) -> list[list[FloatArray]]:
    """The wider search's body-frame turns of the start, in rings of growing angle."""
    rings: list[list[FloatArray]] = [[np.eye(d)]]
    for deg in settings.turns_deg:
        a = np.radians(deg)
        if d == 2:
            rings.append([rot2(a), rot2(-a)])
        else:
            rings.append([exp_so3(s * a * axis) for axis in np.eye(3) for s in (1.0, -1.0)])
    rings.append(_symmetry_turns(d))
    return rings


def _distance2(workpiece: Workpiece, a: Pose, b: Pose) -> float:
    """Squared mass-weighted distance from ``a`` to ``b``: ``ξᵀ M ξ``, ξ the twist of the centre of mass [kg·m²]."""
    dc = com_world(b, workpiece.com_body) - com_world(a, workpiece.com_body)
    if a.dimension == 3:
        turn = log_so3(b.R_world_body @ a.R_world_body.T)
    else:
        turn = np.array([(b.angle_rad - a.angle_rad + np.pi) % (2.0 * np.pi) - np.pi])
    xi = np.concatenate([dc, turn])
    return float(xi @ mass_matrix(workpiece.mass_kg, workpiece.inertia_body, a.R_world_body) @ xi)


def _face_mismatches(
    workpiece: Workpiece, locators: Sequence[Locator], pose: Pose, settings: GoalSettings
) -> tuple[tuple[str, str], ...]:
    """Locators naming a face they do not touch at ``pose`` from outside, with what they touch.

    On its face a locator's contact normal is the face's; a round tip against an edge or a
    corner pushes along a normal between the faces that meet there (named in the answer).
    """
    shape = workpiece.shape
    out = []
    for loc in locators:
        if loc.face is None:
            continue
        proj = shape.project(pose.point_body_from_world(loc.p_world))
        cosines = {
            f: float(proj.normal_body @ _face_normal_body(shape, f, proj.point_body)) for f in named_faces(shape)
        }
        on = [f for f, c in cosines.items() if c >= settings.face_normal_cos]
        if on == [loc.face]:
            continue
        if on:
            out.append((loc.name, f"face {on[0]!r}"))
        else:
            near = [f for f, c in cosines.items() if c > DEFAULT.numerics.zero_rel]  # in named_faces' order
            where = "the edge" if len(near) == 2 else "the corner" if len(near) == 3 else "the rim"
            out.append((loc.name, f"{where} between faces {' and '.join(repr(f) for f in near)}"))
    return tuple(out)


def _beyond_faces(
    shape: Shape, locators: Sequence[Locator], faces: Sequence[str], pose: Pose
) -> list[tuple[str, str, float]]:
    """Locators whose touch point on their face's plane lies outside the face at ``pose``: (name, face, by [m]).

    Box and rectangle faces only (a cylinder's ends and side: none); the largest overshoot first.
    """
    if not isinstance(shape, Box | Rectangle):
        return []
    half = np.asarray(shape.half, dtype=float)
    out = []
    for loc, face in zip(locators, faces, strict=True):
        k = "xyz".index(face[1])
        q = pose.point_body_from_world(loc.p_world)
        excess = max(float(abs(q[j]) - half[j]) for j in range(half.shape[0]) if j != k)
        if excess > DEFAULT.goal.touch_gap_m:
            out.append((loc.name, face, excess))
    return sorted(out, key=lambda item: -item[2])


def _faces_touched(shape: Shape, locators: Sequence[Locator], pose: Pose) -> list[str | None]:
    """The face of the part nearest each locator at ``pose`` (None on a shape without named faces)."""
    return [shape.face_of(shape.project(pose.point_body_from_world(loc.p_world)).point_body) for loc in locators]


def find_goal(
    workpiece: Workpiece, locators: Sequence[Locator], start: Pose, settings: GoalSettings = DEFAULT.goal
) -> GoalSearch:
    """The located pose, where every locator touches, from any start; deterministic.

    1. Gauss–Newton on the exact gaps from the start (the common case: one start).
    2. Else starts turned about the body axes by ``settings.turns_deg`` and by the part's
       symmetry turns, ring by ring. From each start the part first slides (translation only)
       towards the locators; on a shape with named faces (box, rectangle, cylinder) each locator
       then touches the plane of its face (``face``, else the face it is nearest there; from the
       start pose itself also the face it is nearest at the start) — Gauss–Newton on plane gaps
       is well behaved from far away — and the exact gaps polish the pose.
    3. A pose counts when every exact |gap| ≤ ``settings.touch_gap_m`` (no penetration) and each
       locator that names a face touches that face from outside (its contact normal is the
       face's). Of those found, the answer has the fewest locators without ``face`` touching
       another face than the one they are nearest at the start, then is nearest the start in
       the mass-weighted metric, then came from the earlier start. The search stops after the
       first ring (or the first run) that found a pose with every locator on the face it is
       nearest at the start.

    Without a located pose the answer says why: :func:`no_pose_proof`'s proof, the faces the
    locators touch instead of those they name, or that the search did not converge.
    """
    proof = no_pose_proof(workpiece, locators, settings)
    if proof:
        return GoalSearch(False, None, float("inf"), 0, 0, proof, proven=True)
    shape = workpiece.shape
    faces = named_faces(shape)
    exact = _exact_model(workpiece, locators)
    iterations = {"tol_m": settings.stop_gap_m, "max_iterations": settings.max_iterations, "settings": settings}
    seen = _faces_touched(shape, locators, start)  # each locator's face as the start shows it
    free = [i for i, loc in enumerate(locators) if loc.face is None and seen[i] is not None]
    Key = tuple[int, int, float, int]
    # a located pose determines the part: of several, one where G has the rank the locators can
    # give (a trapezoid's B1 and S touching one slanted edge also close every gap, at rank 2 of 3)
    full_rank = min(len(locators), 6 if start.dimension == 3 else 3)
    found: list[tuple[Key, GoalResult]] = []
    touching: list[tuple[Key, GoalResult, tuple[tuple[str, str], ...]]] = []
    # where every locator touches the plane of its face but some lie beyond the face's edges
    # (the least overshoot first): why the exact gaps cannot all close there
    off_faces: list[tuple[str, str, float]] = []
    best: list[GoalResult] = []

    def consider(result: GoalResult, order: int) -> None:
        if not best or result.max_gap_m < best[0].max_gap_m:
            best[:] = [result]
        if not result.converged:
            return
        touched = _faces_touched(shape, locators, result.pose)
        key = (
            full_rank - result.rank,
            sum(touched[i] != seen[i] for i in free),
            _distance2(workpiece, start, result.pose),
            order,
        )
        mismatched = _face_mismatches(workpiece, locators, result.pose, settings)
        if mismatched:
            touching.append((key, result, mismatched))
        else:
            found.append((key, result))

    def answer(tried: int) -> GoalSearch:
        key, result = min(found, key=lambda item: item[0])
        return GoalSearch(True, result.pose, result.max_gap_m, result.rank, tried)

    consider(_gauss_newton(exact, workpiece, start, **iterations), 0)  # type: ignore[arg-type]
    if found and min(key[:2] for key, _ in found) == (0, 0):
        return answer(1)
    iterations["max_iterations"] = settings.search_iterations
    d = start.dimension
    c_start = com_world(start, workpiece.com_body)
    tried = 1
    for ring_index, ring in enumerate(_turn_rings(d, settings)):
        for turn in ring:
            tried += 1
            R = start.R_world_body @ turn
            candidate = Pose(R, c_start - R @ workpiece.com_body)
            slid = _gauss_newton(exact, workpiece, candidate, translation_only=True, **iterations).pose  # type: ignore[arg-type]
            assignments: list[list[str]] = []
            if faces:
                at_slid = _faces_touched(shape, locators, slid)
                assignments.append([loc.face or at_slid[i] or faces[0] for i, loc in enumerate(locators)])
                if ring_index == 0:
                    at_start = [loc.face or seen[i] or faces[0] for i, loc in enumerate(locators)]
                    if at_start != assignments[0]:
                        assignments.append(at_start)
            for named in assignments:
                planes = _face_model(workpiece, locators, named)
                on_planes = _gauss_newton(planes, workpiece, slid, **iterations)  # type: ignore[arg-type]
                pose = on_planes.pose
                if on_planes.converged:
                    beyond = _beyond_faces(shape, locators, named, pose)
                    if beyond and (not off_faces or beyond[0][2] < off_faces[0][2]):
                        off_faces[:] = beyond
                consider(_gauss_newton(exact, workpiece, pose, **iterations), tried)  # type: ignore[arg-type]
            if not faces:
                consider(_gauss_newton(exact, workpiece, slid, **iterations), tried)  # type: ignore[arg-type]
        if found and min(key[0] for key, _ in found) == 0:
            return answer(tried)
    if found:  # only the first run's, or only rank-deficient poses
        return answer(tried)
    if touching:
        _, result, mismatched = min(touching, key=lambda item: item[0])
        return GoalSearch(False, result.pose, result.max_gap_m, result.rank, tried, face_mismatches=mismatched)
    if off_faces:
        where = ", ".join(
            f"{name} lies {out * 1e3:.3g} mm beyond the edge of face {face!r}" for name, face, out in off_faces
        )
        reason = (
            f"no pose touches every locator on its face: where each touches its face's plane, {where} "
            f"(of {tried} starts, the least overshoot); move the locator inward or name another face"
        )
        return GoalSearch(False, None, best[0].max_gap_m, best[0].rank, tried, reason, proven=False)
    reason = (
        f"goal finding did not converge from {tried} starts (largest gap {best[0].max_gap_m:.3g} m at the best); "
        "give workpiece.goal (the located pose)"
    )
    return GoalSearch(False, None, best[0].max_gap_m, best[0].rank, tried, reason)


# -- motions the locators leave free ------------------------------------------------------------------
def free_motions_at(fixture: Fixture, pose: Pose) -> FloatArray:
    """The twists that keep every locator's gap at ``pose`` to first order: the null space of ``G``.

    ``G`` is every locator's normal row at ``pose`` (touching or not); the answer is ``(k, ndof)``
    orthonormal rows, world axes, twists of the centre of mass; ``k = ndof − rank G`` (singular
    values at most ``NumericsSettings.rank_tol`` count as zero, as in :func:`fixplan.summary.goal_rank`).
    """
    ndof = fixture.ndof
    names = [loc.name for loc in fixture.locators]
    if not names:
        return np.eye(ndof)
    G = contact_set(fixture, pose, names).G
    if not np.all(np.isfinite(G)):
        return np.eye(ndof)
    _, sv, vh = np.linalg.svd(G)
    rank = int(np.sum(sv > DEFAULT.numerics.rank_tol))
    return np.ascontiguousarray(vh[rank:])


def _orthonormal_rows(rows: FloatArray) -> FloatArray:
    """Orthonormal rows spanning ``rows`` (independent), each turned to point along its original."""
    q, r = np.linalg.qr(np.asarray(rows, dtype=float).T)
    return np.ascontiguousarray((q * np.where(np.diag(r) < 0.0, -1.0, 1.0)).T)


def _spans(rows: FloatArray, within: FloatArray) -> bool:
    """Whether every row of ``rows`` lies in the span of ``within`` (orthonormal rows)."""
    if len(rows) == 0:
        return True
    rest = rows - (rows @ within.T) @ within
    return float(np.max(np.abs(rest), initial=0.0)) <= DEFAULT.numerics.zero_rel * max(1.0, float(np.max(np.abs(rows))))


def _direction_text(u: FloatArray) -> str:
    """``x`` for a world axis, else the unit vector (sign: largest component positive)."""
    u = u / np.linalg.norm(u)
    u = np.where(np.abs(u) <= DEFAULT.numerics.zero_rel, 0.0, u)
    k = int(np.argmax(np.abs(u)))
    u = u if u[k] > 0 else -u
    if abs(u[k]) > 1.0 - DEFAULT.numerics.zero_rel:
        return "xyz"[k]
    return "(" + ", ".join(f"{x:.3g}" for x in u) + ")"


def _point_text(p: FloatArray, scale_m: float) -> str:
    """``(0.04, 0, 0.05) m``: a point, components below round-off of the part's size shown as 0."""
    q = np.where(np.abs(p) <= DEFAULT.numerics.zero_rel * scale_m, 0.0, p)
    return "(" + ", ".join(f"{x:.3g}" for x in q) + ") m"


def _translations_text(T: FloatArray, d: int) -> str:
    """The translations spanned by the rows of ``T`` (orthonormal, ``(k, d)``), for people."""
    if len(T) == d:
        return "every translation"
    if len(T) == 1:
        return f"translation along {_direction_text(T[0])}"
    normal = np.cross(T[0], T[1])  # 3D, two of three: the plane normal to the one that is held
    k = int(np.argmax(np.abs(normal)))
    if abs(normal[k]) > 1.0 - DEFAULT.numerics.zero_rel:
        return f"translation in the {'xyz'.replace('xyz'[k], '')[0]}-{'xyz'.replace('xyz'[k], '')[1]} plane"
    return f"translation normal to {_direction_text(normal)}"


def _common_point(turns: FloatArray, d: int, c: FloatArray) -> FloatArray | None:
    """The point every row of ``turns`` (3D twists of the centre ``c``) turns about, if there is one.

    A turn ``ω`` about a point ``p`` moves ``c`` at ``v = ω × (c − p)``: ``p − c`` solves
    ``−[ω]× (p − c) = v`` for every row at once, or there is no common point (None).
    """
    if d != 3:
        return None
    A = np.vstack([-skew(t[3:]) for t in turns])
    b = np.concatenate([t[:3] for t in turns])
    x = np.linalg.lstsq(A, b, rcond=DEFAULT.numerics.rcond)[0]
    if float(np.linalg.norm(A @ x - b)) > DEFAULT.numerics.zero_rel * max(1.0, float(np.linalg.norm(b))):
        return None
    return np.asarray(c + x)


def describe_motions(fixture: Fixture, pose: Pose, free_world: FloatArray) -> str:
    """The motions ``free_world`` (rows: world twists of the centre of mass) spans, for people.

    The part's symmetry first (``the spin about the cylinder's axis``), then translations
    (``translation along x``), then rotations about an axis (``rotation about an axis along y
    through (0, 0, 0.05) m``; a screw motion with its pitch).
    """
    d = fixture.dimension
    if len(free_world) == fixture.ndof:
        return "every motion (no locator constrains the part)"
    parts: list[str] = []
    rest = np.asarray(free_world, dtype=float).reshape(-1, fixture.ndof)
    sym = symmetry_motions_body(fixture.workpiece)
    if len(sym):
        sym_world = replace(fixture, free_motions_body=sym).free_motions_world(pose)
        sym_world = _orthonormal_rows(sym_world)
        if _spans(sym_world, rest):
            shape = fixture.workpiece.shape.name
            parts.append(
                f"the spin about the {shape}'s axis"
                if len(symmetry_axes_body(fixture.workpiece.shape)) == 1
                else f"every turn of the {shape} about its centre"
            )
            rest = rest - (rest @ sym_world.T) @ sym_world
            u, sv, vh = np.linalg.svd(rest)
            rest = vh[: int(np.sum(sv > DEFAULT.numerics.rank_tol))]
    if len(rest):
        # translations: the combinations of the rows without a turn
        u, sv, vh = np.linalg.svd(rest[:, d:])
        turning = int(np.sum(sv > DEFAULT.numerics.rank_tol))
        c = com_world(pose, fixture.workpiece.com_body)
        scale = fixture.workpiece.shape.bounding_radius + float(np.linalg.norm(c))
        if turning < len(rest):
            T = np.linalg.qr((u[:, turning:].T @ rest[:, :d]).T)[0].T
            parts.append(_translations_text(T, d))
        turns = u[:, :turning].T @ rest
        point = _common_point(turns, d, c) if turning > 1 else None
        if point is not None:
            where = _point_text(point, scale)
            if turning == 3:
                parts.append(f"every rotation about {where}")
            else:
                normal = np.cross(turns[0, d:], turns[1, d:])
                parts.append(f"rotation about any axis through {where} normal to {_direction_text(normal)}")
            turns = turns[:0]
        for twist in turns:
            v, w = twist[:d], twist[d:]
            if d == 2:
                p = c + np.array([-v[1], v[0]]) / w[0]
                parts.append(f"rotation about {_point_text(p, scale)}")
                continue
            ww = float(w @ w)
            p = c + np.cross(w, v) / ww
            pitch = float(w @ v) / ww
            where = f"an axis along {_direction_text(w)} through {_point_text(p, scale)}"
            if abs(pitch) > DEFAULT.numerics.zero_rel * scale:
                parts.append(f"a screw motion about {where} (pitch {pitch:.3g} m/rad)")
            else:
                parts.append(f"rotation about {where}")
    return ", ".join(parts) if parts else "no motion"


def with_free_motions(fixture: Fixture) -> Fixture:
    """``fixture`` with its free motions: fewer locators than a full fixture that leave only the part's symmetry free.

    Five locators on a cylinder that leave only its spin (three on a sphere, two on a disk) locate
    it up to that spin: the answer has :attr:`~fixplan.model.Fixture.free_motions_body` (the
    symmetry, :func:`~fixplan.model.symmetry_motions_body`) and is full. Otherwise a fixture that
    is not full gets :attr:`~fixplan.model.Fixture.unlocated`: what its locators leave free at the
    start (:func:`describe_motions`). Judged at the start pose, every locator's normal row;
    :func:`settle_free_motions` checks again at the located pose.
    """
    need = 6 if fixture.dimension == 3 else 3
    if len(fixture.locators) >= need or fixture.free_motions_body is not None:
        return fixture
    free = free_motions_at(fixture, fixture.start)
    sym = symmetry_motions_body(fixture.workpiece)
    if len(sym) and len(free) == len(sym):
        sym = _orthonormal_rows(sym)
        if _spans(replace(fixture, free_motions_body=sym).free_motions_world(fixture.start), free):
            return replace(fixture, free_motions_body=sym, unlocated="")
    return replace(fixture, unlocated=describe_motions(fixture, fixture.start, free))


def settle_free_motions(fixture: Fixture) -> Fixture:
    """A fixture located up to its symmetry, once its located pose is known.

    A computed goal takes the start's spin: of the located poses (the goal turned about the
    symmetry axis) the one nearest the start (:func:`~fixplan.model.nearest_symmetric_pose`); a
    given goal is kept as given. When the locators leave more than the symmetry free at the goal,
    the fixture is not full after all: no goal, and :attr:`~fixplan.model.Fixture.unlocated` says
    what is free there.
    """
    if fixture.free_motions_body is None or fixture.goal_pose is None:
        return fixture
    goal = fixture.goal_pose
    if fixture.goal_given is None:
        goal = nearest_symmetric_pose(fixture.workpiece.shape, goal, fixture.start)
    free = free_motions_at(fixture, goal)
    if len(free) == len(fixture.free_motions):
        return replace(fixture, goal_pose=goal)
    return replace(
        fixture,
        free_motions_body=None,
        goal_pose=None,
        goal_starts=0,
        unlocated=describe_motions(fixture, goal, free) + " (at the pose where every locator touches)",
    )


def with_goal(fixture: Fixture) -> Fixture:
    """``fixture`` with its located pose set again, for a model changed after loading.

    The given goal when there is one (``goal_given``, unchecked here), else the pose that
    :func:`find_goal` finds from the start pose; :class:`InfeasibleError` saying why when it
    finds none, or when the fixture is not full. A part located up to its symmetry
    (:func:`with_free_motions`) takes the start's spin (:func:`settle_free_motions`).
    """
    fixture = with_free_motions(fixture)
    require_full(fixture, "the goal pose")
    if fixture.goal_given is not None:
        return settle_free_motions(replace(fixture, goal_pose=fixture.goal_given))
    search = find_goal(fixture.workpiece, fixture.locators, fixture.start)
    if not search.found or search.pose is None:
        raise InfeasibleError(f"{fixture.source}: {search.message}")
    return settle_free_motions(replace(fixture, goal_pose=search.pose, goal_starts=search.starts))


__all__ = [
    "Engagement",
    "Insert",
    "axis_offsets_m",
    "bottom_gap_m",
    "engagement",
    "insertion_axis",
    "inserts",
    "located_pose",
    "find_pin_goal",
    "seating_side_at_start",
    "Seat",
    "seat_at",
    "seat_gaps_m",
    "seated",
    "GoalResult",
    "GoalSearch",
    "contact_set",
    "describe_motions",
    "find_goal",
    "free_motions_at",
    "locator_contact",
    "locator_contacts",
    "locator_gaps",
    "peg_body",
    "insert_contacts",
    "pin_and_hole",
    "cylinder_contacts",
    "named_faces",
    "no_pose_proof",
    "require_full",
    "settle_free_motions",
    "solve_goal",
    "with_free_motions",
    "with_goal",
]
