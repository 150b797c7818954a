"""Features: the surface patch a locator touches, in closed form (CasADi or numpy).

The fine planner's copy of the shape geometry, written so that CasADi can differentiate it; see
:mod:`fixplan.planner.fine` ("Gaps in closed form") for why each feature's gap is a safe lower
bound of the true signed distance of a convex part.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from fixplan.errors import InputError
from fixplan.settings import DEFAULT
from fixplan.spatial import Pose

if TYPE_CHECKING:
    from fixplan.model import Fixture, Locator

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Feature:
    """One smooth piece of a convex shape's surface, in the body frame.

    ``kind`` is ``"plane"`` (outward normal ``normal``, offset ``offset``: the plane ``n·x = h``),
    ``"round"`` (a ball of radius ``radius`` about the origin: sphere, disk), ``"side"`` (the
    lateral surface of a cylinder of radius ``radius`` about body z) or ``"box"`` (the whole
    surface of a box or rectangle of half extents ``half``: faces, edges and corners, for a
    kept contact that may cross an edge, :func:`surface_feature`). ``bounds`` are linear
    inequalities ``A x ≤ b`` that keep a point on the patch (face extents, edge segment,
    cylinder length); ``disc_radius`` bounds ``‖x_xy‖`` on a cylinder end.
    """

    kind: str
    label: str
    normal: FloatArray | None = None
    offset: float = 0.0
    radius: float = 0.0
    bounds_A: FloatArray | None = None
    bounds_b: FloatArray | None = None
    disc_radius: float | None = None
    half: FloatArray | None = None
    # ``"planes"`` (a mesh part): the least of the planes ``N_i·x = h_i`` (outward normals ``N``
    # (k, 3), offsets ``h`` (k,)), the free space of a concave region (:func:`feature_at`)
    normals: FloatArray | None = None
    offsets: FloatArray | None = None

    def _plane_gaps(self, ca: Any, q: Any) -> list[Any]:
        """``planes``: each plane's signed distance ``N_i·q − h_i``."""
        assert self.normals is not None and self.offsets is not None
        return [ca.dot(ca.DM(n), q) - float(h) for n, h in zip(self.normals, self.offsets, strict=True)]

    def _outside(self, ca: Any, q: Any) -> Any:
        """``box``: the vector from the closest point of the box to ``q`` (zero inside)."""
        h = ca.DM(self.half)
        return ca.fmax(ca.fabs(q) - h, 0) * ca.sign(q)

    def distance(self, ca: Any, q: Any) -> Any:
        """Signed distance of the body point ``q`` to the feature's surface (no tip radius).

        ``box``: the distance from outside (0 inside); C¹ wherever ``q`` lies outside, which a
        kept contact's tip centre does (it sits a tip radius off the surface).
        """
        if self.kind == "plane":
            return ca.dot(ca.DM(self.normal), q) - self.offset
        if self.kind == "planes":
            gaps = self._plane_gaps(ca, q)
            return gaps[0] if len(gaps) == 1 else ca.mmin(ca.vertcat(*gaps))
        if self.kind == "box":
            # outside: ‖v‖; inside (v = 0): the largest face-plane gap, ≤ 0 (no NaN derivative at v = 0)
            v = self._outside(ca, q)
            vv = ca.dot(v, v)
            outside = vv > 0
            inside = ca.mmax(ca.fabs(q) - ca.DM(self.half))
            return ca.if_else(outside, ca.sqrt(ca.if_else(outside, vv, 1.0)), inside)
        if self.kind == "round":
            return ca.sqrt(ca.dot(q, q)) - self.radius
        return ca.sqrt(q[0] ** 2 + q[1] ** 2) - self.radius

    def normal_at(self, ca: Any, q: Any) -> Any:
        """Outward unit normal at the projection of ``q``."""
        if self.kind == "plane":
            return ca.DM(self.normal)
        if self.kind == "planes":  # the nearest plane's normal
            assert self.normals is not None
            gaps = self._plane_gaps(ca, q)
            best, normal = gaps[0], ca.DM(self.normals[0])
            for g, n in zip(gaps[1:], self.normals[1:], strict=True):
                normal = ca.if_else(g < best, ca.DM(n), normal)
                best = ca.fmin(best, g)
            return normal
        if self.kind == "box":
            v = self._outside(ca, q)
            vv = ca.dot(v, v)
            return v / ca.sqrt(ca.if_else(vv > 0, vv, 1.0))
        if self.kind == "round":
            return q / ca.sqrt(ca.dot(q, q))
        rho = ca.sqrt(q[0] ** 2 + q[1] ** 2)
        return ca.vertcat(q[0] / rho, q[1] / rho, 0)

    def point_at(self, ca: Any, q: Any) -> Any:
        """The closest point on the feature's surface to ``q``."""
        return q - self.distance(ca, q) * self.normal_at(ca, q)

    def inside(self, ca: Any, x: Any) -> list[Any]:
        """Expressions that are ≥ 0 when the surface point ``x`` lies on the patch."""
        out = []
        if self.bounds_A is not None and self.bounds_b is not None:
            for a, b in zip(self.bounds_A, self.bounds_b, strict=True):
                out.append(b - ca.dot(ca.DM(a), x))
        if self.disc_radius is not None:
            out.append(self.disc_radius**2 - x[0] ** 2 - x[1] ** 2)
        return out


def _box_face(half: FloatArray, face: str, label: str) -> Feature:
    d = half.shape[0]
    axis = "xyz".index(face[1])
    sign = 1.0 if face[0] == "+" else -1.0
    n = np.zeros(d)
    n[axis] = sign
    A, b = [], []
    for j in range(d):
        if j == axis:
            continue
        e = np.zeros(d)
        e[j] = 1.0
        A += [e, -e]
        b += [half[j], half[j]]
    return Feature("plane", label, n, float(half[axis]), bounds_A=np.array(A), bounds_b=np.array(b))


def feature_at(fixture: Fixture, locator: Locator, pose: Pose) -> Feature:
    """The feature of the workpiece nearest to ``locator`` at ``pose``."""
    from fixplan.geometry import Box, Cylinder, Disk, Mesh, Polygon, Rectangle, Sphere

    shape = fixture.workpiece.shape
    q = pose.point_body_from_world(locator.p_world)
    proj = shape.project(q)
    if isinstance(shape, Box | Rectangle):
        face = shape.face_of(proj.point_body) or "+x"
        return _box_face(shape.half, face, face)
    if isinstance(shape, Sphere | Disk):
        return Feature("round", "surface", radius=float(shape.radius))
    if isinstance(shape, Cylinder):
        face = shape.face_of(proj.point_body) or "side"
        half_len = shape.length / 2.0
        if face == "side":
            A = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]])
            return Feature(
                "side", "side", radius=float(shape.radius), bounds_A=A, bounds_b=np.array([half_len, half_len])
            )
        sign = 1.0 if face == "+z" else -1.0
        return Feature("plane", face, np.array([0.0, 0.0, sign]), half_len, disc_radius=float(shape.radius))
    if isinstance(shape, Polygon):
        V, E, N = shape._edges()
        k = int(np.argmax(np.einsum("ij,ij->i", q - V, N)))
        e = E[k] / float(E[k] @ E[k])
        # 0 ≤ (x − V_k)·E_k/|E_k|² ≤ 1
        A = np.array([-e, e])
        b = np.array([-float(e @ V[k]), 1.0 + float(e @ V[k])])
        return Feature("plane", f"edge{k}", N[k].copy(), float(N[k] @ V[k]), bounds_A=A, bounds_b=b)
    if isinstance(shape, Mesh):
        # the least of the planes of the faces (tangent planes at an edge or a vertex) that are
        # local minima of the tip's distance within a band of the nearest: in a concave region the
        # free space is their intersection, so their least gap is the true one there (a tip in a
        # corner: both faces). Unbounded: far from them it is not a lower bound of the true gap on a
        # non-convex part; every plan is run in the engine on the real surface before it is accepted
        found = shape.contacts(q, band_m=DEFAULT.planner.mesh_planes_band_m)
        found = found[:1] + [c for c in found[1:] if c.distance > 0.0]  # not a face seen from behind
        N = np.array([np.asarray(c.normal_body, dtype=float) for c in found]).reshape(-1, 3)
        h = np.array([float(n @ c.point_body) for n, c in zip(N, found, strict=True)])
        label = "face (" + ", ".join(f"{x:.3g}" for x in N[0]) + ")" + (f" + {len(N) - 1}" if len(N) > 1 else "")
        return Feature("planes", label, N[0].copy(), float(h[0]), normals=N, offsets=h)
    raise InputError(
        f"the fine planner has no closed-form gap for a {shape.name!r} workpiece (expected box, cylinder, sphere, rectangle, disk or polygon)"
    )


def surface_feature(fixture: Fixture) -> Feature | None:
    """The whole surface of a box or rectangle workpiece as one feature (None for other shapes).

    A kept contact written against it may slide or roll across an edge onto the next face: a part
    tipped onto a base locator's side face comes back onto its base face that way.
    """
    from fixplan.geometry import Box, Rectangle

    shape = fixture.workpiece.shape
    if isinstance(shape, Box | Rectangle):
        return Feature("box", "surface", half=np.asarray(shape.half, dtype=float).copy())
    return None


def _plane_features(fixture: Fixture) -> list[Feature]:
    """Every face plane of a polyhedral workpiece (box, rectangle, polygon); [] for round shapes."""
    from fixplan.geometry import Box, Polygon, Rectangle

    shape = fixture.workpiece.shape
    if isinstance(shape, Box | Rectangle):
        axes = "xyz"[: shape.half.shape[0]]
        return [_box_face(shape.half, sign + ax, sign + ax) for ax in axes for sign in "+-"]
    if isinstance(shape, Polygon):
        V, E, N = shape._edges()
        out = []
        for k in range(len(V)):
            e = E[k] / float(E[k] @ E[k])
            A = np.array([-e, e])
            b = np.array([-float(e @ V[k]), 1.0 + float(e @ V[k])])
            out.append(Feature("plane", f"edge{k}", N[k].copy(), float(N[k] @ V[k]), bounds_A=A, bounds_b=b))
        return out
    return []


def clearance_features(fixture: Fixture, locator: Locator, start: Pose, feature: Feature) -> tuple[Feature, ...]:
    """The face planes that keep ``locator`` clear along a path from ``start``.

    A face plane's gap ``n·q − h − ρ`` is a lower bound of the true gap of a convex part, so
    "plane gap ≥ c > 0" keeps the locator clear — if that can hold at the start. The goal's face of
    a locator that starts beside another face (a part turned 18° whose side locator lies past the
    face's end) has a *negative* plane gap there, the constraint "no closer than at the start" is
    then vacuous, and planned paths ran the part's corner into the locator. Such a locator gets a
    second plane, the face that separates it best at the start, and the clearance is asked of the
    smooth maximum of the two (:func:`smooth_max`, itself ≤ the larger plane gap ≤ the true gap):
    the part may still turn the goal's face in front of the locator. Keeping it clear of the second
    face alone forbade that and left transitions with no path.
    """
    if feature.kind != "plane":
        return (feature,)
    q = start.point_body_from_world(locator.p_world)

    def plane_gap(f: Feature) -> float:  # every feature here is a plane: its normal is set
        return float(np.asarray(f.normal, dtype=float) @ q) - f.offset - locator.radius_m

    if plane_gap(feature) > 0.0:
        return (feature,)
    best = max(_plane_features(fixture), key=plane_gap, default=feature)
    return (feature, best) if plane_gap(best) > plane_gap(feature) else (feature,)


def smooth_max(ca: Any, a: Any, b: Any, scale_m: float = DEFAULT.planner.smooth_max_m) -> Any:
    """``s log(eᵃᐟˢ + eᵇᐟˢ) − s log 2``: smooth, ≤ max(a, b), equal to it where a = b (stable form).

    ``s = scale_m`` [m] (the fine planner passes its ``PlannerSettings.smooth_max_m``).
    """
    return ca.fmax(a, b) + scale_m * ca.log1p(ca.exp(-ca.fabs(a - b) / scale_m)) - scale_m * np.log(2.0)


__all__ = ["Feature", "clearance_features", "feature_at", "smooth_max", "surface_feature"]
