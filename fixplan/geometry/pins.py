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
- ``"exit"``: a through hole's far edge on the pin's side, once the rim has passed it.
- ``"bottom"``: the pin's tip face on a blind hole's bottom: the face's deepest point; gap
  ``depth − z``; normal ``−a``.

Why these suffice for the side: along a generator line of one cylinder the distance from the other's
axis is convex, so the overlap of two straight cylinders over the engaged length is extreme at its
ends, the rim and the mouth (or exit): a tilted pin's line contact resolves to these two points
(Whitney's one- and two-point contact), and a coaxial one's to either (both at ``(D − d)/2``).

Each extreme is found on its circle ``x(φ) = c + ρ (cos φ e1 + sin φ e2)``: the squared distance
``|w + A cos φ + B sin φ|²`` from the other axis is a trigonometric quadratic; it is sampled
(``PinSettings.rim_samples``) and its stationary point refined by Newton to machine precision.
Not computed here (yet): the pin's tip chamfer on the hole's mouth chamfer (a pin not yet entered).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

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
class HoleBody:
    """A hole (or a bore) in world coordinates: mouth centre, unit axis out of its body through the mouth."""

    mouth_world: FloatArray
    axis_world: FloatArray
    radius_m: float
    depth_m: float
    chamfer_m: float = 0.0
    blind: bool = True


@dataclass(frozen=True)
class PinContact:
    """One contact of a pin and its hole: the point on each, the normal from the pin into the hole's body, the gap."""

    kind: str  # "rim", "mouth", "exit" or "bottom"
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


def _rim(pin: PinBody, hole: HoleBody, settings: PinSettings) -> PinContact | None:
    """The pin's rim (where its side ends) on the hole's wall, when the rim is between the wall's ends."""
    u, a, m = pin.axis_world, hole.axis_world, hole.mouth_world
    centre = pin.base_world + pin.side_end_m * u
    e1, e2 = _perp_basis(u, pin.land_direction_world)
    P = np.eye(3) - np.outer(a, a)
    w, A, B = P @ (centre - m), pin.radius_m * (P @ e1), pin.radius_m * (P @ e2)
    phi = _circle_extreme(w, A, B, True, _land_arcs(pin), settings)
    x = centre + pin.radius_m * (math.cos(phi) * e1 + math.sin(phi) * e2)
    depth = float((m - x) @ a)
    if depth < hole.chamfer_m or depth > hole.depth_m:
        return None
    rho = P @ (x - m)
    rho_m = float(np.linalg.norm(rho))
    n = rho / rho_m if rho_m > 0.0 else e1
    gap = hole.radius_m - rho_m
    return PinContact("rim", x, x + gap * n, n, gap)


def _edge(pin: PinBody, hole: HoleBody, depth_m: float, kind: str, settings: PinSettings) -> PinContact | None:
    """The hole's edge circle at ``depth_m`` on the pin's side, when the pin's side spans that level."""
    u, a = pin.axis_world, hole.axis_world
    centre = hole.mouth_world - depth_m * a
    h1, h2 = _perp_basis(a)
    P = np.eye(3) - np.outer(u, u)
    w, A, B = P @ (centre - pin.base_world), hole.radius_m * (P @ h1), hole.radius_m * (P @ h2)
    phi = _circle_extreme(w, A, B, False, [(0.0, 2.0 * math.pi)], settings)
    y = centre + hole.radius_m * (math.cos(phi) * h1 + math.sin(phi) * h2)
    s = float((y - pin.base_world) @ u)
    if s < 0.0 or s > pin.side_end_m:
        return None
    v = P @ (y - pin.base_world)
    d = float(np.linalg.norm(v))
    if d == 0.0:
        return None
    n = v / d
    if pin.land_direction_world is not None:
        e1, e2 = _perp_basis(u, pin.land_direction_world)
        arcs = _land_arcs(pin)
        if not _in_arcs(math.atan2(float(n @ e2), float(n @ e1)), arcs):
            # the nearest point faces the relief: the nearest one the lands face
            ok = [
                float(t)
                for t in np.linspace(0.0, 2.0 * math.pi, 4 * settings.rim_samples, endpoint=False)
                if _in_arcs(_angle_of(P, centre, h1, h2, hole.radius_m, float(t), pin, e1, e2), arcs)
            ]
            if not ok:
                return None
            phi = min(ok, key=lambda t: _dist2(P, centre, h1, h2, hole.radius_m, t, pin))
            y = centre + hole.radius_m * (math.cos(phi) * h1 + math.sin(phi) * h2)
            v = P @ (y - pin.base_world)
            d = float(np.linalg.norm(v))
            n = v / d
    x = pin.base_world + float((y - pin.base_world) @ u) * u + pin.radius_m * n
    return PinContact(kind, x, y, n, d - pin.radius_m)


def _angle_of(
    P: FloatArray,
    centre: FloatArray,
    h1: FloatArray,
    h2: FloatArray,
    R: float,
    t: float,
    pin: PinBody,
    e1: FloatArray,
    e2: FloatArray,
) -> float:
    v = P @ (centre + R * (math.cos(t) * h1 + math.sin(t) * h2) - pin.base_world)
    return math.atan2(float(v @ e2), float(v @ e1))


def _dist2(P: FloatArray, centre: FloatArray, h1: FloatArray, h2: FloatArray, R: float, t: float, pin: PinBody) -> float:
    v = P @ (centre + R * (math.cos(t) * h1 + math.sin(t) * h2) - pin.base_world)
    return float(v @ v)


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


def pin_hole_contacts(pin: PinBody, hole: HoleBody, settings: PinSettings = _DEFAULT.pins) -> list[PinContact]:
    """Every contact of ``pin`` with ``hole`` that their relative pose makes possible, with its gap.

    The rim and the mouth (a through hole's exit once the rim has passed it) for the side, the
    bottom for a blind hole; an empty list when the pin's side is not in the hole.
    """
    out: list[PinContact] = []
    for found in (
        _rim(pin, hole, settings),
        _edge(pin, hole, hole.chamfer_m, "mouth", settings),
        None if hole.blind else _edge(pin, hole, hole.depth_m, "exit", settings),
        _bottom(pin, hole, settings) if hole.blind else None,
    ):
        if found is not None:
            out.append(found)
    return out


__all__ = ["HoleBody", "PinBody", "PinContact", "pin_hole_contacts", "radial_play_m"]
