"""Fixture files (TOML, ``docs/fixture-format.md``) → a validated :class:`~fixplan.model.Fixture`.

The loader and its checks; the model it builds lives in :mod:`fixplan.model` (re-exported here).
The located pose is computed here, at load, and stored in the model as ``goal_pose``.

Every problem in a file is reported, each as ``FILE: dotted.key.path: what is wrong (what was
expected)``, by raising one :class:`~fixplan.errors.FixtureError` that carries them all.
Locators and contacts are addressed by name in key paths (``locator.P1.position``) when the
name is valid, else by index (``locator[2].position``). Each key is declared, and checked on its
own, in :mod:`fixplan.fixture_schema`; what needs the whole model (an inertia possible for the
shape and mass, the locators against the part, the goal pose) is checked here.

Keys added to the spec (documented in the README): none yet besides what the spec lists.
"""

from __future__ import annotations

import re
import sys
import tomllib
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fixplan import fixture_schema, limits
from fixplan.errors import FixtureError, InputError, Issue, shorten
from fixplan.fixture_schema import validate_document
from fixplan.geometry import Box, Cylinder, Disk, Mesh, Polygon, Rectangle, Shape, Sphere
from fixplan.geometry.collision import BOX as OBSTACLE_BOX
from fixplan.geometry.collision import PLANE as OBSTACLE_PLANE
from fixplan.geometry.collision import collision_points, obstacle_gap, plane_frame, polytope_overlap_m
from fixplan.locating import find_goal, find_pin_goal, locator_contact, settle_free_motions, with_free_motions
from fixplan.model import (
    Bore,
    Clamp,
    ExplicitContact,
    Fixture,
    Hole,
    Locator,
    Manipulator,
    Obstacle,
    Pin,
    ProcessLoad,
    RobotSpec,
    SimulationSettings,
    Workpiece,
)
from fixplan.schema import Reader
from fixplan.settings import DEFAULT as DEFAULT_SETTINGS
from fixplan.settings import Settings, Tolerances
from fixplan.spatial import Pose

FloatArray = NDArray[np.float64]

SHAPES_3D, SHAPES_2D, FACES = fixture_schema.SHAPES_3D, fixture_schema.SHAPES_2D, fixture_schema.FACES
_DATA = Path(__file__).resolve().parent / "data"


def _scaled(shape: Shape, k: float) -> Shape | None:
    """``shape`` with every length times ``k`` (None for a shape not scaled here: polygon, mesh)."""
    if isinstance(shape, Box):
        return Box(tuple(k * x for x in shape.size))  # type: ignore[arg-type]
    if isinstance(shape, Rectangle):
        return Rectangle(tuple(k * x for x in shape.size))  # type: ignore[arg-type]
    if isinstance(shape, Sphere):
        return Sphere(k * shape.radius)
    if isinstance(shape, Disk):
        return Disk(k * shape.radius)
    if isinstance(shape, Cylinder):
        return Cylinder(k * shape.radius, k * shape.length)
    return None


def default_fixture_path() -> Path:
    """The bundled default fixture (a 3-2-1 box), used when a command is given no file."""
    return _DATA / "default.toml"


def load(path: str | Path, settings: Settings = DEFAULT_SETTINGS) -> Fixture:
    """Read and validate a fixture file; raise :class:`FixtureError` listing every problem.

    The fixture carries ``settings.tolerances`` (what touching and penetrating mean, checked at
    load and used by every analysis of it).
    """
    path = Path(path)
    return loads(read_fixture_text(path), source=str(path), base_dir=path.parent, settings=settings)


# -- the fixture a plan file names ------------------------------------------------------------------
_SHA256 = re.compile(r"[0-9a-f]{64}")


def fixture_stamp(path: str | Path) -> dict[str, str]:
    """The keys by which a plan file names its fixture: ``fixture`` and ``fixture_sha256``.

    ``fixture`` is the path resolved to an absolute one (so that the plan can be verified from
    any folder); ``fixture_sha256`` the SHA-256 of the file's bytes, followed by its mesh file's
    bytes for a mesh part (:func:`fixture_sha256`), so that an edited file is noticed
    (:func:`fixture_of_plan`).
    """
    path = Path(path)
    return {"fixture": str(path.resolve()), "fixture_sha256": fixture_sha256(path)[0]}


def fixture_sha256(path: Path) -> tuple[str, str | None]:
    """``(SHA-256 hex, the mesh file's name or None)`` of a fixture: what a plan's ``fixture_sha256`` holds.

    The SHA-256 of the fixture file's bytes; for a mesh part (``[workpiece] shape = "mesh"``),
    of the fixture's bytes followed by its mesh file's bytes (``cat fixture.toml part.stl |
    sha256sum``), so that a plan made on one mesh is not replayed on an edited one. A mesh file
    that cannot be read (gone, outside the folder) adds a marker instead of its bytes: the
    digest then differs from any made on a readable file. A fixture that is not valid TOML is
    digested alone (loading it reports what is wrong).

    Raises
    ------
    UnreadableFile
        The fixture file itself cannot be read.
    """
    import hashlib
    import tomllib

    from fixplan.files import UnreadableFile, open_user_file
    from fixplan.limits import MAX_FILE_BYTES

    with open_user_file(path, expected="a fixture file", max_bytes=MAX_FILE_BYTES) as fh:
        data = fh.read(MAX_FILE_BYTES + 1)
    digest = hashlib.sha256(data)
    try:
        table = tomllib.loads(data.decode("utf-8-sig"))
    except (UnicodeDecodeError, tomllib.TOMLDecodeError):
        return digest.hexdigest(), None
    workpiece = table.get("workpiece")
    file = workpiece.get("file") if isinstance(workpiece, dict) and workpiece.get("shape") == "mesh" else None
    if not isinstance(file, str):
        return digest.hexdigest(), None
    from fixplan import limits
    from fixplan.geometry.mesh import MeshError
    from fixplan.mesh_file import mesh_path

    try:
        with open_user_file(
            mesh_path(file, path.parent), expected="a mesh file", max_bytes=limits.MAX_MESH_BYTES
        ) as fh:
            while chunk := fh.read(1 << 20):
                digest.update(chunk)
    except (MeshError, UnreadableFile, OSError):
        digest.update(b"\0fixplan: the mesh file could not be read\0")
    return digest.hexdigest(), file


def fixture_of_plan(data: Any, plan: Path, given: Path | None) -> tuple[Path, str | None]:
    """The fixture file to verify a plan file's object against, and a warning to print (or None).

    ``given`` (``--fixture``) wins; a differing hash only warns. Else the file the plan names
    (``fixture``: absolute, or relative to the working folder or to the plan's folder), refused
    when it is missing or its bytes changed since the plan was made. A plan that names no fixture
    (written before plans named theirs) is read for the bundled box, with a warning.

    Raises
    ------
    InputError
        The named file is missing or was edited, or the keys are malformed; the message says how
        to go on (``--fixture FILE`` or solve again).
    """
    from shlex import quote

    from fixplan.errors import InputError

    obj = data if isinstance(data, dict) else {}
    named, digest = obj.get("fixture"), obj.get("fixture_sha256")
    if named is not None and not (isinstance(named, str) and named):
        raise InputError(f"{plan}: fixture: expected the fixture file's path, got {shorten(repr(named))}")
    if digest is not None and not (isinstance(digest, str) and _SHA256.fullmatch(digest)):
        raise InputError(f"{plan}: fixture_sha256: expected 64 lowercase hex digits, got {shorten(repr(digest))}")
    if given is not None:
        note = None
        if digest is not None and given.is_file() and fixture_sha256(given)[0] != digest:
            same = named is not None and Path(named).resolve() == given.resolve()
            was = "changed since the plan was made" if same else f"is not the fixture the plan was made for ({named})"
            note = f"warning: {given} {was}: verifying {plan} against it as it is now"
        return given, note
    if named is None:
        return default_fixture_path(), (
            f"warning: {plan} names no fixture (a plan written before plans named theirs): verifying it against the "
            "bundled box; pass its fixture with --fixture FILE"
        )
    candidates = [Path(named)]
    if not Path(named).is_absolute():
        candidates.append(plan.parent / named)
    found = next((c for c in candidates if c.is_file()), None)
    if found is None:
        raise InputError(
            f"{plan}: the plan names the fixture {named}, which is not there (moved or deleted?): "
            "pass the fixture with --fixture FILE"
        )
    if digest is not None and (now := fixture_sha256(found))[0] != digest:
        what = f"the fixture {found}" if now[1] is None else f"the fixture {found} or its mesh file {now[1]!r}"
        raise InputError(
            f"{plan}: {what} changed since the plan was made (SHA-256 {digest[:12]}… then, {now[0][:12]}… now): "
            f"solve it again ('fixplan solve {quote(str(found))} --out {quote(str(plan))} --force'), "
            f"or verify the plan against the file as it is now with --fixture {quote(str(found))}"
        )
    return found, None


def read_fixture_text(path: Path) -> str:
    """The text of a fixture file: a regular UTF-8 file within the size limit, else :class:`FixtureError`."""
    from fixplan.files import UnreadableFile, read_user_text

    try:
        return read_user_text(path, expected="a .toml fixture file")
    except UnreadableFile as exc:
        raise FixtureError(str(path), [Issue("<file>", f"cannot read: {exc.reason}")]) from None


def parse_toml(text: str, source: str) -> dict[str, Any]:
    """The TOML document, or :class:`FixtureError` keyed ``<toml>`` saying what is wrong.

    The nesting is bounded before parsing (:func:`fixplan.limits.toml_nesting`, one linear scan):
    the parser's cost grows with the square of a dotted key's depth.
    """
    deep = limits.toml_nesting(text)
    if deep is not None:
        line, depth = deep
        raise FixtureError(
            source,
            [
                Issue(
                    "<toml>",
                    f"line {line}: tables, arrays or dotted keys nested {depth} deep (expected at most "
                    f"{limits.MAX_TOML_NESTING} levels; a fixture file nests 3)",
                )
            ],
        )
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise FixtureError(source, [Issue("<toml>", f"invalid TOML: {exc}")]) from None
    except RecursionError:
        raise FixtureError(
            source, [Issue("<toml>", "invalid TOML: arrays or tables nested too deeply (expected a fixture file)")]
        ) from None
    except ValueError:  # an integer beyond Python's digit limit for int("...")
        raise FixtureError(
            source,
            [
                Issue(
                    "<toml>",
                    f"invalid TOML: an integer of more than {sys.get_int_max_str_digits()} digits (expected numbers of ordinary size)",
                )
            ],
        ) from None


def loads(
    text: str, source: str = "<string>", base_dir: Path | None = None, settings: Settings = DEFAULT_SETTINGS
) -> Fixture:
    """Validate fixture TOML text (see :func:`load`)."""
    return _Builder(parse_toml(text, source), source, base_dir or Path("."), settings.tolerances).build()


class _Builder:
    """Reads one parsed TOML document into a Fixture, collecting every issue.

    The keys are checked by their declarations (:mod:`fixplan.fixture_schema`); what needs the
    whole model (an inertia possible for the shape and mass, the locators against the part,
    the goal) is checked here.
    """

    def __init__(self, data: dict[str, Any], source: str, base_dir: Path, tol: Tolerances):
        self.data = data
        self.source = source
        self.base_dir = base_dir
        self.tol = tol
        self.r = Reader()
        self.warnings: list[Issue] = []
        self.goal_starts = 0  # starts goal finding tried (0: the goal is given, or the fixture is not full)

    def fail_if_issues(self) -> None:
        if self.r.issues:
            raise FixtureError(self.source, self.r.issues)

    def build(self) -> Fixture:
        r = self.r
        self.check_entry_count()
        dim = _dimension_of(self.data)
        kind = _shape_of(self.data, dim)
        doc, issues = validate_document(self.data, dim, kind)
        if dim is None:  # without a valid dimension nothing but the scene can be checked meaningfully
            raise FixtureError(self.source, [i for i in issues if re.split(r"[.\[]", i.key)[0] not in _PER_DIMENSION])
        r.issues.extend(issues)
        if doc is not None and not doc.locator and not doc.contact and not doc.pin and not doc.bore and not r.issues:
            r.error("locator", "no [[locator]] or [[contact]] entries (expected at least one)")
        self.fail_if_issues()
        if doc is None:  # no issue and no document: a reader fault, still one line and exit 2
            raise FixtureError(self.source, [Issue("", "the file could not be read as a fixture (no issue was found)")])
        workpiece = self.workpiece(doc.workpiece, dim)
        self.fail_if_issues()
        scene, wp = doc.scene, doc.workpiece
        gravity = scene.gravity or ((0.0, 0.0, -9.81) if dim == 3 else (0.0, -9.81))
        manipulator, simulation = doc.manipulator, doc.simulation
        fixture = Fixture(
            source=self.source,
            name=scene.name,
            dimension=dim,
            gravity=np.array(gravity),
            workpiece=workpiece,
            locators=tuple(
                Locator(e.name, np.array(e.position), e.radius, e.friction, e.torsion, e.face) for e in doc.locator
            ),
            contacts=tuple(
                ExplicitContact(e.name, np.array(e.point), _unit(e.normal), e.friction, e.torsion) for e in doc.contact
            ),
            manipulator=Manipulator(
                _or_inf(manipulator.max_force if manipulator else None),
                _or_inf(manipulator.max_torque if manipulator else None),
            ),
            simulation=SimulationSettings(simulation.timestep, simulation.restitution, simulation.tolerance)
            if simulation
            else SimulationSettings(),
            start=_pose(wp.start, dim) if wp.start is not None else Pose.identity(dim),
            goal_given=_pose(wp.goal, dim) if wp.goal is not None else None,
            tolerances=self.tol,
            obstacles=tuple(self.obstacle(e, dim) for e in doc.obstacle),
            pins=tuple(self.pin(e) for e in doc.pin),
            bores=tuple(self.bore(e) for e in doc.bore),
            robot=self.robot(doc.robot) if doc.robot is not None else None,
            clamps=tuple(
                Clamp(e.name, np.array(e.position), _unit(e.direction), e.radius, e.friction, e.max_force, e.force)
                for e in doc.clamp
            ),
            loads=tuple(ProcessLoad(e.name, np.array(e.wrench)) for e in doc.load),
        )
        self.fail_if_issues()
        if fixture.has_pins or workpiece.holes:
            self.check_pins(fixture, dim)
            self.fail_if_issues()
        else:
            fixture = with_free_motions(fixture)  # fewer locators that leave only the part's symmetry free
        goal = self.check_geometry(fixture)
        self.check_obstacles(fixture, goal)
        self.check_clamps(fixture, goal)
        self.fail_if_issues()
        fixture = replace(fixture, goal_pose=goal, goal_starts=self.goal_starts, warnings=tuple(self.warnings))
        return settle_free_motions(fixture)

    def check_entry_count(self) -> None:
        """At most :data:`~fixplan.limits.MAX_ENTRIES` locators and contacts, refused before any is read."""
        obstacles = self.data.get("obstacle")
        if isinstance(obstacles, list) and len(obstacles) > limits.MAX_ENTRIES:
            raise FixtureError(
                self.source,
                [Issue("obstacle", f"{len(obstacles)} [[obstacle]] entries (expected at most {limits.MAX_ENTRIES})")],
            )
        count = sum(len(v) for k in ("locator", "contact") if isinstance(v := self.data.get(k), list))
        if count > limits.MAX_ENTRIES:
            raise FixtureError(
                self.source,
                [
                    Issue(
                        "locator",
                        f"{count} [[locator]] and [[contact]] entries (expected at most {limits.MAX_ENTRIES}; "
                        "a fixture needs 6 in 3D, 3 in 2D)",
                    )
                ],
            )

    # -- pins, holes and bores ------------------------------------------------------------------
    def pin(self, e: fixture_schema.Pin) -> Pin:
        axis = _unit(e.axis)
        land = None
        if e.land_direction is not None:
            d = _unit(e.land_direction)
            if abs(float(d @ axis)) > np.sin(DEFAULT_SETTINGS.pins.axis_angle_rad):
                self.r.error(
                    f"pin.{e.name}.land_direction",
                    f"not normal to the pin's axis (cosine {float(d @ axis):.3g}; expected a direction across the pin)",
                )
            d = d - float(d @ axis) * axis
            land = d / np.linalg.norm(d) if np.linalg.norm(d) > 0.0 else None
        return Pin(
            e.name,
            e.kind,
            e.hole,
            np.array(e.position),
            axis,
            e.diameter,
            e.length,
            e.friction,
            e.chamfer,
            land,
            e.land_width or 0.0,
        )

    def bore(self, e: fixture_schema.Bore) -> Bore:
        return Bore(e.name, np.array(e.position), _unit(e.axis), e.diameter, e.depth, e.friction, e.chamfer)

    def check_pins(self, fixture: Fixture, dim: int) -> None:
        """Each pin against its hole and each bore against the part: sizes, names (the located pose: :meth:`check_pin_goal`)."""
        r, wp = self.r, fixture.workpiece
        if dim != 3:
            for key in ("pin", "bore", "workpiece.hole"):
                r.error(key, "pins, holes and bores are 3D only (expected scene.dimension = 3)")
            return
        holes = {h.name: h for h in wp.holes}
        for pin in fixture.pins:
            key = f"pin.{pin.name}"
            hole = holes.get(pin.hole)
            if hole is None:
                known = ", ".join(holes) if holes else "none: add a [[workpiece.hole]]"
                r.error(f"{key}.hole", f"no hole {pin.hole!r} in the part (expected one of: {known})")
                continue
            if pin.diameter_m >= hole.diameter_m:
                r.error(
                    f"{key}.diameter",
                    f"{pin.diameter_m:g} m does not fit hole {hole.name} of {hole.diameter_m:g} m "
                    "(expected a pin smaller than its hole)",
                )
            if pin.kind == "diamond" and pin.land_width_m > pin.diameter_m:
                r.error(
                    f"{key}.land_width",
                    f"{pin.land_width_m:g} m is wider than the pin ({pin.diameter_m:g} m; expected lands narrower "
                    "than the pin's diameter)",
                )
            if pin.chamfer_m >= 0.5 * pin.diameter_m or pin.chamfer_m >= pin.length_m:
                r.error(f"{key}.chamfer", f"{pin.chamfer_m:g} m (expected less than the pin's radius and length)")
        for bore in fixture.bores:
            key = f"bore.{bore.name}"
            if not isinstance(wp.shape, Cylinder):
                r.error(
                    key,
                    f"a bore takes a cylindrical part (expected workpiece.shape = 'cylinder', got {wp.shape.name!r})",
                )
            elif 2.0 * wp.shape.radius >= bore.diameter_m:
                r.error(
                    f"{key}.diameter",
                    f"{bore.diameter_m:g} m does not take the part of {2.0 * wp.shape.radius:g} m "
                    "(expected a bore larger than the part)",
                )
        for hole in wp.holes:
            if hole.chamfer_m >= hole.depth_m:
                r.error(f"workpiece.hole.{hole.name}.chamfer", f"{hole.chamfer_m:g} m (expected less than the depth)")

    def check_goal_gaps(self, fixture: Fixture, goal: Pose) -> None:
        """Every locator touches at the given goal (``|gap| ≤ goal_gap_m``), else one error each."""
        tol = self.tol
        for loc in fixture.locators:
            gap = locator_contact(fixture.workpiece, goal, loc).gap_m
            if abs(gap) > tol.goal_gap_m:
                self.r.error(
                    "workpiece.goal",
                    f"locator {loc.name} does not touch at the given goal (gap {gap:.3g} m; expected |gap| ≤ {tol.goal_gap_m:g} m)",
                )

    def check_pin_goal(self, fixture: Fixture, goal: Pose) -> None:
        """Every pin in its hole at the located pose, and rests with pins leaving 6 constraints (rank of the normals)."""
        r, wp, tol = self.r, fixture.workpiece, self.tol
        angle = DEFAULT_SETTINGS.pins.axis_angle_rad
        rows = [locator_contact(wp, goal, loc) for loc in fixture.locators]
        normals = [(c.point_world, c.normal_world) for c in rows]
        for pin in fixture.pins:
            hole = wp.hole(pin.hole)
            key = f"pin.{pin.name}"
            a = goal.R_world_body @ hole.axis_body
            m = goal.point_world_from_body(hole.p_body)
            if float(a @ pin.axis_world) > -np.cos(angle):
                r.error(
                    f"{key}.axis",
                    f"hole {hole.name} does not face the pin at the located pose (its axis is "
                    f"{np.degrees(np.arccos(np.clip(-float(a @ pin.axis_world), -1, 1))):.3g}° off; expected the hole's axis "
                    "against the pin's)",
                )
                continue
            tip = pin.p_world + pin.length_m * pin.axis_world
            tip_depth = float((m - tip) @ a)
            if tip_depth <= hole.chamfer_m:
                r.error(
                    f"{key}.position",
                    f"the pin does not reach into hole {hole.name} at the located pose (its tip is {-tip_depth:.3g} m "
                    "out of the hole's mouth; expected the pin's side inside the hole)",
                )
                continue
            if not hole.through and tip_depth > hole.depth_m + tol.goal_gap_m:
                r.error(
                    f"{key}.length",
                    f"the pin is {tip_depth - hole.depth_m:.3g} m longer than hole {hole.name} is deep at the located "
                    "pose (expected it clear of the hole's bottom while the rests touch)",
                )
            # the pin's axis where it crosses the mouth, against the hole's axis
            s = float((m - pin.p_world) @ pin.axis_world)
            q = pin.p_world + s * pin.axis_world
            off = q - m - float((q - m) @ a) * a
            play = 0.5 * (hole.diameter_m - pin.diameter_m)
            along = (
                abs(float(off @ pin.land_direction_world))
                if pin.land_direction_world is not None
                else float(np.linalg.norm(off))
            )
            if along > play + tol.goal_gap_m:
                r.error(
                    f"{key}.position",
                    f"hole {hole.name} cannot reach the pin at the located pose: the axes are {along:.3g} m apart "
                    f"(expected at most the radial play (D - d)/2 = {play:.3g} m)",
                )
            e1 = pin.land_direction_world
            if e1 is None:
                k = int(np.argmin(np.abs(pin.axis_world)))
                e1 = np.eye(3)[k] - pin.axis_world[k] * pin.axis_world
                e1 = e1 / np.linalg.norm(e1)
                normals.append((q, np.cross(pin.axis_world, e1)))
            normals.append((q, e1))
        if r.issues:
            return
        c = goal.point_world_from_body(wp.com_body)
        scale = wp.shape.bounding_radius
        G = np.array([[*n, *(np.cross(p - c, n) / scale)] for p, n in normals]).reshape(len(normals), 6)
        rank = int(np.linalg.matrix_rank(G)) if len(G) else 0
        if rank < 6:
            r.error(
                "pin",
                f"the rests and pins leave {6 - rank} motion(s) free at the located pose (rank of their constraint "
                f"normals {rank} < 6; expected 3 rests, a round pin and a diamond pin whose lands do not point at the "
                "round pin)",
            )

    # -- clamps ---------------------------------------------------------------------------------
    def check_clamps(self, fixture: Fixture, goal: Pose | None) -> None:
        """Each clamp's tip on the located part's surface (``|gap| ≤ goal_gap_m``): clamping comes after locating.

        A direction pointing out of the surface is not refused here: ``fixplan clamp`` refuses it
        with the reason (a tip can only push).
        """
        if not fixture.clamps or self.r.issues:
            return
        if goal is None:
            self.r.error(
                "clamp",
                f"clamps act at the located pose, which needs a full fixture ({6 if fixture.dimension == 3 else 3} "
                f"locators); this one has {len(fixture.locators)}",
            )
            return
        tol = self.tol
        for clamp in fixture.clamps:
            tip = Locator(clamp.name, clamp.p_world, clamp.radius_m, clamp.friction)
            gap = locator_contact(fixture.workpiece, goal, tip).gap_m
            if abs(gap) > tol.goal_gap_m:
                where = "inside the part" if gap < 0.0 else "away from the part"
                self.r.error(
                    f"clamp.{clamp.name}.position",
                    f"the tip is {abs(gap):.3g} m {where} at the located pose (expected it on the part's surface: "
                    f"|gap| ≤ {tol.goal_gap_m:g} m)",
                )
            for loc in fixture.locators:
                dist = float(np.linalg.norm(loc.p_world - clamp.p_world))
                if dist < loc.radius_m + clamp.radius_m or (
                    loc.radius_m + clamp.radius_m == 0.0 and dist < tol.touch_m
                ):
                    self.r.error(
                        f"clamp.{clamp.name}.position",
                        f"the tip overlaps locator {loc.name}'s (centres {dist:.3g} m apart; expected ≥ "
                        f"{loc.radius_m + clamp.radius_m:g} m)",
                    )

    # -- obstacles ---------------------------------------------------------------------------
    def robot(self, e: fixture_schema.Robot) -> RobotSpec | None:
        """``[robot]``: its URDF found and loaded now (a missing file or frame is an issue at load)."""
        from fixplan.robot_file import RobotError, load_robot, urdf_path

        try:
            path = urdf_path(e.urdf, self.base_dir)
        except RobotError as exc:
            self.r.error("robot.urdf", str(exc))
            return None
        spec = RobotSpec(e.urdf, path, _pose(e.base, 3), _pose(e.grasp, 3), e.tool_frame, e.repeatability)
        try:
            load_robot(spec)
        except RobotError as exc:
            self.r.error("robot.tool_frame" if str(exc).startswith("tool_frame") else "robot.urdf", str(exc))
            return None
        return spec

    def obstacle(self, e: fixture_schema.Obstacle, dim: int) -> Obstacle:
        """``[[obstacle]]`` of a valid table: a plane (line) or a box (rectangle) in the world."""
        plane = e.shape == fixture_schema.OBSTACLE_SHAPES[dim][0]
        if (e.point is None or e.normal is None) if plane else (e.pose is None or e.size is None):
            # the table's rules require these keys; a model built otherwise is refused the same way
            need = "point and normal" if plane else "size and pose"
            raise FixtureError(self.source, [Issue(f"obstacle.{e.name}", f"a {e.shape} needs {need}")])
        if plane:
            frame = plane_frame(np.array(e.point), _unit(e.normal))  # type: ignore[arg-type]
            half = np.zeros(0)
        else:
            pose = _pose(e.pose, dim)  # type: ignore[arg-type]
            frame, half = (pose.R_world_body, pose.p_world), np.array(e.size) / 2.0
        return Obstacle(e.name, e.shape, frame[0], frame[1], half, e.friction)

    def check_obstacles(self, fixture: Fixture, goal: Pose | None) -> None:
        """The part clear of every obstacle at the start and at the located pose (within the penetration tolerance)."""
        if not fixture.obstacles:
            return
        wp, tol, dim = fixture.workpiece, self.tol, fixture.dimension
        pts, radii = collision_points(wp.shape, DEFAULT_SETTINGS.engine.rim_points)
        for ob in fixture.obstacles:
            code = OBSTACLE_PLANE if ob.is_plane else OBSTACLE_BOX
            for what, pose in (("start pose", fixture.start), ("located pose", goal)):
                if pose is None:
                    continue
                gap = min(
                    obstacle_gap(code, ob.R_world_obstacle, ob.o_world, ob.half_m, pose.point_world_from_body(b), rho)[
                        0
                    ]
                    for b, rho in zip(pts, radii, strict=True)
                )
                if not ob.is_plane and isinstance(wp.shape, Box | Rectangle | Polygon):
                    # a box part against a box: the separating-axis test (a plate through the part's middle)
                    corners, _ = collision_points(
                        Box(tuple(2 * ob.half_m)) if dim == 3 else Rectangle(tuple(2 * ob.half_m)), 0
                    )  # type: ignore[arg-type]
                    axes_b = ob.R_world_obstacle.T
                    if isinstance(wp.shape, Polygon):
                        E = np.roll(wp.shape.array, -1, axis=0) - wp.shape.array
                        axes_a = (
                            np.stack([E[:, 1], -E[:, 0]], axis=1)
                            / np.linalg.norm(E, axis=1)[:, None]
                            @ pose.R_world_body.T
                        )
                    else:
                        axes_a = pose.R_world_body.T
                    depth = polytope_overlap_m(
                        pts @ pose.R_world_body.T + pose.p_world, axes_a, corners @ axes_b + ob.o_world, axes_b
                    )
                    gap = min(gap, -depth)
                if gap < -tol.penetration_m:
                    self.r.error(
                        f"obstacle.{ob.name}",
                        f"the part at its {what} is inside this collision-only body by {-gap:.3g} m (expected it clear: "
                        "an obstacle never locates, so it must lie beyond the part where the locators hold it)",
                    )

    # -- workpiece ---------------------------------------------------------------------------
    def workpiece(self, wp: fixture_schema.Workpiece, dim: int) -> Workpiece:
        """The workpiece of a valid table; an inertia impossible for its shape and mass is an issue."""
        shape: Shape
        if wp.shape == "box":
            shape = Box(wp.size)  # type: ignore[arg-type]
        elif wp.shape == "rectangle":
            shape = Rectangle(wp.size)  # type: ignore[arg-type]
        elif wp.shape == "sphere":
            shape = Sphere(wp.radius)  # type: ignore[arg-type]
        elif wp.shape == "disk":
            shape = Disk(wp.radius)  # type: ignore[arg-type]
        elif wp.shape == "cylinder":
            shape = Cylinder(wp.radius, wp.length)  # type: ignore[arg-type]
        elif wp.shape == "mesh":
            from fixplan.geometry.mesh import MeshError
            from fixplan.geometry.step import STEP_SUFFIXES
            from fixplan.mesh_file import load_mesh_file

            step = Path(wp.file or "").suffix.lower() in STEP_SUFFIXES
            if step and wp.units is not None:
                raise FixtureError(
                    self.source,
                    [Issue("workpiece.units", "not used for a STEP file, which states its own unit (remove it)")],
                )
            if not step and wp.tolerance is not None:
                raise FixtureError(
                    self.source,
                    [Issue("workpiece.tolerance", "only used for a STEP file's tessellation (remove it)")],
                )
            try:
                shape = load_mesh_file(wp.file or "", self.base_dir, units=wp.units or "m", tolerance_m=wp.tolerance)
            except MeshError as exc:
                raise FixtureError(self.source, [Issue("workpiece.file", str(exc))]) from None
        else:
            shape = Polygon(wp.vertices)  # type: ignore[arg-type]
        mass = wp.mass
        if wp.inertia is None:
            inertia = shape.inertia_body(mass)
        else:
            inertia = np.array([[wp.inertia]]) if dim == 2 else np.diag(wp.inertia)
            self.check_inertia(inertia, shape, mass)
        self.check_density(shape, mass, dim)
        holes = tuple(self.hole(h, shape) for h in wp.hole)
        return Workpiece(shape, mass, inertia, shape.com_body, holes)

    def hole(self, e: fixture_schema.Hole, shape: Shape) -> Hole:
        """A ``[[workpiece.hole]]``: through when its bottom lies on or outside the part's surface.

        A mesh may model the hole's bore: a blind one's bottom then lies on the bore's floor, on the
        surface too. So for a mesh the point just past the bottom (``MeshSettings.hole_probe_m``)
        decides: inside the part, the hole is blind.
        """
        axis = _unit(e.axis)
        bottom = np.array(e.position) - e.depth * axis
        through = shape.dimension == 3 and shape.project(bottom).distance >= -self.tol.penetration_m
        if through and isinstance(shape, Mesh):
            through = shape.project(bottom - shape.settings.hole_probe_m * axis).distance > 0.0
        return Hole(e.name, np.array(e.position), axis, e.diameter, e.depth, e.chamfer, through)

    def check_inertia(self, inertia: FloatArray, shape: Shape, mass: float) -> bool:
        """A given inertia within what a rigid body of this shape and mass can have (see :mod:`fixplan.limits`)."""
        uniform = np.diag(shape.inertia_body(mass))
        radius = shape.bounding_radius + float(np.linalg.norm(shape.com_body))
        high = mass * radius**2  # no point of the part is farther than R from its centre of mass
        for i, moment in enumerate(np.diag(inertia)):
            low = limits.INERTIA_MIN_OF_UNIFORM * float(uniform[i])
            if not low <= moment <= high:
                axis = "xyz"[i] if inertia.shape[0] == 3 else "z"
                self.r.error(
                    "workpiece.inertia",
                    f"I{axis}{axis} = {moment:g} kg·m² is impossible for this {shape.name} of {mass:g} kg "
                    f"(expected a moment in [{low:.3g}, {high:.3g}] kg·m²: from 10⁻³ of uniform density to m·R²)",
                )
                return False
        return True

    def check_density(self, shape: Shape, mass: float, dim: int) -> None:
        """Warn (not an error) when the density is far outside solids: is the file in millimetres or grams."""
        if isinstance(shape, Box):
            volume = float(np.prod(shape.size))
        elif isinstance(shape, Sphere):
            volume = 4.0 / 3.0 * np.pi * shape.radius**3
        elif isinstance(shape, Cylinder):
            volume = np.pi * shape.radius**2 * shape.length
        elif dim == 3 and getattr(shape, "volume_m3", 0.0) > 0.0:  # a mesh
            volume = shape.volume_m3  # type: ignore[attr-defined]
        else:  # 2D: a mass per unit depth has no density to judge
            return
        rho = mass / volume
        lo, hi = limits.DENSITY_WARN_KGPM3
        if not lo <= rho <= hi:
            self.warnings.append(
                Issue(
                    "workpiece.mass",
                    f"warning: the part's density is {rho:.3g} kg/m³, far outside solids ({lo:g} to {hi:g} kg/m³); "
                    "units are metres and kilograms (is the file in millimetres or grams?)",
                )
            )

    def check_units(self, fixture: Fixture) -> None:
        """Tips inside the part that would clear it were its sizes in cm or mm: say that sizes are in metres.

        Each scale is tried on the shape alone (the locators and poses as written): a file whose
        sizes alone are in centimetres has every tip outside once they are read as such, and the
        nearest within the part's width (a tip pushed a little into a part in metres is not).
        """
        wp, tol = fixture.workpiece, self.tol
        for factor, unit in ((1e2, "centimetres"), (1e3, "millimetres")):
            shape = _scaled(wp.shape, 1.0 / factor)
            if shape is None:
                return
            scaled = Workpiece(shape, wp.mass_kg, wp.inertia_body, shape.com_body)
            gaps = [locator_contact(scaled, fixture.start, loc).gap_m for loc in fixture.locators]
            # ... and the nearest tip near the part read so (a fixture holds its part), not metres away
            if min(gaps) >= -tol.penetration_m and min(gaps) <= 2.0 * shape.bounding_radius:
                self.r.error(
                    "workpiece",
                    f"the locators are inside the part, and would not be were its sizes in {unit}: "
                    f"sizes are in metres; did you write {unit}?",
                )
                return

    # -- checks that need the whole model -------------------------------------------------------------
    def check_geometry(self, fixture: Fixture) -> Pose | None:
        """Check the locators against the shape and locate the part; the located pose (full fixtures)."""
        r, tol = self.r, self.tol
        locs = fixture.locators
        for i, a in enumerate(locs):
            for b in locs[i + 1 :]:
                dist = float(np.linalg.norm(a.p_world - b.p_world))
                reach = a.radius_m + b.radius_m
                if reach == 0.0 and dist < tol.touch_m:
                    r.error(
                        f"locator.{b.name}.position",
                        f"{b.name} and {a.name} are at one place ({dist:.3g} m apart; expected point locators "
                        f"at least {tol.touch_m:g} m apart)",
                    )
                elif reach > 0.0 and dist < reach:
                    r.error(
                        f"locator.{b.name}.position",
                        f"{b.name} and {a.name} are at one place: their tips overlap (centres {dist:.3g} m apart; "
                        f"expected ≥ {reach:g} m, the sum of the tip radii)",
                    )
        wp = fixture.workpiece
        inside = [loc for loc in locs if locator_contact(wp, fixture.start, loc).gap_m < -tol.penetration_m]
        if inside:
            self.check_units(fixture)
        for loc in locs:
            gap = locator_contact(wp, fixture.start, loc).gap_m
            if gap < -tol.penetration_m:
                r.error(
                    f"locator.{loc.name}.position",
                    f"tip is inside the workpiece by {-gap:.3g} m at the start pose (expected gap ≥ -{tol.penetration_m:g} m)",
                )
        if fixture.has_pins and not r.issues and fixture.is_full:
            if fixture.goal_given is None:
                try:
                    search = find_pin_goal(fixture)
                except InputError as exc:  # the pins' axes differ: no one insertion to locate along
                    why = str(exc).removeprefix(f"{fixture.source}: ")
                    r.error("workpiece.goal", f"missing, and no located pose to find: {why}")
                    return None
                if not search.found or search.pose is None:
                    r.error("workpiece.goal", f"missing, and {search.message}")
                    return None
                goal = search.pose
            else:
                goal = fixture.goal_given
            self.check_goal_gaps(fixture, goal)
            self.check_pin_goal(fixture, goal)
            return goal
        if r.issues or not fixture.is_full:
            if fixture.goal_given is not None and not fixture.is_full and not r.issues:
                r.error(
                    "workpiece.goal",
                    f"a goal needs a full fixture ({6 if fixture.dimension == 3 else 3} locators); this one has {len(locs)}",
                )
            return None
        if fixture.goal_given is not None:
            goal = fixture.goal_given
            self.check_goal_gaps(fixture, goal)
            for loc in locs:
                if loc.face is None:
                    continue
                p_body = goal.point_body_from_world(loc.p_world)
                face = wp.shape.face_of(wp.shape.project(p_body).point_body)
                if face != loc.face:
                    r.error(f"locator.{loc.name}.face", f"touches face {face!r} at the goal (expected {loc.face!r})")
            return goal
        search = find_goal(wp, locs, fixture.start)
        self.goal_starts = search.starts
        if search.found and search.pose is not None:
            return search.pose
        for name, touched in search.face_mismatches:
            expected = fixture.locator(name).face
            r.error(f"locator.{name}.face", f"touches {touched} at the located pose (expected {expected!r})")
        if not search.face_mismatches:
            r.error("locator", search.message)
        return None


_PER_DIMENSION = (
    "workpiece",
    "locator",
    "contact",
    "pin",
    "bore",
    "clamp",
    "load",
)  # tables whose keys need the scene's dimension


def _dimension_of(data: dict[str, Any]) -> int | None:
    """``scene.dimension`` (3 when absent), None when it is not 2 or 3 (the schema says so)."""
    scene = data.get("scene")
    if not isinstance(scene, dict) or "dimension" not in scene:
        return 3
    dim = scene["dimension"]
    return dim if type(dim) is int and dim in (2, 3) else None


def _shape_of(data: dict[str, Any], dim: int | None) -> str | None:
    """``workpiece.shape`` when it is a shape of the scene's dimension (locator faces are checked against it)."""
    wp = data.get("workpiece")
    kind = wp.get("shape") if isinstance(wp, dict) else None
    return kind if kind in (SHAPES_3D if dim == 3 else SHAPES_2D) else None


def _pose(pose: fixture_schema.Pose, dim: int) -> Pose:
    if dim == 3:
        return Pose.from_rpy_deg(list(pose.position), list(pose.rpy_deg))
    return Pose.from_angle_deg(list(pose.position), pose.angle_deg)


def _unit(v: tuple[float, ...]) -> FloatArray:
    """``v`` normalised in two steps (``[1e300, 1e300]`` does not overflow)."""
    a = np.array(v, dtype=float)
    a = a / np.max(np.abs(a))
    return a / np.linalg.norm(a)


def _or_inf(x: float | None) -> float:
    return float("inf") if x is None else x
