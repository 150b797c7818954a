"""Fixture files (TOML, ``docs/fixture-format.md``) → a validated :class:`~fixplan.model.Fixture`.

The loader and its checks; the model it builds lives in :mod:`fixplan.model` (re-exported here).
The located pose is computed here, at load, and stored in the model as ``goal_pose``.

Every problem in a file is reported, each as ``FILE: dotted.key.path: what is wrong (what was
expected)``, by raising one :class:`~fixplan.errors.FixtureError` that carries them all.
Locators and contacts are addressed by name in key paths (``locator.P1.position``) when the
name is valid, else by index (``locator[2].position``).

Keys added to the spec (documented in the README): none yet besides what the spec lists.
"""

from __future__ import annotations

import re
import sys
import tomllib
from dataclasses import replace
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fixplan import limits
from fixplan.errors import FixtureError, Issue
from fixplan.geometry import Box, Cylinder, Disk, Polygon, Rectangle, Shape, Sphere
from fixplan.geometry.collision import BOX as OBSTACLE_BOX
from fixplan.geometry.collision import PLANE as OBSTACLE_PLANE
from fixplan.geometry.collision import collision_points, obstacle_gap, plane_frame, polytope_overlap_m
from fixplan.locating import find_goal, locator_contact, settle_free_motions, with_free_motions
from fixplan.model import ExplicitContact, Fixture, Locator, Manipulator, Obstacle, SimulationSettings, Workpiece
from fixplan.schema import Reader, shorten
from fixplan.settings import DEFAULT as DEFAULT_SETTINGS
from fixplan.settings import DEFAULT_TOLERANCES as DEFAULT
from fixplan.settings import Tolerances
from fixplan.spatial import Pose

FloatArray = NDArray[np.float64]

SHAPES_3D = ("box", "cylinder", "sphere", "mesh")
SHAPES_2D = ("rectangle", "disk", "polygon")
FACES = {
    "box": ("+x", "-x", "+y", "-y", "+z", "-z"),
    "rectangle": ("+x", "-x", "+y", "-y"),
    "cylinder": ("+z", "-z", "side"),
}
_DATA = Path(__file__).resolve().parent / "data"
# Locator and contact names appear in one-line messages, CSV headers and comma-separated --contacts
NAME_PATTERN = re.compile(rf"[\w+\-]{{1,{limits.MAX_NAME_LENGTH}}}")
NAME_RULE = f"a name of 1 to {limits.MAX_NAME_LENGTH} letters, digits, '_', '-' or '+' (no spaces, commas, dots or control characters)"
_SIZE = limits.SIZE
UNITS_HINT = "sizes are in metres; did you write millimetres?"
OBSTACLE_SHAPES = {3: ("plane", "box"), 2: ("line", "rectangle")}
OBSTACLE_FRICTION = 0.3  # an [[obstacle]] without friction: a steel plate, dry


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


_VERTEX = limits.Range("a vertex coordinate", "m", -limits.LENGTH_MAX_M, limits.LENGTH_MAX_M)


def default_fixture_path() -> Path:
    """The bundled default fixture (a 3-2-1 box), used when a command is given no file."""
    return _DATA / "default.toml"


def load(path: str | Path, tolerances: Tolerances = DEFAULT) -> Fixture:
    """Read and validate a fixture file; raise :class:`FixtureError` listing every problem."""
    path = Path(path)
    return loads(read_fixture_text(path), source=str(path), base_dir=path.parent, tolerances=tolerances)


# -- the fixture a plan file names ------------------------------------------------------------------
_SHA256 = re.compile(r"[0-9a-f]{64}")


def fixture_stamp(path: str | Path) -> dict[str, str]:
    """The keys by which a plan file names its fixture: ``fixture`` and ``fixture_sha256``.

    ``fixture`` is the path resolved to an absolute one (so that the plan can be verified from
    any folder); ``fixture_sha256`` the SHA-256 of the file's bytes, so that an edited file is
    noticed (:func:`fixture_of_plan`).
    """
    from fixplan.files import file_sha256

    path = Path(path)
    return {"fixture": str(path.resolve()), "fixture_sha256": file_sha256(path)}


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
    from fixplan.files import file_sha256

    obj = data if isinstance(data, dict) else {}
    named, digest = obj.get("fixture"), obj.get("fixture_sha256")
    if named is not None and not (isinstance(named, str) and named):
        raise InputError(f"{plan}: fixture: expected the fixture file's path, got {shorten(repr(named))}")
    if digest is not None and not (isinstance(digest, str) and _SHA256.fullmatch(digest)):
        raise InputError(f"{plan}: fixture_sha256: expected 64 lowercase hex digits, got {shorten(repr(digest))}")
    if given is not None:
        note = None
        if digest is not None and given.is_file() and file_sha256(given) != digest:
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
    if digest is not None and (now := file_sha256(found)) != digest:
        raise InputError(
            f"{plan}: the fixture {found} changed since the plan was made (SHA-256 {digest[:12]}… then, "
            f"{now[:12]}… now): solve it again ('fixplan solve {quote(str(found))} --out {quote(str(plan))} --force'), "
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
    """The TOML document, or :class:`FixtureError` keyed ``<toml>`` saying what is wrong."""
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
    text: str, source: str = "<string>", base_dir: Path | None = None, tolerances: Tolerances = DEFAULT
) -> Fixture:
    """Validate fixture TOML text (see :func:`load`)."""
    return _Builder(parse_toml(text, source), source, base_dir or Path("."), tolerances).build()


class _Builder:
    """Reads one parsed TOML document into a Fixture, collecting every issue."""

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
        r, data = self.r, self.data
        r.unknown_keys(
            data, ("format", "scene", "workpiece", "locator", "contact", "obstacle", "manipulator", "simulation"), ""
        )
        fmt = r.integer(data, "format", "format", required=True, allowed=(1,))
        del fmt
        scene = r.table(data, "scene", "scene", required=True) or {}
        r.unknown_keys(scene, ("name", "dimension", "gravity"), "scene")
        name = r.string(scene, "name", "scene.name", required=True) or "?"
        if not name.isprintable() or len(name) > 200:
            r.error("scene.name", "expected a printable name of at most 200 characters (no newlines or control codes)")
            name = "?"
        dim = (
            r.integer(scene, "dimension", "scene.dimension", required=False, allowed=(2, 3))
            if "dimension" in scene
            else 3
        )
        if dim is None:
            # Without a valid dimension nothing else can be checked meaningfully.
            raise FixtureError(self.source, r.issues)
        default_g = [0.0, 0.0, -9.81] if dim == 3 else [0.0, -9.81]
        gravity = r.vector(
            scene, "gravity", "scene.gravity", dim, default=default_g, dimension_hint=dim, bounds=limits.GRAVITY
        )

        self.check_entry_count()
        wp_table = r.table(data, "workpiece", "workpiece", required=True) or {}
        workpiece, start, goal = self.workpiece(wp_table, dim)
        locators = self.locators(dim, workpiece)
        contacts = self.explicit_contacts(dim)
        obstacles = self.obstacles(dim)
        manipulator = self.manipulator()
        simulation = self.simulation()
        names = [loc.name for loc in locators] + [c.name for c in contacts]
        if not names and not r.issues:
            r.error("locator", "no [[locator]] or [[contact]] entries (expected at least one)")
        self.fail_if_issues()
        if workpiece is None or start is None or gravity is None:  # pragma: no cover - issues were recorded
            raise FixtureError(self.source, [Issue("workpiece", "could not be read")])
        fixture = Fixture(
            source=self.source,
            name=name,
            dimension=dim,
            gravity=np.array(gravity),
            workpiece=workpiece,
            locators=tuple(locators),
            contacts=tuple(contacts),
            manipulator=manipulator,
            simulation=simulation,
            start=start,
            goal_given=goal,
            tolerances=self.tol,
            obstacles=tuple(obstacles),
        )
        fixture = with_free_motions(fixture)  # fewer locators that leave only the part's symmetry free
        goal = self.check_geometry(fixture)
        self.check_obstacles(fixture, goal)
        self.fail_if_issues()
        fixture = replace(fixture, goal_pose=goal, goal_starts=self.goal_starts, warnings=tuple(self.warnings))
        return settle_free_motions(fixture)

    def check_entry_count(self) -> None:
        """At most :data:`~fixplan.limits.MAX_ENTRIES` locators and contacts, refused before any is read."""
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

    # -- workpiece ---------------------------------------------------------------------------
    def workpiece(self, t: dict, dim: int) -> tuple[Workpiece | None, Pose | None, Pose | None]:
        r = self.r
        shapes = SHAPES_3D if dim == 3 else SHAPES_2D
        allowed = ("shape", "size", "radius", "length", "vertices", "file", "mass", "inertia", "start", "goal")
        r.unknown_keys(t, allowed, "workpiece")
        if not t and "workpiece" not in self.data:
            return None, None, None
        kind = t.get("shape")
        other = SHAPES_2D if dim == 3 else SHAPES_3D
        if isinstance(kind, str) and kind in other:
            r.error(
                "workpiece.shape",
                f"got {kind!r}, a {5 - dim}D shape (expected one of: {', '.join(shapes)} for a {dim}D scene)",
            )
            kind = None
        else:
            kind = r.string(t, "shape", "workpiece.shape", required=True, choices=shapes)
        shape: Shape | None = None
        used = {"shape", "mass", "inertia", "start", "goal"}
        if kind == "box":
            size = r.vector(
                t, "size", "workpiece.size", 3, required=True, dimension_hint=3, bounds=_SIZE, too_large=UNITS_HINT
            )
            used.add("size")
            if size is not None and self.positive_all(size, "workpiece.size", "edge lengths > 0"):
                shape = Box(tuple(size))  # type: ignore[arg-type]
        elif kind == "rectangle":
            size = r.vector(
                t, "size", "workpiece.size", 2, required=True, dimension_hint=2, bounds=_SIZE, too_large=UNITS_HINT
            )
            used.add("size")
            if size is not None and self.positive_all(size, "workpiece.size", "side lengths > 0"):
                shape = Rectangle(tuple(size))  # type: ignore[arg-type]
        elif kind in ("sphere", "disk"):
            radius = r.number(
                t,
                "radius",
                "workpiece.radius",
                required=True,
                exclusive_minimum=0.0,
                bounds=_SIZE,
                what="a radius",
                too_large=UNITS_HINT,
            )
            used.add("radius")
            if radius is not None:
                shape = Sphere(radius) if kind == "sphere" else Disk(radius)
        elif kind == "cylinder":
            radius = r.number(
                t,
                "radius",
                "workpiece.radius",
                required=True,
                exclusive_minimum=0.0,
                bounds=_SIZE,
                what="a radius",
                too_large=UNITS_HINT,
            )
            length = r.number(
                t,
                "length",
                "workpiece.length",
                required=True,
                exclusive_minimum=0.0,
                bounds=_SIZE,
                what="a length",
                too_large=UNITS_HINT,
            )
            used |= {"radius", "length"}
            if radius is not None and length is not None:
                shape = Cylinder(radius, length)
        elif kind == "polygon":
            used.add("vertices")
            shape = self.polygon(t)
        elif kind == "mesh":
            used.add("file")
            r.error("workpiece.shape", "mesh workpieces are not supported yet (expected box, cylinder or sphere)")
        if kind is not None:
            for key in t:
                if key not in used and key in allowed:
                    r.error(f"workpiece.{key}", f"not used by shape {kind!r} (remove it)")
        mass = r.number(
            t, "mass", "workpiece.mass", required=True, exclusive_minimum=0.0, bounds=limits.MASS, what="a mass [kg]"
        )
        inertia = self.inertia(t, dim)
        start = self.pose(t, "start", dim, required=False) or Pose.identity(dim)
        goal = self.pose(t, "goal", dim, required=False)
        if shape is None or mass is None:
            return None, start, goal
        if inertia is not None and not self.check_inertia(inertia, shape, mass):
            return None, start, goal
        I_b = inertia if inertia is not None else shape.inertia_body(mass)
        self.check_density(shape, mass, dim)
        return Workpiece(shape, mass, I_b, shape.com_body), start, goal

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

    def positive_all(self, values: list[float], path: str, what: str) -> bool:
        bad = [i for i, v in enumerate(values) if v <= 0]
        for i in bad:
            self.r.error(f"{path}[{i}]", f"got {values[i]:g} (expected {what})")
        return not bad

    def polygon(self, t: dict) -> Polygon | None:
        r = self.r
        if "vertices" not in t:
            r.error("workpiece.vertices", "missing (expected a list of [x, y] vertices, counter-clockwise)")
            return None
        raw = t["vertices"]
        if not isinstance(raw, list) or len(raw) < 3:
            r.error("workpiece.vertices", "expected at least 3 [x, y] vertices, counter-clockwise")
            return None
        verts = []
        for i, _ in enumerate(raw):
            v = r.vector(
                {"v": raw[i]}, "v", f"workpiece.vertices[{i}]", 2, required=True, dimension_hint=2, bounds=_VERTEX
            )
            if v is None:
                return None
            verts.append(v)
        V = np.array(verts)
        E = np.roll(V, -1, axis=0) - V
        if np.any(np.linalg.norm(E, axis=1) <= 1e-12):
            r.error("workpiece.vertices", "two consecutive vertices coincide (expected distinct vertices)")
            return None
        cross = E[:, 0] * np.roll(E, -1, axis=0)[:, 1] - E[:, 1] * np.roll(E, -1, axis=0)[:, 0]
        if np.all(cross < 0):
            r.error("workpiece.vertices", "vertices are clockwise (expected counter-clockwise)")
            return None
        if not np.all(cross > 0):
            r.error(
                "workpiece.vertices", "polygon is not strictly convex (expected a convex polygon, counter-clockwise)"
            )
            return None
        extent = float(np.min(V.max(axis=0) - V.min(axis=0)))
        if extent < _SIZE.low:
            r.error("workpiece.vertices", f"the polygon is {extent:.3g} m across (expected a width {_SIZE.expected()})")
            return None
        return Polygon(tuple((float(v[0]), float(v[1])) for v in verts))

    def inertia(self, t: dict, dim: int) -> FloatArray | None:
        r = self.r
        if "inertia" not in t:
            return None
        if dim == 2:
            izz = r.number(t, "inertia", "workpiece.inertia", exclusive_minimum=0.0, what="Izz [kg·m²]")
            return None if izz is None else np.array([[izz]])
        vals = r.vector(
            t, "inertia", "workpiece.inertia", 3, what="principal moments [Ixx, Iyy, Izz]", dimension_hint=3
        )
        if vals is None:
            return None
        a, b, c = vals
        if min(vals) <= 0.0:
            r.error("workpiece.inertia", f"got {vals} (expected a positive-definite inertia: every moment > 0)")
            return None
        if a + b < c or a + c < b or b + c < a:
            r.error(
                "workpiece.inertia",
                f"got {vals} (expected moments satisfying the triangle inequality, as any rigid body does)",
            )
            return None
        return np.diag(vals)

    def pose(self, t: dict, key: str, dim: int, *, required: bool) -> Pose | None:
        return self._pose_table(t, key, f"workpiece.{key}", dim, required=required)

    def _pose_table(self, t: dict, key: str, path: str, dim: int, *, required: bool) -> Pose | None:
        r = self.r
        tab = r.table(t, key, path, required=required)
        if tab is None:
            return None
        if dim == 3:
            r.unknown_keys(tab, ("position", "rpy_deg"), path)
            pos = r.vector(
                tab, "position", f"{path}.position", 3, required=True, dimension_hint=3, bounds=limits.COORDINATE
            )
            rpy = r.vector(
                tab, "rpy_deg", f"{path}.rpy_deg", 3, default=[0.0, 0.0, 0.0], dimension_hint=3, bounds=limits.ANGLE
            )
            if pos is None or rpy is None:
                return None
            return Pose.from_rpy_deg(pos, rpy)
        r.unknown_keys(tab, ("position", "angle_deg"), path)
        pos = r.vector(
            tab, "position", f"{path}.position", 2, required=True, dimension_hint=2, bounds=limits.COORDINATE
        )
        ang = r.number(tab, "angle_deg", f"{path}.angle_deg", default=0.0, bounds=limits.ANGLE, what="an angle [deg]")
        if pos is None or ang is None:
            return None
        return Pose.from_angle_deg(pos, ang)

    # -- locators and contacts ------------------------------------------------------------------
    def _entry_path(self, kind: str, entry: dict, index: int, seen: set[str]) -> tuple[str, str | None]:
        """``locator.NAME`` for an entry with a valid name (even a duplicate), else ``locator[INDEX]``."""
        name = entry.get("name")
        if isinstance(name, str) and NAME_PATTERN.fullmatch(name):
            return f"{kind}.{name}", name
        return f"{kind}[{index}]", None

    def locators(self, dim: int, workpiece: Workpiece | None) -> list[Locator]:
        r = self.r
        out: list[Locator] = []
        seen: set[str] = set()
        for i, entry in enumerate(r.tables(self.data, "locator", "locator")):
            path, _ = self._entry_path("locator", entry, i, seen)
            r.unknown_keys(entry, ("name", "position", "radius", "friction", "torsion", "face"), path)
            name = self._name(entry, path, seen)
            pos = r.vector(
                entry, "position", f"{path}.position", dim, required=True, dimension_hint=dim, bounds=limits.COORDINATE
            )
            radius = r.number(
                entry,
                "radius",
                f"{path}.radius",
                default=0.0,
                minimum=0.0,
                bounds=limits.TIP_RADIUS,
                what="a tip radius [m]",
            )
            mu = r.number(
                entry,
                "friction",
                f"{path}.friction",
                required=True,
                minimum=0.0,
                bounds=limits.FRICTION,
                what="a friction coefficient",
            )
            torsion = self._torsion(entry, path, dim)
            face = None
            if "face" in entry:
                kind = workpiece.shape.name if workpiece is not None else None
                faces = FACES.get(kind or "", ())
                if kind is not None and not faces:
                    r.error(f"{path}.face", f"shape {kind!r} has no named faces (expected no face hint)")
                elif kind is not None:
                    face = r.string(entry, "face", f"{path}.face", choices=faces)
            if None in (name, pos, radius, mu, torsion):
                continue
            out.append(Locator(name, np.array(pos), radius, mu, torsion, face))  # type: ignore[arg-type]
        return out

    def _name(self, entry: dict, path: str, seen: set[str]) -> str | None:
        name = entry.get("name")
        if name is None:
            self.r.error(f"{path}.name", "missing (expected a unique name)")
            return None
        if not isinstance(name, str) or not name.strip():
            self.r.error(f"{path}.name", "expected a non-empty string")
            return None
        if not NAME_PATTERN.fullmatch(name):
            self.r.error(f"{path}.name", f"got {shorten(name)} (expected {NAME_RULE})")
            return None
        if name in seen:
            self.r.error(f"{path}.name", f"{name!r} is used twice (expected unique names)")
            return None
        seen.add(name)
        self.all_names.add(name)
        return name

    @cached_property
    def all_names(self) -> set[str]:
        return set()

    def _torsion(self, entry: dict, path: str, dim: int) -> float | None:
        if "torsion" not in entry:
            return 0.0
        if dim == 2:
            self.r.error(f"{path}.torsion", "torsional friction is 3D only (remove it in a 2D scene)")
            return None
        return self.r.number(
            entry, "torsion", f"{path}.torsion", minimum=0.0, bounds=limits.TORSION, what="a torsional radius [m]"
        )

    def explicit_contacts(self, dim: int) -> list[ExplicitContact]:
        r = self.r
        out: list[ExplicitContact] = []
        seen = set(self.all_names)
        for i, entry in enumerate(r.tables(self.data, "contact", "contact")):
            path, _ = self._entry_path("contact", entry, i, seen)
            r.unknown_keys(entry, ("name", "point", "normal", "friction", "torsion"), path)
            name = self._name(entry, path, seen)
            point = r.vector(
                entry, "point", f"{path}.point", dim, required=True, dimension_hint=dim, bounds=limits.COORDINATE
            )
            normal = r.vector(entry, "normal", f"{path}.normal", dim, required=True, dimension_hint=dim)
            if normal is not None:
                scale = float(np.max(np.abs(normal)))  # normalised in two steps: [1e300, 1e300] does not overflow
                if scale <= 1e-12 or not np.isfinite(np.linalg.norm(np.array(normal) / scale)):
                    r.error(f"{path}.normal", "got a zero vector (expected a direction)")
                    normal = None
                else:
                    normal = list(np.array(normal) / scale)
            mu = r.number(
                entry,
                "friction",
                f"{path}.friction",
                required=True,
                minimum=0.0,
                bounds=limits.FRICTION,
                what="a friction coefficient",
            )
            torsion = self._torsion(entry, path, dim)
            if name is None or point is None or normal is None or mu is None or torsion is None:
                continue
            n = np.array(normal) / np.linalg.norm(normal)
            out.append(ExplicitContact(name, np.array(point), n, mu, torsion))  # type: ignore[arg-type]
        return out

    def obstacles(self, dim: int) -> list[Obstacle]:
        """``[[obstacle]]``: collision-only bodies (a floor plane, a base plate box; 2D: line, rectangle)."""
        r = self.r
        out: list[Obstacle] = []
        seen = set(self.all_names)
        entries = r.tables(self.data, "obstacle", "obstacle")
        if len(entries) > limits.MAX_ENTRIES:
            r.error("obstacle", f"{len(entries)} [[obstacle]] entries (expected at most {limits.MAX_ENTRIES})")
            return out
        plane, box = OBSTACLE_SHAPES[dim]
        for i, entry in enumerate(entries):
            path, _ = self._entry_path("obstacle", entry, i, seen)
            kind = entry.get("shape")
            if kind == "mesh":
                r.error(f"{path}.shape", "mesh obstacles come later, with CAD meshes (expected plane or box for now)")
                continue
            r.unknown_keys(entry, ("name", "shape", "point", "normal", "size", "pose", "friction"), path)
            name = self._name(entry, path, seen)
            kind = r.string(entry, "shape", f"{path}.shape", required=True, choices=(plane, box))
            mu = r.number(
                entry, "friction", f"{path}.friction", default=OBSTACLE_FRICTION, minimum=0.0,
                bounds=limits.FRICTION, what="a friction coefficient",
            )  # fmt: skip
            for key in ("size", "pose") if kind == plane else ("point", "normal") if kind == box else ():
                if key in entry:
                    r.error(
                        f"{path}.{key}",
                        f"not a key of a {kind} (expected {'point, normal' if kind == plane else 'size, pose'})",
                    )
            frame = None
            half = np.zeros(0)
            if kind == plane:
                point = r.vector(
                    entry, "point", f"{path}.point", dim, required=True, dimension_hint=dim, bounds=limits.COORDINATE
                )
                normal = r.vector(
                    entry, "normal", f"{path}.normal", dim, required=True, dimension_hint=dim, bounds=limits.NORMAL
                )
                if normal is not None:
                    scale = float(np.max(np.abs(normal)))
                    if scale <= 1e-12:
                        r.error(f"{path}.normal", "got a zero vector (expected the direction of the free side)")
                        normal = None
                if point is not None and normal is not None:
                    frame = plane_frame(np.array(point), np.array(normal) / scale)
            elif kind == box:
                size = r.vector(
                    entry,
                    "size",
                    f"{path}.size",
                    dim,
                    required=True,
                    dimension_hint=dim,
                    bounds=_SIZE,
                    too_large=UNITS_HINT,
                )
                pose = self._pose_table(entry, "pose", f"{path}.pose", dim, required=True)
                if size is not None and pose is not None:
                    frame, half = (pose.R_world_body, pose.p_world), np.array(size) / 2.0
            if name is None or mu is None or frame is None or kind is None:
                continue
            out.append(Obstacle(name, kind, frame[0], frame[1], half, mu))
        return out

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

    def manipulator(self) -> Manipulator:
        r = self.r
        t = r.table(self.data, "manipulator", "manipulator", required=False)
        if t is None:
            return Manipulator()
        r.unknown_keys(t, ("max_force", "max_torque"), "manipulator")
        f = r.number(
            t,
            "max_force",
            "manipulator.max_force",
            default=float("inf"),
            exclusive_minimum=0.0,
            bounds=limits.MAX_FORCE,
            what="a force [N]",
        )
        m = r.number(
            t,
            "max_torque",
            "manipulator.max_torque",
            default=float("inf"),
            exclusive_minimum=0.0,
            bounds=limits.MAX_TORQUE,
            what="a torque [N·m]",
        )
        return Manipulator(f if f is not None else float("inf"), m if m is not None else float("inf"))

    def simulation(self) -> SimulationSettings:
        r = self.r
        t = r.table(self.data, "simulation", "simulation", required=False)
        if t is None:
            return SimulationSettings()
        r.unknown_keys(t, ("timestep", "restitution", "tolerance"), "simulation")
        h = r.number(
            t,
            "timestep",
            "simulation.timestep",
            default=1e-3,
            exclusive_minimum=0.0,
            maximum=1.0,
            bounds=limits.TIMESTEP,
            what="a time step [s]",
        )
        e = r.number(
            t,
            "restitution",
            "simulation.restitution",
            default=0.0,
            minimum=0.0,
            maximum=1.0,
            bounds=limits.RESTITUTION,
            what="a restitution coefficient",
        )
        tol = r.number(
            t,
            "tolerance",
            "simulation.tolerance",
            default=1e-8,
            exclusive_minimum=0.0,
            maximum=1.0,
            bounds=limits.SOLVER_TOLERANCE,
            what="a solver tolerance",
        )
        return SimulationSettings(h or 1e-3, e or 0.0, tol or 1e-8)

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
        if r.issues or not fixture.is_full:
            if fixture.goal_given is not None and not fixture.is_full and not r.issues:
                r.error(
                    "workpiece.goal",
                    f"a goal needs a full fixture ({6 if fixture.dimension == 3 else 3} locators); this one has {len(locs)}",
                )
            return None
        if fixture.goal_given is not None:
            goal = fixture.goal_given
            for loc in locs:
                gap = locator_contact(wp, goal, loc).gap_m
                if abs(gap) > tol.goal_gap_m:
                    r.error(
                        "workpiece.goal",
                        f"locator {loc.name} does not touch at the given goal (gap {gap:.3g} m; expected |gap| ≤ {tol.goal_gap_m:g} m)",
                    )
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
