"""Convex workpiece shapes with closed-form point queries in the body frame.

Every shape answers one question, :meth:`Shape.project`: for a point ``p_body``, the signed
distance to the surface (negative inside), the closest surface point and the outward unit
normal there. A spherical locator tip of radius ρ centred at ``p`` then has the gap
``distance − ρ``, touches at the closest point, and pushes along the *inward* normal
(docs/math.md's ``n``, from the locator into the workpiece).

On the surface itself the outward normal is taken from the face the point lies on (not from a
0/0 difference), so point locators resting exactly on a face get an exact normal.
"""

from __future__ import annotations

import functools
import math
from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Projection:
    """Result of projecting a body-frame point onto a shape's surface."""

    distance: float  # signed: > 0 outside, < 0 inside [m]
    point_body: FloatArray  # closest surface point [m]
    normal_body: FloatArray  # outward unit normal at that point


class Shape(ABC):
    """A convex rigid shape, described in its body frame."""

    dimension: int
    name: str

    @abstractmethod
    def project(self, p_body: FloatArray) -> Projection:
        """Closest surface point, signed distance and outward normal for ``p_body``."""

    @abstractmethod
    def inertia_body(self, mass_kg: float) -> FloatArray:
        """Uniform-density inertia about the centre of mass, body axes: (3,3) in 3D, (1,1) in 2D."""

    @property
    def com_body(self) -> FloatArray:
        """Centre of mass in the body frame (uniform density)."""
        return np.zeros(self.dimension)

    @property
    @abstractmethod
    def bounding_radius(self) -> float:
        """Radius of a ball about the body origin that contains the shape [m]."""

    def face_of(self, p_body: FloatArray) -> str | None:
        """Name of the face (``"+x"``, ``"-z"``, ...) nearest to a surface point, if faces exist."""
        return None


def _box_project(p: FloatArray, half: FloatArray) -> Projection:
    """Closest point on an axis-aligned box of half extents ``half`` (any dimension).

    Scalar arithmetic on Python floats: the box has 2 or 3 axes, and a dozen NumPy calls on
    arrays that small cost ten times the arithmetic (this runs for every locator at every pose
    the planner and the executor look at).
    """
    ps = p.tolist()
    hs = half.tolist()
    q = [abs(pi) - hi for pi, hi in zip(ps, hs, strict=True)]
    sign = [1.0 if pi >= 0.0 else -1.0 for pi in ps]
    outside = [qi if qi > 0.0 else 0.0 for qi in q]
    n_out = math.sqrt(math.fsum(o * o for o in outside))  # lengths of a part: no overflow to guard against
    if n_out > 1e-12 * max(hs):
        # Outside: a face, edge or corner region; the normal is exact in each.
        closest = [min(max(pi, -hi), hi) for pi, hi in zip(ps, hs, strict=True)]
        normal = [si * oi / n_out for si, oi in zip(sign, outside, strict=True)]
        return Projection(n_out, np.array(closest), np.array(normal))
    # Inside or on the surface: the nearest face (the first of equals, as argmax).
    k = max(range(len(q)), key=q.__getitem__)
    closest = list(ps)
    closest[k] = sign[k] * hs[k]
    normal = [0.0] * len(ps)
    normal[k] = sign[k]
    return Projection(q[k], np.array(closest), np.array(normal))


def _face_name(axis: int, sign: float) -> str:
    return ("+" if sign > 0 else "-") + "xyz"[axis]


@dataclass(frozen=True)
class Box(Shape):
    """A box with full edge lengths ``size`` along body x, y, z, centred on the body origin."""

    size: tuple[float, float, float]
    dimension = 3
    name = "box"

    @property
    def half(self) -> FloatArray:
        return self._half.copy()

    @functools.cached_property
    def _half(self) -> FloatArray:
        """The half extents, computed once (``project`` runs for every locator at every tick)."""
        return np.asarray(self.size, dtype=float) / 2.0

    def project(self, p_body: FloatArray) -> Projection:
        return _box_project(np.asarray(p_body, dtype=float), self._half)

    def inertia_body(self, mass_kg: float) -> FloatArray:
        a, b, c = self.size
        return mass_kg / 12.0 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])

    @functools.cached_property
    def bounding_radius(self) -> float:
        return float(np.linalg.norm(self._half))

    def face_of(self, p_body: FloatArray) -> str | None:
        q = np.abs(p_body) - self.half
        k = int(np.argmax(q))
        return _face_name(k, float(np.sign(p_body[k]) or 1.0))


@dataclass(frozen=True)
class Rectangle(Shape):
    """A rectangle with full side lengths ``size = (w, h)``, centred on the body origin (2D)."""

    size: tuple[float, float]
    dimension = 2
    name = "rectangle"

    @property
    def half(self) -> FloatArray:
        return self._half.copy()

    @functools.cached_property
    def _half(self) -> FloatArray:
        """The half extents, computed once (``project`` runs for every locator at every tick)."""
        return np.asarray(self.size, dtype=float) / 2.0

    def project(self, p_body: FloatArray) -> Projection:
        return _box_project(np.asarray(p_body, dtype=float), self._half)

    def inertia_body(self, mass_kg: float) -> FloatArray:
        w, h = self.size
        return np.array([[mass_kg * (w * w + h * h) / 12.0]])

    @functools.cached_property
    def bounding_radius(self) -> float:
        return float(np.linalg.norm(self._half))

    def face_of(self, p_body: FloatArray) -> str | None:
        q = np.abs(p_body) - self.half
        k = int(np.argmax(q))
        return _face_name(k, float(np.sign(p_body[k]) or 1.0))


@dataclass(frozen=True)
class Sphere(Shape):
    """A ball of radius ``radius`` centred on the body origin."""

    radius: float
    dimension = 3
    name = "sphere"

    def project(self, p_body: FloatArray) -> Projection:
        p = np.asarray(p_body, dtype=float)
        rho = float(np.linalg.norm(p))
        normal = p / rho if rho > 1e-15 else np.array([0.0, 0.0, 1.0])
        return Projection(rho - self.radius, self.radius * normal, normal)

    def inertia_body(self, mass_kg: float) -> FloatArray:
        return np.eye(3) * 0.4 * mass_kg * self.radius**2

    @property
    def bounding_radius(self) -> float:
        return self.radius


@dataclass(frozen=True)
class Disk(Shape):
    """A disk of radius ``radius`` centred on the body origin (2D)."""

    radius: float
    dimension = 2
    name = "disk"

    def project(self, p_body: FloatArray) -> Projection:
        p = np.asarray(p_body, dtype=float)
        rho = float(np.linalg.norm(p))
        normal = p / rho if rho > 1e-15 else np.array([0.0, 1.0])
        return Projection(rho - self.radius, self.radius * normal, normal)

    def inertia_body(self, mass_kg: float) -> FloatArray:
        return np.array([[0.5 * mass_kg * self.radius**2]])

    @property
    def bounding_radius(self) -> float:
        return self.radius


@dataclass(frozen=True)
class Cylinder(Shape):
    """A solid cylinder, axis along body z, centred on the body origin."""

    radius: float
    length: float
    dimension = 3
    name = "cylinder"

    def project(self, p_body: FloatArray) -> Projection:
        p = np.asarray(p_body, dtype=float)
        rho = float(np.hypot(p[0], p[1]))
        radial = p[:2] / rho if rho > 1e-15 else np.array([1.0, 0.0])
        # The cylinder is a rectangle in the (ρ, z) half-plane.
        proj = _box_project(np.array([rho, p[2]]), np.array([self.radius, self.length / 2.0]))
        rho_c, z_c = proj.point_body
        n_rho, n_z = proj.normal_body
        point = np.array([rho_c * radial[0], rho_c * radial[1], z_c])
        normal = np.array([n_rho * radial[0], n_rho * radial[1], n_z])
        return Projection(proj.distance, point, normal / np.linalg.norm(normal))

    def inertia_body(self, mass_kg: float) -> FloatArray:
        r, L = self.radius, self.length
        i_perp = mass_kg * (3 * r * r + L * L) / 12.0
        return np.diag([i_perp, i_perp, 0.5 * mass_kg * r * r])

    @property
    def bounding_radius(self) -> float:
        return float(np.hypot(self.radius, self.length / 2.0))

    def face_of(self, p_body: FloatArray) -> str | None:
        rho = float(np.hypot(p_body[0], p_body[1]))
        if abs(p_body[2]) - self.length / 2.0 > rho - self.radius:
            return "+z" if p_body[2] > 0 else "-z"
        return "side"


@dataclass(frozen=True)
class Polygon(Shape):
    """A convex polygon with counter-clockwise vertices in the body frame (2D).

    The body frame is the file's own frame; the centre of mass is the area centroid
    (:attr:`com_body`), which need not be the origin.
    """

    vertices: tuple[tuple[float, float], ...]
    dimension = 2
    name = "polygon"

    @property
    def array(self) -> FloatArray:
        return np.asarray(self.vertices, dtype=float)

    def _edges(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        return self._edge_arrays

    @functools.cached_property
    def _edge_arrays(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Vertices, edge vectors and outward unit normals, computed once (read-only arrays).

        ``project`` runs for every locator at every pose the planner and its executor look at;
        rebuilding these per call was a third of it.
        """
        V = self.array
        E = np.roll(V, -1, axis=0) - V
        lengths = np.linalg.norm(E, axis=1)
        normals = np.stack([E[:, 1], -E[:, 0]], axis=1) / lengths[:, None]  # outward for CCW
        for a in (V, E, normals):
            a.setflags(write=False)
        return V, E, normals

    @functools.cached_property
    def _edge_lists(self) -> tuple[tuple[float, float, float, float, float, float, float], ...]:
        """Per edge: vertex (x, y), edge vector (x, y), outward unit normal (x, y), |edge|²."""
        V, E, N = self._edges()
        return tuple(
            (float(v[0]), float(v[1]), float(e[0]), float(e[1]), float(n[0]), float(n[1]), float(e @ e))
            for v, e, n in zip(V, E, N, strict=True)
        )

    def project(self, p_body: FloatArray) -> Projection:
        # scalar arithmetic on Python floats: a polygon has a handful of edges, and the NumPy
        # version's dozen calls on arrays that small cost ten times the arithmetic
        px, py = (float(c) for c in np.asarray(p_body, dtype=float))
        edges = self._edge_lists
        plane = [
            (px - vx) * nx + (py - vy) * ny for vx, vy, _, _, nx, ny, _ in edges
        ]  # signed distance to each edge's line
        k_in = max(range(len(plane)), key=plane.__getitem__)
        if plane[k_in] <= 0.0:
            _, _, _, _, nx, ny, _ = edges[k_in]
            d = plane[k_in]
            return Projection(d, np.array([px - d * nx, py - d * ny]), np.array([nx, ny]))
        # Outside: nearest point over the edge segments.
        nearest = []  # per edge: (distance, segment parameter t, closest point)
        for vx, vy, ex, ey, _, _, ee in edges:
            t = ((px - vx) * ex + (py - vy) * ey) / ee
            t = 0.0 if t < 0.0 else 1.0 if t > 1.0 else t
            cx, cy = vx + t * ex, vy + t * ey
            nearest.append((math.hypot(px - cx, py - cy), t, cx, cy))
        k = min(range(len(nearest)), key=lambda i: nearest[i][0])  # the first of equals, as argmin
        d, t, cx, cy = nearest[k]
        _, _, _, _, nx, ny, _ = edges[k]
        tiny = 1e-12 * self.bounding_radius
        if d > tiny and 0.0 < t < 1.0:
            normal = [nx, ny]
        elif d > tiny:
            normal = [(px - cx) / d, (py - cy) / d]
        else:
            _, _, _, _, nx, ny, _ = edges[k_in]
            normal = [nx, ny]
        return Projection(d, np.array([cx, cy]), np.array(normal))

    def _area_terms(self) -> tuple[float, FloatArray, float]:
        area, c, j = self._area_terms_once
        return area, c.copy(), j

    @functools.cached_property
    def _area_terms_once(self) -> tuple[float, FloatArray, float]:
        V = self.array
        x, y = V[:, 0], V[:, 1]
        xn, yn = np.roll(x, -1), np.roll(y, -1)
        cr = x * yn - xn * y
        area = cr.sum() / 2.0
        cx = ((x + xn) * cr).sum() / (6.0 * area)
        cy = ((y + yn) * cr).sum() / (6.0 * area)
        # Second moment about the origin, then shifted to the centroid.
        j_origin = ((x * x + x * xn + xn * xn + y * y + y * yn + yn * yn) * cr).sum() / 12.0
        return float(area), np.array([cx, cy]), float(j_origin)

    @property
    def area(self) -> float:
        return self._area_terms()[0]

    @property
    def com_body(self) -> FloatArray:
        return self._area_terms()[1]

    def inertia_body(self, mass_kg: float) -> FloatArray:
        area, c, j_origin = self._area_terms()
        j_centroid = j_origin / area - float(c @ c)  # per unit mass
        return np.array([[mass_kg * j_centroid]])

    @functools.cached_property
    def bounding_radius(self) -> float:
        return float(np.linalg.norm(self.array, axis=1).max())
