"""A cylindrical pin in a cylindrical hole: the contacts in closed form (world frame, metres).

A *pin* is a cylinder of radius ``r`` from its base ``b`` along its unit axis ``u`` (base to tip)
for ``length_m``, its tip chamfered at 45° by ``chamfer_m`` (its side ends at ``s = L − c_p``); a
diamond pin keeps only two lands of its side, the arcs of width ``land_width_m`` centred on
``±land_direction``. A *hole* is a cylinder of radius ``R`` from its mouth ``m`` into the material
along ``−a`` (``a`` points out of the body through the mouth) for ``depth_m``, its mouth
chamfered at 45° by ``chamfer_m`` (its wall begins at depth ``c_h``), blind or through.

The same pair serves a fixture pin in a workpiece hole (``[[pin]]`` in ``[[workpiece.hole]]``) and a
workpiece peg in a fixture bore (``[[bore]]``): every contact carries the point on each body and the
normal from the pin into the hole's body, and the caller takes the workpiece's side.

Contacts (each an edge on a surface, exact):

- ``"rim"``: the circle where the pin's side ends on the hole's wall: the rim's point farthest from
  the hole's axis; gap ``R − ρ_max``; normal the wall's, radially outward.
- ``"mouth"``: the circle where the hole's wall begins on the pin's side: the circle's point nearest
  the pin's axis; gap ``d_min − r``; normal the pin side's, radially outward from the pin's axis.

  Each counts only where the side and the wall are the nearest surfaces: a rim point inside the
  hole's body nearer the mouth's chamfer or the face around it than the wall (its overlap ``−gap``
  more than its distance to the mouth's profile, :func:`_mouth_distance`), or a mouth point inside
  the pin nearer its tip's chamfer or face than its side (:func:`_tip_distance`), is the tip's and
  the face's business. A tip just past a sharp mouth with its axis beyond the play (a shaft landing
  beside the bore) overlaps the wall by the offset less the play, but lies a hair under the mouth's
  plane: its contact is the mouth's edge on its face, gap that hair; counting the overlap threw the
  part sideways into the hole.
- ``"exit"``: a through hole's far edge on the pin's side, once the rim has passed it.
- ``"bottom"``: the pin's tip face on a blind hole's bottom: the face's deepest point; gap
  ``depth − z``; normal ``−a``.
- ``"tip"``: the tip entering the mouth: the hole's mouth edges (the chamfer's top and bottom
  circles) on the pin's tip chamfer or face, and the pin's rim and tip circles on the hole's
  chamfer. A point's distance to a surface of revolution is its distance in the half-plane
  ``(t, ρ)`` of that axis to the surface's profile (a segment, or a corner); the least over the
  edge circle is sampled and refined by golden section (a land's ends are candidates too: a land
  ends abruptly, and the least may be at its end). A diamond pin's tip, like its side, is its
  lands only: the relief across them runs through the tip, so a hole's edge meets the tip's
  chamfer or face only where its direction from the pin's axis is within a land; and each land has
  its own tip contacts (a diamond pin in a hole's chamfer rests on both lands at once).

Why these suffice for the side: along a generator line of one cylinder the distance from the other's
axis is convex, so the overlap of two straight cylinders over the engaged length is extreme at its
ends, the rim and the mouth (or exit): a tilted pin's line contact resolves to these two points
(Whitney's one- and two-point contact), and a coaxial one's to either (both at ``(D − d)/2``).

Each extreme is found on its circle ``x(φ) = c + ρ (cos φ e1 + sin φ e2)``: the squared distance
``|w + A cos φ + B sin φ|²`` from the other axis is a trigonometric quadratic; it is sampled
(``PinSettings.rim_samples``) and its stationary point refined by Newton to machine precision.

The pin's tip on the face around the hole (:func:`tip_face_contacts`, kind ``"face"``): a pin that
misses its hole by more than the chamfers capture lands on the part's face. A hole whose mouth
lies in a planar face of the part (:func:`mouth_face`: a box's face, a cylinder's end, the face's
extent from the shape in closed form; a mesh part's rectangular face of coplanar triangles around
the mouth, found once when the engine sets up the pins) carries that face (:class:`MouthFace`: the plane
through the mouth with the face's outward normal ``n``, its rectangle or disk). The tip is convex,
so its point nearest a plane lies on one of its two edge circles, the tip face's (radius
``r − c_p`` at ``L``) and the chamfer's base (radius ``r`` at ``L − c_p``): on the nearer one, at
the angle of ``d = −(n − (n·u) u)``, the way down to the face within the circle's plane (``|d|``
is the sine of the tilt). Gap: that point's height ``(x − o)·n`` above the face; normal ``−n``, from
the pin into the part. A tip flat on the face (``|d|`` below ``coaxial_rel``) takes the point
farthest from the hole's axis. The point counts where it lies over the face's material: outside
the mouth's outer edge (``R + c_h`` from the hole's axis) and within the face's extent; below the
face only while the face is its nearest surface (deeper than its distance to the mouth's edge or
to the extent's, it is the hole's or the part's side's business, as for the tip's other contacts).
A bore (``[[bore]]``) has the fixture's face around its mouth (:func:`bore_face`: the plane of the
mouth normal to its axis, unbounded), where a shaft's leading end lands when it misses the mouth.
A tip partly over the mouth rests on the face along a crescent: the engine's points of it add the
ends of each arc of the tip's edge over the face (a tenth of the arc in, :func:`_arc_ends_over_face`;
the deepest point and the points at fixed angles may all but one lie over the mouth).
Other holes' mouths in the same face are no material either: the engine's rows
(:mod:`fixplan.geometry._pin_kernels`) carry them with the face, so a point over one is not the
face's, and a pin within reach of another hole's mouth has its contacts with that hole too (a pin
landing on its neighbour's rim, or in it); a pin's contacts with any hole are taken only while its
tip's centre is within ``R + c_h + r`` of that hole's axis (farther, the side's closed forms,
which assume the pin at the hole, gave walls as deep as the distance). Not modelled: a mesh part's face
whose outline is not a rectangle (an L, a notch, a disk: no face),
and curved faces (a hole in a cylinder's side: no face).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fixplan.geometry.mesh import Mesh, closest_on_triangles
from fixplan.geometry.shapes import Box, Cylinder, Shape
from fixplan.settings import DEFAULT as _DEFAULT
from fixplan.settings import PinSettings

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class PinBody:
    """A pin (or a workpiece peg) in world coordinates: base ``base_world``, unit axis base → tip."""

    base_world: FloatArray
    axis_world: FloatArray
    radius_m: float
    length_m: float
    chamfer_m: float = 0.0
    land_direction_world: FloatArray | None = None  # a diamond pin: the direction its lands locate along
    land_width_m: float = 0.0

    @property
    def side_end_m(self) -> float:
        """Where the cylindrical side ends along the axis (the tip chamfer begins)."""
        return self.length_m - self.chamfer_m

    @property
    def land_half_angle_rad(self) -> float:
        """Half the angle each land spans about the axis (π/2: a round pin, all of its side)."""
        if self.land_direction_world is None:
            return math.pi / 2
        return math.asin(min(1.0, self.land_width_m / (2.0 * self.radius_m)))


@dataclass(frozen=True)
class MouthFace:
    """The planar face a hole's mouth lies in, limited to the part's extent (body or world frame, as its holder).

    ``centre`` on the face, ``normal`` its unit outward normal, ``e1`` a unit direction in it;
    a rectangle of half extents ``half_m`` along ``e1`` and ``e2 = normal × e1``, or (``disk``) a
    disk of radius ``half_m[0]``.
    """

    centre: FloatArray
    normal: FloatArray
    e1: FloatArray
    half_m: tuple[float, float]
    disk: bool = False

    def moved(self, R: FloatArray, p: FloatArray) -> MouthFace:
        """The face carried by the rigid motion ``x → R x + p`` (body to world)."""
        return MouthFace(p + R @ self.centre, R @ self.normal, R @ self.e1, self.half_m, self.disk)

    def inside_m(self, x: FloatArray) -> float:
        """How far within the face's extent the projection of ``x`` lies (negative: outside it) [m]."""
        q = x - self.centre
        q1, q2 = float(q @ self.e1), float(q @ np.cross(self.normal, self.e1))
        if self.disk:
            return self.half_m[0] - math.hypot(q1, q2)
        return min(self.half_m[0] - abs(q1), self.half_m[1] - abs(q2))


@dataclass(frozen=True)
class HoleBody:
    """A hole (or a bore) in world coordinates: mouth centre, unit axis out of its body through the mouth.

    ``face``: the planar face around the mouth (world frame) where the pin's tip can land; None: none
    modelled (a bore, a curved face, a mesh part's face that is no rectangle).
    """

    mouth_world: FloatArray
    axis_world: FloatArray
    radius_m: float
    depth_m: float
    chamfer_m: float = 0.0
    blind: bool = True
    face: MouthFace | None = None


def mouth_face(
    shape: Shape, p_body: FloatArray, axis_body: FloatArray, tol_m: float, angle_rad: float
) -> MouthFace | None:
    """The face of ``shape`` a hole's mouth lies in (body frame); None when there is none.

    A box: the face whose plane holds the mouth (within ``tol_m``) and whose outward normal is the
    hole's axis (within ``angle_rad``), its rectangle the box's other two half extents. A cylinder:
    an end face (its disk). A mesh: its coplanar triangles around the mouth, when their outline is a
    rectangle (:func:`_mesh_mouth_face`; the mesh twin of a box gets the box's face to the bit).
    Other shapes (a cylinder's side, a sphere) have none.
    """
    p, a = np.asarray(p_body, dtype=float), np.asarray(axis_body, dtype=float)
    cos_min = math.cos(angle_rad)
    if isinstance(shape, Box):
        half = shape.half
        for k in range(3):
            for sign in (1.0, -1.0):
                normal = np.zeros(3)
                normal[k] = sign
                if abs(float(p[k]) - sign * half[k]) > tol_m or float(a @ normal) < cos_min:
                    continue
                k1, k2 = (k + 1) % 3, (k + 2) % 3
                e1 = np.zeros(3)
                e1[k1] = 1.0
                face = MouthFace(half[k] * normal, normal, e1, (float(half[k1]), float(half[k2])))
                return face if face.inside_m(p) >= 0.0 else None
        return None
    if isinstance(shape, Cylinder):
        for sign in (1.0, -1.0):
            normal = np.array([0.0, 0.0, sign])
            if abs(float(p[2]) - sign * 0.5 * shape.length) > tol_m or float(a @ normal) < cos_min:
                continue
            face = MouthFace(0.5 * shape.length * normal, normal, np.array([1.0, 0.0, 0.0]), (shape.radius, 0.0), True)
            return face if face.inside_m(p) >= 0.0 else None
    if isinstance(shape, Mesh):
        return _mesh_mouth_face(shape, p, a, tol_m, cos_min)
    return None


def _mesh_mouth_face(mesh: Mesh, p: FloatArray, a: FloatArray, tol_m: float, cos_min: float) -> MouthFace | None:
    """The rectangular planar face of ``mesh`` around the mouth ``p`` (outward normal within ``cos_min`` of ``a``); None: none.

    The face's triangles: those whose three vertices lie within ``tol_m`` of the mouth's plane (normal
    ``a``) and whose outward normal is ``a``'s within the angle, connected by shared edges to the one
    nearest the mouth (a modelled bore leaves an opening there; the mouth may lie in it). Its plane: their
    area-weighted normal, through their vertices' median height. Its extent: the least-area rectangle
    whose sides run along one of its boundary edges (edges in one of its triangles) and that holds its
    vertices, taken only when the boundary covers the rectangle's whole perimeter (within ``tol_m`` of
    its sides): the face is that rectangle less its inner openings (other holes' mouths, as a box's
    face). Any other outline (an L, a notch, a disk) gives None, as a curved face: not modelled.
    """
    F = mesh.faces
    tri = mesh.vertices[F]  # (m, 3, 3)
    height = (tri - p) @ a
    flat = np.flatnonzero((mesh.face_normals @ a >= cos_min) & (np.abs(height).max(axis=1) <= tol_m))
    if flat.size == 0:
        return None
    # the flat triangles' components over shared edges (union-find), and the one nearest the mouth
    parent = list(range(flat.size))

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    owner: dict[tuple[int, int], int] = {}
    for j, t in enumerate(F[flat].tolist()):
        for u, v in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0])):
            key = (min(u, v), max(u, v))
            if key in owner:
                parent[root(j)] = root(owner[key])
            else:
                owner[key] = j
    points, _ = closest_on_triangles(p, tri[flat, 0], tri[flat, 1], tri[flat, 2])
    nearest = int(np.argmin(np.linalg.norm(points - p, axis=1)))
    ids = flat[[j for j in range(flat.size) if root(j) == root(nearest)]]
    cross = np.cross(tri[ids, 1] - tri[ids, 0], tri[ids, 2] - tri[ids, 0])
    normal = cross.sum(axis=0)
    normal = normal / np.linalg.norm(normal)
    verts = mesh.vertices[np.unique(F[ids])]
    level = float(np.median(verts @ normal))
    count: dict[tuple[int, int], int] = {}
    for t in F[ids].tolist():
        for u, v in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0])):
            key = (min(u, v), max(u, v))
            count[key] = count.get(key, 0) + 1
    boundary = np.array([key for key, c in count.items() if c == 1], dtype=np.int64).reshape(-1, 2)
    if boundary.shape[0] == 0:
        return None
    ends = mesh.vertices[boundary]  # (b, 2, 3)
    best: tuple[float, FloatArray, FloatArray, FloatArray] | None = None
    for d in ends[:, 1] - ends[:, 0]:
        e1 = d - float(d @ normal) * normal
        if float(np.linalg.norm(e1)) <= tol_m:
            continue
        e1 = e1 / np.linalg.norm(e1)
        e2 = np.cross(normal, e1)
        q = verts @ np.column_stack([e1, e2])
        lo, hi = q.min(axis=0), q.max(axis=0)
        area = float(np.prod(hi - lo))
        if best is None or area < best[0]:
            best = (area, e1, lo, hi)
    if best is None:
        return None
    _, e1, lo, hi = best
    e2 = np.cross(normal, e1)
    # the boundary's length along the rectangle's sides: the whole perimeter, or the outline is another
    q = ends @ np.column_stack([e1, e2])  # (b, 2, 2)
    on_side = np.zeros(boundary.shape[0], dtype=bool)
    for k in range(2):
        for bound in (lo[k], hi[k]):
            on_side |= np.all(np.abs(q[:, :, k] - bound) <= tol_m, axis=1)
    covered = float(np.linalg.norm(ends[on_side, 1] - ends[on_side, 0], axis=1).sum())
    if covered < 2.0 * float(np.sum(hi - lo)) - 4.0 * tol_m:
        return None
    mid = 0.5 * (lo + hi)
    centre = mid[0] * e1 + mid[1] * e2 + level * normal
    face = MouthFace(centre, normal, e1, (float(0.5 * (hi[0] - lo[0])), float(0.5 * (hi[1] - lo[1]))))
    return face if face.inside_m(p) >= 0.0 else None


def bore_face(mouth: FloatArray, axis: FloatArray, radius_m: float = math.inf) -> MouthFace:
    """The fixture's face around a bore's mouth (world frame): the plane through the mouth normal to its axis.

    A disk of ``radius_m`` about the axis (unbounded by default: the fixture's surface is wider than
    the part); the shaft's leading end rests on it where it misses the mouth.
    """
    m, a = np.asarray(mouth, dtype=float), np.asarray(axis, dtype=float)
    e1, _ = _perp_basis(a)
    return MouthFace(m.copy(), a.copy(), e1, (float(radius_m), 0.0), True)


@dataclass(frozen=True)
class PinContact:
    """One contact of a pin and its hole: the point on each, the normal from the pin into the hole's body, the gap."""

    kind: str  # "rim", "mouth", "exit", "bottom", "tip" or "face"
    point_pin_world: FloatArray
    point_hole_world: FloatArray
    normal_world: FloatArray  # unit, from the pin into the hole's body
    gap_m: float  # signed: > 0 clearance, < 0 overlap


def radial_play_m(hole_diameter_m: float, pin_diameter_m: float) -> float:
    """The radial play of a pin of diameter d in a hole of D: ``(D − d) / 2``."""
    return 0.5 * (hole_diameter_m - pin_diameter_m)


def _perp_basis(u: FloatArray, prefer: FloatArray | None = None) -> tuple[FloatArray, FloatArray]:
    """``e1, e2`` with ``(e1, e2, u)`` right-handed; ``e1`` along ``prefer``'s part normal to ``u`` when given."""
    if prefer is not None:
        e1 = prefer - (prefer @ u) * u
    else:
        k = int(np.argmin(np.abs(u)))
        e1 = np.zeros(3)
        e1[k] = 1.0
        e1 = e1 - (e1 @ u) * u
    e1 = e1 / np.linalg.norm(e1)
    return e1, np.cross(u, e1)


def _circle_extreme(
    w: FloatArray,
    A: FloatArray,
    B: FloatArray,
    largest: bool,
    arcs: list[tuple[float, float]],
    settings: PinSettings,
) -> float:
    """The angle φ within ``arcs`` at which ``|w + A cos φ + B sin φ|²`` is largest (or least)."""
    sign = 1.0 if largest else -1.0

    def f(phi: float) -> float:
        v = w + A * math.cos(phi) + B * math.sin(phi)
        return sign * float(v @ v)

    best_phi, best = arcs[0][0], -math.inf
    n = max(settings.rim_samples // len(arcs), 2)
    for lo, hi in arcs:
        for phi in np.linspace(lo, hi, n + 1):
            val = f(float(phi))
            if val > best:
                best_phi, best = float(phi), val
    lo, hi = next((a for a in arcs if a[0] <= best_phi <= a[1]), arcs[0])
    if hi - lo >= 2.0 * math.pi:  # the whole circle: nothing to clip to
        lo, hi = -math.inf, math.inf
    phi = best_phi
    for _ in range(settings.newton_steps):
        c, s = math.cos(phi), math.sin(phi)
        v = w + A * c + B * s
        dv = -A * s + B * c
        d1 = 2.0 * float(v @ dv)
        d2 = 2.0 * float(dv @ dv - v @ (A * c + B * s))
        if d2 * sign >= 0.0 or d2 == 0.0:  # not concave towards the extreme: keep the sample
            break
        step = min(max(phi - d1 / d2, lo), hi)
        if f(step) < f(phi):
            break
        phi = step
    return phi


def _land_arcs(pin: PinBody) -> list[tuple[float, float]]:
    """The angles (about the pin's axis, from ``e1`` = the land direction) its side spans."""
    if pin.land_direction_world is None:
        return [(0.0, 2.0 * math.pi)]
    alpha = pin.land_half_angle_rad
    return [(-alpha, alpha), (math.pi - alpha, math.pi + alpha)]


def _in_arcs(angle: float, arcs: list[tuple[float, float]]) -> bool:
    for lo, hi in arcs:
        if lo <= angle <= hi or lo <= angle + 2 * math.pi <= hi or lo <= angle - 2 * math.pi <= hi:
            return True
    return False


def _rim(pin: PinBody, hole: HoleBody, arcs: list[tuple[float, float]], settings: PinSettings) -> PinContact | None:
    """The pin's rim (where its side ends, within ``arcs``) on the hole's wall, when the rim is between the wall's ends."""
    u, a, m = pin.axis_world, hole.axis_world, hole.mouth_world
    centre = pin.base_world + pin.side_end_m * u
    e1, e2 = _perp_basis(u, pin.land_direction_world)
    P = np.eye(3) - np.outer(a, a)
    w, A, B = P @ (centre - m), pin.radius_m * (P @ e1), pin.radius_m * (P @ e2)
    phi = _circle_extreme(w, A, B, True, arcs, settings)
    x = centre + pin.radius_m * (math.cos(phi) * e1 + math.sin(phi) * e2)
    depth = float((m - x) @ a)
    if depth < hole.chamfer_m or depth > hole.depth_m:
        return None
    rho = P @ (x - m)
    rho_m = float(np.linalg.norm(rho))
    n = rho / rho_m if rho_m > 0.0 else e1
    gap = hole.radius_m - rho_m
    if gap < 0.0 and -gap > _mouth_distance(hole, np.array([depth, rho_m])):
        return None  # in the body, nearer the mouth's face or chamfer than the wall: not the wall's
    return PinContact("rim", x, x + gap * n, n, gap)


def _edge(
    pin: PinBody, hole: HoleBody, depth_m: float, kind: str, arcs: list[tuple[float, float]], settings: PinSettings
) -> PinContact | None:
    """The hole's edge circle at ``depth_m`` on the pin's side within ``arcs``, when the side spans that level.

    A round pin's whole side: the circle's point nearest the pin's axis (Newton). A diamond's land:
    the nearest point whose direction from the axis the land faces (sampled, then golden section:
    at the land's end when the nearest point overall faces the relief).
    """
    u, a = pin.axis_world, hole.axis_world
    centre = hole.mouth_world - depth_m * a
    h1, h2 = _perp_basis(a)
    P = np.eye(3) - np.outer(u, u)
    R = hole.radius_m

    def point(phi: float) -> FloatArray:
        return centre + R * (math.cos(phi) * h1 + math.sin(phi) * h2)

    if pin.land_direction_world is None:
        w, A, B = P @ (centre - pin.base_world), R * (P @ h1), R * (P @ h2)
        phi: float | None = _circle_extreme(w, A, B, False, [(0.0, 2.0 * math.pi)], settings)
    else:
        e1, e2 = _perp_basis(u, pin.land_direction_world)

        def gap_of(t: float) -> float | None:
            v = P @ (point(t) - pin.base_world)
            if not _in_arcs(math.atan2(float(v @ e2), float(v @ e1)), arcs):
                return None
            return float(np.linalg.norm(v)) - pin.radius_m

        ends = _land_end_angles(P @ (centre - pin.base_world), R * (P @ h1), R * (P @ h2), e1, e2, arcs)
        phi = _least_on_circle(gap_of, settings, ends)
    if phi is None:
        return None
    y = point(phi)
    s = float((y - pin.base_world) @ u)
    if s < 0.0 or s > pin.side_end_m:
        return None
    v = P @ (y - pin.base_world)
    d = float(np.linalg.norm(v))
    if d == 0.0:
        return None
    n = v / d
    x = pin.base_world + s * u + pin.radius_m * n
    gap = d - pin.radius_m
    if kind == "mouth" and gap < 0.0 and -gap > _tip_distance(pin, np.array([s, d])):
        return None  # in the pin, nearer its tip's face or chamfer than its side: the tip's contact
    return PinContact(kind, x, y, n, gap)


def _bottom(pin: PinBody, hole: HoleBody, settings: PinSettings) -> PinContact | None:
    """The pin's tip face on a blind hole's bottom, when the tip is in the hole."""
    u, a, m = pin.axis_world, hole.axis_world, hole.mouth_world
    tip = pin.base_world + pin.length_m * u
    down = -a - float(-a @ u) * u  # the way down the hole, within the tip face
    rho = pin.radius_m - pin.chamfer_m
    norm = float(np.linalg.norm(down))
    x = tip + rho * down / norm if norm > settings.coaxial_rel else tip
    depth = float((m - x) @ a)
    if depth < hole.chamfer_m:
        return None
    gap = hole.depth_m - depth
    return PinContact("bottom", x, x - gap * a, -a, gap)


# -- the tip entering the mouth: edges on the chamfers, in the plane (t, ρ) of each body's axis -------------
# A point's distance to a surface of revolution is its distance, in the half-plane (t along the axis,
# ρ from it), to the surface's profile: exact for the circles of the other body, point by point.
_SQRT_HALF = math.sqrt(0.5)


def _nearest_on_segment(q: FloatArray, a: FloatArray, b: FloatArray) -> tuple[FloatArray, float]:
    """The point of segment ``ab`` nearest ``q`` and its parameter in [0, 1]."""
    d = b - a
    dd = float(d @ d)
    t = 0.0 if dd == 0.0 else min(max(float((q - a) @ d) / dd, 0.0), 1.0)
    return a + t * d, t


def _mouth_distance(hole: HoleBody, q: FloatArray) -> float:
    """Distance of ``q = (depth, ρ)`` (hole frame) from the mouth's profile: its chamfer and the face around it."""
    c, R = hole.chamfer_m, hole.radius_m
    top = np.array([0.0, R + c])
    face = abs(float(q[0])) if q[1] >= R + c else float(np.linalg.norm(q - top))
    if c <= 0.0:
        return face
    p, _ = _nearest_on_segment(q, top, np.array([c, R]))
    return min(face, float(np.linalg.norm(q - p)))


def _tip_distance(pin: PinBody, q: FloatArray) -> float:
    """Distance of ``q = (t, ρ)`` (pin frame) from the pin's tip: its chamfer and its face."""
    L, r, c = pin.length_m, pin.radius_m, pin.chamfer_m
    corner = np.array([L, r - c])
    p, _ = _nearest_on_segment(q, corner, np.array([L, 0.0]))
    d = float(np.linalg.norm(q - p))
    if c > 0.0:
        p, _ = _nearest_on_segment(q, np.array([L - c, r]), corner)
        d = min(d, float(np.linalg.norm(q - p)))
    return d


def _in_cone(v: FloatArray, n1: FloatArray, n2: FloatArray) -> bool:
    """``v`` between the unit normals ``n1`` and ``n2`` (less than π apart), boundaries included."""
    cross = lambda x, y: float(x[0] * y[1] - x[1] * y[0])  # noqa: E731
    return cross(n1, v) * cross(n1, n2) >= 0.0 and cross(v, n2) * cross(n1, n2) >= 0.0


def _pin_tip_gap(pin: PinBody, q: FloatArray) -> tuple[float, FloatArray] | None:
    """Signed distance of a point ``q = (t, ρ)`` (pin frame) from the pin's tip: its chamfer and face.

    The free-side normal ``(n_t, n_ρ)`` with it; None where the nearest point is on the side (the rim
    and mouth contacts' business) or the tip's nearest feature does not face ``q``.
    """
    L, r, c = pin.length_m, pin.radius_m, pin.chamfer_m
    a, b, e = np.array([L - c, r]), np.array([L, r - c]), np.array([L, 0.0])
    side, cham, face = np.array([0.0, 1.0]), np.array([_SQRT_HALF, _SQRT_HALF]), np.array([1.0, 0.0])
    p1, t1 = _nearest_on_segment(q, a, b)
    p2, t2 = _nearest_on_segment(q, b, e)
    d1, d2 = float(np.linalg.norm(q - p1)), float(np.linalg.norm(q - p2))
    if c > 0.0 and d1 <= d2:
        p, n = p1, cham
        if t1 == 0.0:  # the rim's corner: facing q between the side and the chamfer
            v = q - p
            if not _in_cone(v, side, cham):
                return None
            n = v / np.linalg.norm(v) if np.linalg.norm(v) > 0.0 else cham
        elif t1 == 1.0 and not _in_cone(q - p, cham, face):
            return None
    else:
        p, n = p2, face
        if t2 == 0.0:  # the tip's corner (no chamfer: the rim's)
            v = q - p
            if not _in_cone(v, side if c == 0.0 else cham, face):
                return None
            n = v / np.linalg.norm(v) if np.linalg.norm(v) > 0.0 else face
        elif t2 == 1.0:
            return None  # the axis
    gap = float((q - p) @ n)
    if gap < 0.0 and r - float(q[1]) < -gap:
        return None  # inside the pin, nearer its side: the rim and mouth contacts' business
    return gap, n


def _hole_chamfer_gap(hole: HoleBody, q: FloatArray) -> tuple[float, FloatArray] | None:
    """Signed distance of ``q = (depth, ρ)`` (hole frame) from the mouth chamfer's face, its free normal; None off the face."""
    c = hole.chamfer_m
    if c <= 0.0:
        return None
    a, b = np.array([0.0, hole.radius_m + c]), np.array([c, hole.radius_m])
    p, t = _nearest_on_segment(q, a, b)
    if t <= 0.0 or t >= 1.0:
        return None
    n = np.array([-_SQRT_HALF, -_SQRT_HALF])
    gap = float((q - p) @ n)
    if gap < 0.0 and min(float(q[1]) - hole.radius_m, float(q[0])) < -gap:
        return None  # inside the body, nearer its wall or its face
    return gap, n


def _least_on_circle(
    gap_of: Callable[[float], float | None], settings: PinSettings, ends: Sequence[float] = ()
) -> float | None:
    """The angle where ``gap_of`` is least on a circle: sampled, then golden-section between the neighbours.

    ``ends``: a diamond's lands' ends on this circle (:func:`_land_end_angles`), candidates too: a
    land ends abruptly, and the least may be at its end, between two samples.
    """
    phis = np.linspace(0.0, 2.0 * math.pi, settings.rim_samples, endpoint=False)
    vals = [gap_of(float(p)) for p in phis]
    ok = [(v, float(p)) for v, p in zip(vals, phis, strict=True) if v is not None]
    step = 2.0 * math.pi / settings.rim_samples

    def value(x: float) -> float:
        v = gap_of(x)
        return math.inf if v is None else v

    best, phi = math.inf, 0.0
    if ok:
        best, phi = min(ok)
        lo, hi = phi - step, phi + step
        g = 0.5 * (math.sqrt(5.0) - 1.0)
        x1, x2 = hi - g * (hi - lo), lo + g * (hi - lo)
        f1, f2 = value(x1), value(x2)
        for _ in range(settings.golden_steps):
            if f1 <= f2:
                hi, x2, f2 = x2, x1, f1
                x1 = hi - g * (hi - lo)
                f1 = value(x1)
            else:
                lo, x1, f1 = x1, x2, f2
                x2 = lo + g * (hi - lo)
                f2 = value(x2)
        x = 0.5 * (lo + hi)
        fx = value(x)
        if fx <= best:
            phi, best = x, fx
    nudge = step * 2.0**-40  # just inside each end: the end itself falls on either side by rounding
    for end in ends:
        for x in (end + nudge, end - nudge):
            v = gap_of(x)
            if v is not None and v < best:
                best, phi = v, x
    return None if best == math.inf else phi


def _land_end_angles(
    w: FloatArray, A: FloatArray, B: FloatArray, e1: FloatArray, e2: FloatArray, arcs: list[tuple[float, float]]
) -> list[float]:
    """The angles φ of a circle ``w + A cos φ + B sin φ`` (from a pin's axis) whose direction is a land's end.

    The direction at angle ``β`` from ``e1``: ``across cos β − along sin β = 0``, a trigonometric
    equation ``a₀ + a₁ cos φ + a₂ sin φ = 0`` with up to two roots per end.
    """
    out = []
    for beta in [b for arc in arcs for b in arc]:
        cb, sb = math.cos(beta), math.sin(beta)
        a0 = float(w @ e2) * cb - float(w @ e1) * sb
        a1 = float(A @ e2) * cb - float(A @ e1) * sb
        a2 = float(B @ e2) * cb - float(B @ e1) * sb
        rr = math.hypot(a1, a2)
        if rr == 0.0 or abs(a0) > rr:
            continue
        mid, half = math.atan2(a2, a1), math.acos(-a0 / rr)
        out += [mid + half, mid - half]
    return out


def _hole_edges_on_tip(
    pin: PinBody, hole: HoleBody, arcs: list[tuple[float, float]], settings: PinSettings
) -> list[PinContact]:
    """The hole's mouth edges (the chamfer's top and bottom circles) on the pin's tip chamfer or face.

    A diamond pin's tip is its lands' (the relief that narrows its side across them runs through
    its tip): an edge point counts where its direction from the pin's axis is within a land, as
    for the side (:func:`_edge`) and the pin's circles on the chamfer (:func:`_tip_edges_on_chamfer`);
    ``arcs`` is one land's (:func:`pin_hole_contacts` asks for each land's least: a diamond in a
    chamfer rests on both).
    """
    u, a = pin.axis_world, hole.axis_world
    h1, h2 = _perp_basis(a)
    P = np.eye(3) - np.outer(u, u)
    e1, e2 = _perp_basis(u, pin.land_direction_world)
    edges = [(0.0, hole.radius_m + hole.chamfer_m)] + ([(hole.chamfer_m, hole.radius_m)] if hole.chamfer_m > 0 else [])
    out = []
    for depth, radius in edges:
        centre = hole.mouth_world - depth * a

        def at(phi: float, centre: FloatArray = centre, radius: float = radius) -> tuple[FloatArray, FloatArray]:
            y = centre + radius * (math.cos(phi) * h1 + math.sin(phi) * h2)
            v = P @ (y - pin.base_world)
            return y, np.array([float((y - pin.base_world) @ u), float(np.linalg.norm(v))])

        def gap_of(phi: float, at: Callable[[float], tuple[FloatArray, FloatArray]] = at) -> float | None:
            y, q = at(phi)
            if pin.land_direction_world is not None:
                v = P @ (y - pin.base_world)
                if not _in_arcs(math.atan2(float(v @ e2), float(v @ e1)), arcs):
                    return None
            found = _pin_tip_gap(pin, q)
            return None if found is None else found[0]

        ends = (
            []
            if pin.land_direction_world is None
            else _land_end_angles(P @ (centre - pin.base_world), radius * (P @ h1), radius * (P @ h2), e1, e2, arcs)
        )
        phi = _least_on_circle(gap_of, settings, ends)
        if phi is None:
            continue
        y, q = at(phi)
        found = _pin_tip_gap(pin, q)
        if found is None:
            continue
        gap, n2 = found
        v = P @ (y - pin.base_world)
        radial = v / np.linalg.norm(v) if np.linalg.norm(v) > 0.0 else _perp_basis(u)[0]
        n = n2[0] * u + n2[1] * radial
        out.append(PinContact("tip", y - gap * n, y, n, gap))
    return out


def _tip_edges_on_chamfer(
    pin: PinBody, hole: HoleBody, arcs: list[tuple[float, float]], settings: PinSettings
) -> list[PinContact]:
    """The pin's rim and tip circles on the hole's mouth chamfer, within ``arcs`` (a diamond: one land's)."""
    if hole.chamfer_m <= 0.0:
        return []
    u, a, m = pin.axis_world, hole.axis_world, hole.mouth_world
    e1, e2 = _perp_basis(u, pin.land_direction_world)
    P = np.eye(3) - np.outer(a, a)
    circles = [(pin.side_end_m, pin.radius_m)] + (
        [(pin.length_m, pin.radius_m - pin.chamfer_m)] if pin.chamfer_m > 0 else []
    )
    out = []
    for s, radius in circles:
        centre = pin.base_world + s * u

        def at(phi: float, centre: FloatArray = centre, radius: float = radius) -> tuple[FloatArray, FloatArray]:
            x = centre + radius * (math.cos(phi) * e1 + math.sin(phi) * e2)
            return x, np.array([float((m - x) @ a), float(np.linalg.norm(P @ (x - m)))])

        def gap_of(phi: float, at: Callable[[float], tuple[FloatArray, FloatArray]] = at) -> float | None:
            if not _in_arcs(phi, arcs):
                return None
            found = _hole_chamfer_gap(hole, at(phi)[1])
            return None if found is None else found[0]

        ends = [] if pin.land_direction_world is None else [b for arc in arcs for b in arc]
        phi = _least_on_circle(gap_of, settings, ends)
        if phi is None:
            continue
        x, q = at(phi)
        found = _hole_chamfer_gap(hole, q)
        if found is None:
            continue
        gap, f2 = found
        rho = P @ (x - m)
        radial = rho / np.linalg.norm(rho) if np.linalg.norm(rho) > 0.0 else e1
        free = f2[0] * (-a) + f2[1] * radial  # away from the hole's body
        out.append(PinContact("tip", x, x - gap * free, -free, gap))
    return out


def tip_face_contacts(
    pin: PinBody, hole: HoleBody, points: int = 1, settings: PinSettings = _DEFAULT.pins
) -> list[PinContact]:
    """The pin's tip on the face around the hole's mouth (kind ``"face"``; the module text), deepest point first.

    ``points`` points of the tip's nearer edge circle at equal angles from its deepest point (the
    engine's support of a tip lying flat, ``PinSettings.face_points``; 1: the deepest point only),
    each where it lies over the face's material. None without a face (``hole.face``).
    """
    face = hole.face
    if face is None:
        return []
    u, a, m, n = pin.axis_world, hole.axis_world, hole.mouth_world, face.normal
    down = -(n - float(n @ u) * u)
    sin_tilt = float(np.linalg.norm(down))
    c, rho = pin.base_world + pin.length_m * u, pin.radius_m - pin.chamfer_m
    if pin.chamfer_m > 0.0:  # the chamfer's base circle is the nearer beyond 45° of tilt
        c2 = pin.base_world + pin.side_end_m * u
        if float((c2 - face.centre) @ n) - pin.radius_m * sin_tilt < float((c - face.centre) @ n) - rho * sin_tilt:
            c, rho = c2, pin.radius_m
    if sin_tilt > settings.coaxial_rel:
        d1 = down / sin_tilt
    else:  # flat on the face: the point farthest from the hole's axis
        w = (c - m) - float((c - m) @ u) * u
        norm_w = float(np.linalg.norm(w))
        d1 = w / norm_w if norm_w > settings.coaxial_rel * hole.radius_m else _perp_basis(u)[0]
    d2 = np.cross(u, d1)
    count = points if rho > 0.0 and points > 1 else 1
    outer = hole.radius_m + hole.chamfer_m
    angles = [2.0 * math.pi * j / count for j in range(count)]
    if points > 1 and rho > 0.0:  # where the edge leaves the face for the mouth: each such arc's ends
        angles += _arc_ends_over_face(c, rho, d1, d2, m, a, outer, settings)
    out = []
    for phi in angles:
        x = c + rho * (math.cos(phi) * d1 + math.sin(phi) * d2)
        gap = float((x - face.centre) @ n)
        v = x - m
        beyond_mouth = float(np.linalg.norm(v - float(v @ a) * a)) - outer
        inside = face.inside_m(x)
        if beyond_mouth < 0.0 or inside < 0.0 or (gap < 0.0 and -gap > min(beyond_mouth, inside)):
            continue  # over the hole, off the part, or nearer the mouth's edge or the part's side
        out.append(PinContact("face", x, x - gap * n, -n, gap))
    return out


def _arc_ends_over_face(
    c: FloatArray,
    rho: float,
    d1: FloatArray,
    d2: FloatArray,
    m: FloatArray,
    a: FloatArray,
    outer: float,
    settings: PinSettings,
) -> list[float]:
    """The angles near the ends of each arc of the circle ``c + ρ (cos φ d1 + sin φ d2)`` outside the mouth's outer edge.

    A tip partly over the mouth rests on the face along a crescent, bounded by its edge's arc over
    the face: the deepest point alone (or points at fixed angles, most of them over the mouth) lets it
    tip about that point. Each arc where the circle's distance from the hole's axis exceeds
    ``outer`` (the crossings sampled at ``rim_samples`` angles, refined by ``golden_steps``
    bisections) adds two points ``face_arc_inset`` of the arc in from its ends, so strictly over
    the material. None when the whole circle is on one side.
    """
    P = np.eye(3) - np.outer(a, a)
    w, A, B = P @ (c - m), rho * (P @ d1), rho * (P @ d2)

    def f(phi: float) -> float:
        return float(np.linalg.norm(w + A * math.cos(phi) + B * math.sin(phi))) - outer

    n = settings.rim_samples
    step = 2.0 * math.pi / n
    vals = [f(k * step) for k in range(n)]
    crossings: list[tuple[float, bool]] = []  # (angle, entering the face going up in φ)
    for k in range(n):
        f0, f1 = vals[k], vals[(k + 1) % n]
        if (f0 >= 0.0) == (f1 >= 0.0):
            continue
        lo, hi = k * step, (k + 1) * step
        for _ in range(settings.golden_steps):
            mid = 0.5 * (lo + hi)
            if (f(mid) >= 0.0) == (f0 >= 0.0):
                lo = mid
            else:
                hi = mid
        crossings.append((0.5 * (lo + hi), f1 >= 0.0))
    out: list[float] = []
    for i, (start, entering) in enumerate(crossings):
        if not entering:
            continue
        end = crossings[(i + 1) % len(crossings)][0]
        span = (end - start) % (2.0 * math.pi)
        out += [start + settings.face_arc_inset * span, start + (1.0 - settings.face_arc_inset) * span]
    return out


def pin_hole_contacts(pin: PinBody, hole: HoleBody, settings: PinSettings = _DEFAULT.pins) -> list[PinContact]:
    """Every contact of ``pin`` with ``hole`` that their relative pose makes possible, with its gap.

    The rim and the mouth (a through hole's exit once the rim has passed it) for the side (a
    diamond pin: for each land, the one along ``+land_direction`` first), the
    bottom for a blind hole, and the tip entering the mouth: the hole's mouth edges on the pin's tip
    chamfer or face, the pin's rim and tip circles on the hole's mouth chamfer (``"tip"``), each
    where its nearest feature faces the other body.
    """
    out: list[PinContact] = []
    arcs = _land_arcs(pin)
    for land in [arcs] if len(arcs) == 1 else [[arc] for arc in arcs]:  # a diamond: each land on its own
        for found in (
            _rim(pin, hole, land, settings),
            _edge(pin, hole, hole.chamfer_m, "mouth", land, settings),
            None if hole.blind else _edge(pin, hole, hole.depth_m, "exit", land, settings),
        ):
            if found is not None:
                out.append(found)
    bottom = _bottom(pin, hole, settings) if hole.blind else None
    if bottom is not None:
        out.append(bottom)
    for land in [arcs] if len(arcs) == 1 else [[arc] for arc in arcs]:  # the tip too: each land on its own
        out += _hole_edges_on_tip(pin, hole, land, settings) + _tip_edges_on_chamfer(pin, hole, land, settings)
    return out


__all__ = [
    "HoleBody",
    "MouthFace",
    "PinBody",
    "PinContact",
    "bore_face",
    "mouth_face",
    "pin_hole_contacts",
    "radial_play_m",
    "tip_face_contacts",
]
