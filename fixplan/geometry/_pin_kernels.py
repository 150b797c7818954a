"""The closed-form pin/hole contacts of :mod:`fixplan.geometry.pins`, compiled (numba): what the engine calls each step.

The same arithmetic as :func:`fixplan.geometry.pins.pin_hole_contacts` (the reference; the
module's text derives the contacts), on flat arrays instead of dataclasses and without closures:
the Python reference takes about 10 ms for the two pins of a housing, a 1 kHz loop has 1 ms for
everything. ``tests/engine/test_pin_slots.py`` pins the two together on random poses.

Arrays (world frame, metres):

- ``pin`` (14,): base (3), unit axis base → tip (3), radius, length, tip chamfer, land direction
  (3), land width, 1.0 for a diamond pin (else 0.0);
- ``hole`` (10,): mouth centre (3), unit axis out of its body (3), radius, depth, mouth chamfer,
  1.0 for a blind hole; or (:data:`FACE_COLUMNS`,): those and the face around its mouth
  (:class:`fixplan.geometry.pins.MouthFace`): a kind (0.0 none, 1.0 a rectangle, 2.0 a disk),
  centre (3), unit outward normal (3), unit ``e1`` (3), half extents along ``e1`` and
  ``normal × e1`` (a disk: its radius, 0); or (:data:`HOLE_COLUMNS`,): those, then how many other
  holes of the part have their mouths in that face (at most :data:`OTHER_HOLES`) and each one's 10
  columns as above: the face is not the pin's support over their mouths, and the pin has its
  contacts with them too (a pin landing on, or in, its neighbour's hole);
- ``out`` (:data:`MAX_CONTACTS`, 11): one row per contact, ``[kind, point on the pin (3), point on
  the hole's body (3), unit normal from the pin into the hole's body (3), gap]``, kinds coded as
  :data:`KINDS` (:func:`contacts`, the pin and its hole) and :data:`FACE` (:func:`face_contacts`,
  the pin's tip on the face: :func:`fixplan.geometry.pins.tip_face_contacts`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

KINDS = ("rim", "mouth", "exit", "bottom", "tip")  # the kind codes of contacts()' rows (the pin and its hole)
RIM, MOUTH, EXIT, BOTTOM, TIP = 0, 1, 2, 3, 4
FACE = 5  # the kind code of face_contacts()' rows (the pin's tip on the face around the hole)
ALL_KINDS = (*KINDS, "face")  # the kind codes of pose_contacts()' rows
FACE_COLUMNS = 22  # a hole's row with the face around its mouth (module text)
OTHER_HOLES = 3  # the other holes' mouths in the same face a hole's row carries (module text)
HOLE_COLUMNS = FACE_COLUMNS + 1 + 10 * OTHER_HOLES  # a hole's row with its face and the other mouths in it
# 2 lands x (rim, mouth, exit, 2 mouth edges, 2 pin circles) + bottom = 15, + the bottom face's rim
# and the tip on the face (face_points each, 4 by default): 23, + the ends of the tip's arcs over the
# face (2 per arc, 2 arcs at most): 27
MAX_CONTACTS = 28
_MAX_ARCS = 2  # arcs of a tip's edge over the face around a mouth (module face_contacts)
_TWO_PI = 2.0 * math.pi
_SQRT_HALF = math.sqrt(0.5)
_GOLDEN = 0.5 * (math.sqrt(5.0) - 1.0)


@njit(cache=True)
def _perp_basis(u, prefer, use_prefer):
    """``e1, e2`` with ``(e1, e2, u)`` right-handed; ``e1`` along ``prefer``'s part normal to ``u`` when asked."""
    if use_prefer:
        e1 = prefer - (prefer @ u) * u
    else:
        k = int(np.argmin(np.abs(u)))
        e1 = np.zeros(3)
        e1[k] = 1.0
        e1 = e1 - (e1 @ u) * u
    e1 = e1 / np.linalg.norm(e1)
    return e1, np.cross(u, e1)


@njit(cache=True)
def _proj(a):
    """``I − a aᵀ``: the projection normal to the unit ``a``."""
    return np.eye(3) - np.outer(a, a)


@njit(cache=True)
def _land_arcs(pin):
    """The angles (about the pin's axis, from ``e1`` = the land direction) its side spans, ``(k, 2)``."""
    if pin[13] == 0.0:
        out = np.empty((1, 2))
        out[0, 0], out[0, 1] = 0.0, _TWO_PI
        return out
    alpha = math.asin(min(1.0, pin[12] / (2.0 * pin[6])))
    out = np.empty((2, 2))
    out[0, 0], out[0, 1] = -alpha, alpha
    out[1, 0], out[1, 1] = math.pi - alpha, math.pi + alpha
    return out


@njit(cache=True)
def _in_arcs(angle, arcs):
    for i in range(arcs.shape[0]):
        lo, hi = arcs[i, 0], arcs[i, 1]
        if lo <= angle <= hi or lo <= angle + _TWO_PI <= hi or lo <= angle - _TWO_PI <= hi:
            return True
    return False


@njit(cache=True)
def _sq(w, A, B, phi, sign):
    """``sign · |w + A cos φ + B sin φ|²`` (scalars: no temporary arrays in the hot loop)."""
    c, s = math.cos(phi), math.sin(phi)
    v0 = w[0] + A[0] * c + B[0] * s
    v1 = w[1] + A[1] * c + B[1] * s
    v2 = w[2] + A[2] * c + B[2] * s
    return sign * (v0 * v0 + v1 * v1 + v2 * v2)


@njit(cache=True)
def _circle_extreme(w, A, B, largest, arcs, rim_samples, newton_steps):
    """The angle φ within ``arcs`` at which ``|w + A cos φ + B sin φ|²`` is largest (or least)."""
    sign = 1.0 if largest else -1.0
    best_phi, best = arcs[0, 0], -math.inf
    n = max(rim_samples // arcs.shape[0], 2)
    for i in range(arcs.shape[0]):
        lo, hi = arcs[i, 0], arcs[i, 1]
        step = (hi - lo) / n
        for j in range(n + 1):
            phi = j * step + lo if j < n else hi  # np.linspace(lo, hi, n + 1), as the reference
            val = _sq(w, A, B, phi, sign)
            if val > best:
                best_phi, best = phi, val
    lo, hi = arcs[0, 0], arcs[0, 1]
    for i in range(arcs.shape[0]):
        if arcs[i, 0] <= best_phi <= arcs[i, 1]:
            lo, hi = arcs[i, 0], arcs[i, 1]
            break
    if hi - lo >= _TWO_PI:
        lo, hi = -math.inf, math.inf
    phi = best_phi
    for _ in range(newton_steps):
        c, s = math.cos(phi), math.sin(phi)
        d1 = 0.0
        vv2 = 0.0
        for k in range(3):
            v = w[k] + A[k] * c + B[k] * s
            dv = -A[k] * s + B[k] * c
            d1 += v * dv
            vv2 += dv * dv - v * (A[k] * c + B[k] * s)
        d1 *= 2.0
        d2 = 2.0 * vv2
        if d2 * sign >= 0.0 or d2 == 0.0:
            break
        step = min(max(phi - d1 / d2, lo), hi)
        if _sq(w, A, B, step, sign) < _sq(w, A, B, phi, sign):
            break
        phi = step
    return phi


@njit(cache=True)
def _put(out, n, kind, x, y, normal, gap):
    out[n, 0] = kind
    out[n, 1:4] = x
    out[n, 4:7] = y
    out[n, 7:10] = normal
    out[n, 10] = gap
    return n + 1


@njit(cache=True)
def _rim(pin, hole, arcs, rim_samples, newton_steps, out, n):
    u, a, m = pin[3:6], hole[3:6], hole[0:3]
    r = pin[6]
    centre = pin[0:3] + (pin[7] - pin[8]) * u
    e1, e2 = _perp_basis(u, pin[9:12], pin[13] != 0.0)
    P = _proj(a)
    w, A, B = P @ (centre - m), r * (P @ e1), r * (P @ e2)
    phi = _circle_extreme(w, A, B, True, arcs, rim_samples, newton_steps)
    x = centre + r * (math.cos(phi) * e1 + math.sin(phi) * e2)
    depth = (m - x) @ a
    if depth < hole[8] or depth > hole[7]:
        return n
    rho = P @ (x - m)
    rho_m = np.linalg.norm(rho)
    nn = rho / rho_m if rho_m > 0.0 else e1
    gap = hole[6] - rho_m
    if gap < 0.0 and -gap > _mouth_distance(hole, depth, rho_m):
        return n  # in the body, nearer the mouth's face or chamfer than the wall: not the wall's
    return _put(out, n, RIM, x, x + gap * nn, nn, gap)


# -- the distance of a point (t, ρ) to the pin's tip and to the hole's mouth chamfer ------------------------
@njit(cache=True)
def _seg(q0, q1, a0, a1, b0, b1):
    """The point of segment ``ab`` nearest ``q`` and its parameter in [0, 1] (2D, scalars)."""
    d0, d1 = b0 - a0, b1 - a1
    dd = d0 * d0 + d1 * d1
    t = 0.0 if dd == 0.0 else min(max(((q0 - a0) * d0 + (q1 - a1) * d1) / dd, 0.0), 1.0)
    return a0 + t * d0, a1 + t * d1, t


@njit(cache=True)
def _mouth_distance(hole, q0, q1):
    """:func:`fixplan.geometry.pins._mouth_distance`: ``(depth, ρ)`` from the mouth's chamfer and the face around it."""
    c, R = hole[8], hole[6]
    face = abs(q0) if q1 >= R + c else math.hypot(q0, q1 - R - c)
    if c <= 0.0:
        return face
    p0, p1, _t = _seg(q0, q1, 0.0, R + c, c, R)
    return min(face, math.hypot(q0 - p0, q1 - p1))


@njit(cache=True)
def _tip_distance(pin, q0, q1):
    """:func:`fixplan.geometry.pins._tip_distance`: ``(t, ρ)`` from the pin's tip chamfer and face."""
    L, r, c = pin[7], pin[6], pin[8]
    p0, p1, _t = _seg(q0, q1, L, r - c, L, 0.0)
    d = math.hypot(q0 - p0, q1 - p1)
    if c > 0.0:
        p0, p1, _t = _seg(q0, q1, L - c, r, L, r - c)
        d = min(d, math.hypot(q0 - p0, q1 - p1))
    return d


@njit(cache=True)
def _in_cone(v0, v1, n10, n11, n20, n21):
    c12 = n10 * n21 - n11 * n20
    return (n10 * v1 - n11 * v0) * c12 >= 0.0 and (v0 * n21 - v1 * n20) * c12 >= 0.0


@njit(cache=True)
def _pin_tip_gap(pin, q0, q1):
    """``(found, gap, n_t, n_ρ)``: :func:`fixplan.geometry.pins._pin_tip_gap`."""
    L, r, c = pin[7], pin[6], pin[8]
    s = _SQRT_HALF
    p10, p11, t1 = _seg(q0, q1, L - c, r, L, r - c)
    p20, p21, t2 = _seg(q0, q1, L, r - c, L, 0.0)
    d1 = math.hypot(q0 - p10, q1 - p11)
    d2 = math.hypot(q0 - p20, q1 - p21)
    if c > 0.0 and d1 <= d2:
        p0, p1, n0, n1 = p10, p11, s, s
        if t1 == 0.0:
            v0, v1 = q0 - p0, q1 - p1
            if not _in_cone(v0, v1, 0.0, 1.0, s, s):
                return False, 0.0, 0.0, 0.0
            nv = math.hypot(v0, v1)
            if nv > 0.0:
                n0, n1 = v0 / nv, v1 / nv
        elif t1 == 1.0 and not _in_cone(q0 - p0, q1 - p1, s, s, 1.0, 0.0):
            return False, 0.0, 0.0, 0.0
    else:
        p0, p1, n0, n1 = p20, p21, 1.0, 0.0
        if t2 == 0.0:
            v0, v1 = q0 - p0, q1 - p1
            m0, m1 = (0.0, 1.0) if c == 0.0 else (s, s)
            if not _in_cone(v0, v1, m0, m1, 1.0, 0.0):
                return False, 0.0, 0.0, 0.0
            nv = math.hypot(v0, v1)
            if nv > 0.0:
                n0, n1 = v0 / nv, v1 / nv
        elif t2 == 1.0:
            return False, 0.0, 0.0, 0.0
    gap = (q0 - p0) * n0 + (q1 - p1) * n1
    if gap < 0.0 and r - q1 < -gap:
        return False, 0.0, 0.0, 0.0
    return True, gap, n0, n1


@njit(cache=True)
def _hole_chamfer_gap(hole, q0, q1):
    """``(found, gap, n_depth, n_ρ)``: :func:`fixplan.geometry.pins._hole_chamfer_gap`."""
    c, R = hole[8], hole[6]
    if c <= 0.0:
        return False, 0.0, 0.0, 0.0
    p0, p1, t = _seg(q0, q1, 0.0, R + c, c, R)
    if t <= 0.0 or t >= 1.0:
        return False, 0.0, 0.0, 0.0
    n0, n1 = -_SQRT_HALF, -_SQRT_HALF
    gap = (q0 - p0) * n0 + (q1 - p1) * n1
    if gap < 0.0 and min(q1 - R, q0) < -gap:
        return False, 0.0, 0.0, 0.0
    return True, gap, n0, n1


# -- a gap along a circle, by mode (numba has no closures to hand around) -----------------------------------
# mode 0: the hole's edge circle on a diamond pin's land; 1: a hole edge circle on the pin's tip (a
# diamond's: on its lands); 2: a pin circle on the hole's mouth chamfer (a diamond's: on its lands). The circle is ``x(φ) = c + rad (cos φ b1 + sin φ b2)``;
# the other body's axial coordinate of ``x`` is ``t0 + t1 cos φ + t2 sin φ`` and its radial vector
# ``w + A cos φ + B sin φ`` (coefficients computed once per circle, then only scalars per angle).
@njit(cache=True)
def _circle_coef(mode, pin, hole, c, rad, b1, b2):
    """``[w (3), A (3), B (3), t (3), radial·e1 (3), radial·e2 (3)]`` of the circle in the other body's frame."""
    out = np.zeros(18)
    if mode == 2:
        a, m = hole[3:6], hole[0:3]
        P = _proj(a)
        out[0:3], out[3:6], out[6:9] = P @ (c - m), rad * (P @ b1), rad * (P @ b2)
        out[9], out[10], out[11] = (m - c) @ a, -rad * (b1 @ a), -rad * (b2 @ a)
        return out
    u, base = pin[3:6], pin[0:3]
    P = _proj(u)
    out[0:3], out[3:6], out[6:9] = P @ (c - base), rad * (P @ b1), rad * (P @ b2)
    out[9], out[10], out[11] = (c - base) @ u, rad * (b1 @ u), rad * (b2 @ u)
    if mode == 0 or pin[13] != 0.0:  # a diamond's side and tip: the direction from its axis, to keep its lands
        e1, e2 = _perp_basis(u, pin[9:12], True)
        for k in range(3):
            out[12 + k] = out[3 * k : 3 * k + 3] @ e1
            out[15 + k] = out[3 * k : 3 * k + 3] @ e2
    return out


@njit(cache=True)
def _circle_q(coef, cs, sn):
    """The circle's point at ``(cos φ, sin φ)`` in the other body's half-plane: ``(t, ρ)``, from the coefficients."""
    v0 = coef[0] + coef[3] * cs + coef[6] * sn
    v1 = coef[1] + coef[4] * cs + coef[7] * sn
    v2 = coef[2] + coef[5] * cs + coef[8] * sn
    return coef[9] + coef[10] * cs + coef[11] * sn, math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)


@njit(cache=True)
def _circle_gap(mode, phi, pin, hole, arcs, coef):
    cs, sn = math.cos(phi), math.sin(phi)
    if mode == 2 and not _in_arcs(phi, arcs):
        return False, 0.0
    t, rho = _circle_q(coef, cs, sn)
    if mode == 2:
        found, gap, _n0, _n1 = _hole_chamfer_gap(hole, t, rho)
        return found, gap
    if mode == 0 or pin[13] != 0.0:  # a diamond's side and tip are its lands only
        along = coef[12] + coef[13] * cs + coef[14] * sn
        across = coef[15] + coef[16] * cs + coef[17] * sn
        if not _in_arcs(math.atan2(across, along), arcs):
            return False, 0.0
    if mode == 0:
        return True, rho - pin[6]
    found, gap, _n0, _n1 = _pin_tip_gap(pin, t, rho)
    return found, gap


@njit(cache=True)
def _value(mode, phi, pin, hole, arcs, coef):
    found, gap = _circle_gap(mode, phi, pin, hole, arcs, coef)
    return gap if found else math.inf


@njit(cache=True)
def _land_end(mode, phi_end, pin, hole, arcs, coef, step, best, phi):
    """The gap just inside a land's end ``phi_end``, if it is below ``best``: ``(best, φ)``.

    Measured 2⁻⁴⁰ of the sample spacing to either side (the end itself falls on either side
    by rounding); the side within the land counts.
    """
    nudge = step * 2.0**-40
    for x in (phi_end + nudge, phi_end - nudge):
        found, gap = _circle_gap(mode, x, pin, hole, arcs, coef)
        if found and gap < best:
            best, phi = gap, x
    return best, phi


@njit(cache=True)
def _least_on_circle(mode, pin, hole, arcs, c, rad, b1, b2, rim_samples, golden_steps):
    """``(found, φ, t, ρ)``: the angle where the mode's gap is least on the circle (sampled, then golden section).

    A diamond's lands end abruptly: the least may be at a land's end, between two samples, where
    the gap falls until the land stops. Each end is therefore a candidate too: the angle itself for
    the pin's circles (mode 2), the circle's angles whose direction from the pin's axis is the
    land's end for the hole's (modes 0 and 1: ``a₀ + a₁ cos φ + a₂ sin φ = 0``).

    ``(t, ρ)`` is the point at ``φ`` as the search measured it (:func:`_circle_q`): the least may lie
    where the gap stops being the mode's (its nearest feature changes), and the search converges
    onto that edge from the side where it is; the same point re-measured from the circle's world
    point may fall past it by rounding. The callers judge it by these numbers then, not drop it.
    """
    coef = _circle_coef(mode, pin, hole, c, rad, b1, b2)
    step = _TWO_PI / rim_samples
    best, phi, any_found = math.inf, 0.0, False
    for i in range(rim_samples):
        t = i * step
        found, gap = _circle_gap(mode, t, pin, hole, arcs, coef)
        if found and (not any_found or gap < best):
            best, phi, any_found = gap, t, True
    if any_found:
        lo, hi = phi - step, phi + step
        g = _GOLDEN
        x1, x2 = hi - g * (hi - lo), lo + g * (hi - lo)
        f1 = _value(mode, x1, pin, hole, arcs, coef)
        f2 = _value(mode, x2, pin, hole, arcs, coef)
        for _ in range(golden_steps):
            if f1 <= f2:
                hi, x2, f2 = x2, x1, f1
                x1 = hi - g * (hi - lo)
                f1 = _value(mode, x1, pin, hole, arcs, coef)
            else:
                lo, x1, f1 = x1, x2, f2
                x2 = lo + g * (hi - lo)
                f2 = _value(mode, x2, pin, hole, arcs, coef)
        x = 0.5 * (lo + hi)
        fx = _value(mode, x, pin, hole, arcs, coef)
        if fx <= best:
            phi, best = x, fx
    if pin[13] != 0.0:  # a diamond: its lands' ends
        for k in range(arcs.shape[0]):
            for j in range(2):
                beta = arcs[k, j]
                if mode == 2:
                    best, phi = _land_end(mode, beta, pin, hole, arcs, coef, step, best, phi)
                    continue
                # the direction from the pin's axis at angle β: across cos β − along sin β = 0
                cb, sb = math.cos(beta), math.sin(beta)
                a0 = coef[15] * cb - coef[12] * sb
                a1 = coef[16] * cb - coef[13] * sb
                a2 = coef[17] * cb - coef[14] * sb
                rr = math.hypot(a1, a2)
                if rr == 0.0 or abs(a0) > rr:
                    continue
                mid, half = math.atan2(a2, a1), math.acos(-a0 / rr)
                best, phi = _land_end(mode, mid + half, pin, hole, arcs, coef, step, best, phi)
                best, phi = _land_end(mode, mid - half, pin, hole, arcs, coef, step, best, phi)
    if best == math.inf:
        return False, 0.0, 0.0, 0.0
    t, rho = _circle_q(coef, math.cos(phi), math.sin(phi))
    return True, phi, t, rho


@njit(cache=True)
def _edge(pin, hole, depth_m, kind, arcs, rim_samples, newton_steps, golden_steps, out, n):
    u, a, base = pin[3:6], hole[3:6], pin[0:3]
    centre = hole[0:3] - depth_m * a
    h1, h2 = _perp_basis(a, a, False)
    P = _proj(u)
    R = hole[6]
    if pin[13] == 0.0:
        w, A, B = P @ (centre - base), R * (P @ h1), R * (P @ h2)
        full = np.empty((1, 2))
        full[0, 0], full[0, 1] = 0.0, _TWO_PI
        phi = _circle_extreme(w, A, B, False, full, rim_samples, newton_steps)
    else:
        found, phi, _t, _rho = _least_on_circle(0, pin, hole, arcs, centre, R, h1, h2, rim_samples, golden_steps)
        if not found:
            return n
    y = centre + R * (math.cos(phi) * h1 + math.sin(phi) * h2)
    s = (y - base) @ u
    if s < 0.0 or s > pin[7] - pin[8]:
        return n
    v = P @ (y - base)
    d = np.linalg.norm(v)
    if d == 0.0:
        return n
    nn = v / d
    x = base + s * u + pin[6] * nn
    gap = d - pin[6]
    if kind == MOUTH and gap < 0.0 and -gap > _tip_distance(pin, s, d):
        return n  # in the pin, nearer its tip's face or chamfer than its side: the tip's contact
    return _put(out, n, kind, x, y, nn, gap)


@njit(cache=True)
def _bottom(pin, hole, coaxial_rel, out, n):
    u, a, m = pin[3:6], hole[3:6], hole[0:3]
    tip = pin[0:3] + pin[7] * u
    down = -a - ((-a) @ u) * u
    rho = pin[6] - pin[8]
    norm = np.linalg.norm(down)
    x = tip + rho * down / norm if norm > coaxial_rel else tip
    depth = (m - x) @ a
    if depth < hole[8]:
        return n
    gap = hole[7] - depth
    return _put(out, n, BOTTOM, x, x - gap * a, -a, gap)


@njit(cache=True)
def _hole_edges_on_tip(pin, hole, arcs, rim_samples, golden_steps, out, n):
    u, a, base = pin[3:6], hole[3:6], pin[0:3]
    h1, h2 = _perp_basis(a, a, False)
    P = _proj(u)
    ch = hole[8]
    n_edges = 2 if ch > 0.0 else 1
    for k in range(n_edges):
        depth, radius = (0.0, hole[6] + ch) if k == 0 else (ch, hole[6])
        centre = hole[0:3] - depth * a
        found, phi, t, rho = _least_on_circle(1, pin, hole, arcs, centre, radius, h1, h2, rim_samples, golden_steps)
        if not found:
            continue
        y = centre + radius * (math.cos(phi) * h1 + math.sin(phi) * h2)
        v = P @ (y - base)
        nv = np.linalg.norm(v)
        ok, gap, n0, n1 = _pin_tip_gap(pin, (y - base) @ u, nv)
        if not ok:  # on the edge of the tip's region, past it by rounding: the search's own measure
            ok, gap, n0, n1 = _pin_tip_gap(pin, t, rho)
        if not ok:
            continue
        if nv > 0.0:
            radial = v / nv
        else:
            radial, _e2 = _perp_basis(u, u, False)
        nn = n0 * u + n1 * radial
        n = _put(out, n, TIP, y - gap * nn, y, nn, gap)
    return n


@njit(cache=True)
def _tip_edges_on_chamfer(pin, hole, arcs, rim_samples, golden_steps, out, n):
    if hole[8] <= 0.0:
        return n
    u, a, m = pin[3:6], hole[3:6], hole[0:3]
    e1, e2 = _perp_basis(u, pin[9:12], pin[13] != 0.0)
    P = _proj(a)
    n_circles = 2 if pin[8] > 0.0 else 1
    for k in range(n_circles):
        s, radius = (pin[7] - pin[8], pin[6]) if k == 0 else (pin[7], pin[6] - pin[8])
        centre = pin[0:3] + s * u
        found, phi, t, rho_c = _least_on_circle(2, pin, hole, arcs, centre, radius, e1, e2, rim_samples, golden_steps)
        if not found:
            continue
        x = centre + radius * (math.cos(phi) * e1 + math.sin(phi) * e2)
        rho = P @ (x - m)
        nr = np.linalg.norm(rho)
        ok, gap, f0, f1 = _hole_chamfer_gap(hole, (m - x) @ a, nr)
        if not ok:  # on the edge of the chamfer's region, past it by rounding: the search's own measure
            ok, gap, f0, f1 = _hole_chamfer_gap(hole, t, rho_c)
        if not ok:
            continue
        radial = rho / nr if nr > 0.0 else e1
        free = f0 * (-a) + f1 * radial
        n = _put(out, n, TIP, x, x - gap * free, -free, gap)
    return n


@njit(cache=True)
def contacts(pin, hole, rim_samples, newton_steps, golden_steps, coaxial_rel, out):
    """Every contact of ``pin`` with ``hole`` into ``out`` (module text); returns how many.

    The same contacts, in the same order, as :func:`fixplan.geometry.pins.pin_hole_contacts`.
    """
    n = 0
    arcs = _land_arcs(pin)
    blind = hole[9] != 0.0
    for i in range(arcs.shape[0]):
        land = arcs if arcs.shape[0] == 1 else arcs[i : i + 1]
        n = _rim(pin, hole, land, rim_samples, newton_steps, out, n)
        n = _edge(pin, hole, hole[8], MOUTH, land, rim_samples, newton_steps, golden_steps, out, n)
        if not blind:
            n = _edge(pin, hole, hole[7], EXIT, land, rim_samples, newton_steps, golden_steps, out, n)
    if blind:
        n = _bottom(pin, hole, coaxial_rel, out, n)
    for i in range(arcs.shape[0]):  # a diamond's tip, like its side: each land on its own
        land = arcs if arcs.shape[0] == 1 else arcs[i : i + 1]
        n = _hole_edges_on_tip(pin, hole, land, rim_samples, golden_steps, out, n)
        n = _tip_edges_on_chamfer(pin, hole, land, rim_samples, golden_steps, out, n)
    return n


@njit(cache=True)
def _face_points(pin, hole, face_points, coaxial_rel, rows, k):
    """A tip face on a blind hole's bottom as ``face_points`` points of the face's rim (and its centre when flat).

    :func:`contacts` gives the face's deepest point only (exact for the gap); a face resting on the
    bottom is held by its whole disk, so the engine also hands over the rim at ``face_points``
    angles from the deepest point (each with its own gap to the bottom, normal ``−a``). Appended to
    ``rows`` after row ``k − 1``; returns the new count.
    """
    if face_points <= 1:
        return k
    u, a, m = pin[3:6], hole[3:6], hole[0:3]
    rho = pin[6] - pin[8]
    if rho <= 0.0:
        return k
    tip = pin[0:3] + pin[7] * u
    down = -a - ((-a) @ u) * u
    norm = np.linalg.norm(down)
    if norm > coaxial_rel:
        d1 = down / norm
        first = 1  # the deepest point (angle 0) is contacts()' own
    else:
        d1, _d2 = _perp_basis(u, u, False)
        first = 0  # flat: contacts() gave the centre; the whole rim is added
    d2 = np.cross(u, d1)
    for j in range(first, face_points):
        phi = _TWO_PI * j / face_points
        x = tip + rho * (math.cos(phi) * d1 + math.sin(phi) * d2)
        depth = (m - x) @ a
        if depth < hole[8]:
            continue
        gap = hole[7] - depth
        k = _put(rows, k, BOTTOM, x, x - gap * a, -a, gap)
    return k


@njit(cache=True)
def _tip_over_mouth(pin, hole):
    """Both of the tip's edge circles wholly over the hole's mouth (a pin in its hole, or over it within the capture).

    In scalars, the engine's usual case: then no point of either is over the face, as each point's
    distance from the hole's axis is at most its circle's centre's plus its radius.
    """
    outer = hole[6] + hole[8]
    for k in range(2):
        s_k, rho_k = (pin[7], pin[6] - pin[8]) if k == 0 else (pin[7] - pin[8], pin[6])
        w0 = pin[0] + s_k * pin[3] - hole[0]
        w1 = pin[1] + s_k * pin[4] - hole[1]
        w2 = pin[2] + s_k * pin[5] - hole[2]
        along = w0 * hole[3] + w1 * hole[4] + w2 * hole[5]
        r0, r1, r2 = w0 - along * hole[3], w1 - along * hole[4], w2 - along * hole[5]
        if math.sqrt(r0 * r0 + r1 * r1 + r2 * r2) + rho_k >= outer:
            return False
    return True


@njit(cache=True)
def _over_mouth(pin, hole):
    """The pin's tip within reach of the hole's mouth: its centre at most ``R + c_h + r`` from the hole's axis.

    Beyond, the tip's disk lies wholly outside the mouth's outer edge and the pin cannot touch the hole
    (its side's closed forms assume the pin at the hole: far from it they give a wall "contact" as
    deep as the distance); the face around the mouth holds it there.
    """
    w0 = pin[0] + pin[7] * pin[3] - hole[0]
    w1 = pin[1] + pin[7] * pin[4] - hole[1]
    w2 = pin[2] + pin[7] * pin[5] - hole[2]
    along = w0 * hole[3] + w1 * hole[4] + w2 * hole[5]
    r0, r1, r2 = w0 - along * hole[3], w1 - along * hole[4], w2 - along * hole[5]
    return math.sqrt(r0 * r0 + r1 * r1 + r2 * r2) <= hole[6] + hole[8] + pin[6]


@njit(cache=True)
def _others(hole):
    """How many other holes' mouths lie in the face of ``hole``'s row (0: a row without them)."""
    if hole.shape[0] < HOLE_COLUMNS:
        return 0
    return int(hole[FACE_COLUMNS])


@njit(cache=True)
def _arc_f(w, A, B, phi, outer):
    return math.sqrt(_sq(w, A, B, phi, 1.0)) - outer


@njit(cache=True)
def _arc_ends_over_face(c, rho, d1, d2, m, a, outer, rim_samples, golden_steps, inset, angles, k):
    """:func:`fixplan.geometry.pins._arc_ends_over_face`: appended to ``angles`` after entry ``k − 1``; the new count.

    At most :data:`_MAX_ARCS` arcs (a circle's projection, an ellipse, crosses a circle at most 4
    times: 2 arcs).
    """
    P = _proj(a)
    w, A, B = P @ (c - m), rho * (P @ d1), rho * (P @ d2)
    step = _TWO_PI / rim_samples
    cross = np.empty(2 * _MAX_ARCS)
    entering = np.zeros(2 * _MAX_ARCS, dtype=np.bool_)
    nc = 0
    for i in range(rim_samples):
        f0 = _arc_f(w, A, B, i * step, outer)
        f1 = _arc_f(w, A, B, (i + 1) * step, outer)
        if (f0 >= 0.0) == (f1 >= 0.0) or nc >= 2 * _MAX_ARCS:
            continue
        lo, hi = i * step, (i + 1) * step
        for _ in range(golden_steps):
            mid = 0.5 * (lo + hi)
            if (_arc_f(w, A, B, mid, outer) >= 0.0) == (f0 >= 0.0):
                lo = mid
            else:
                hi = mid
        cross[nc] = 0.5 * (lo + hi)
        entering[nc] = f1 >= 0.0
        nc += 1
    for i in range(nc):
        if not entering[i]:
            continue
        start = cross[i]
        span = (cross[(i + 1) % nc] - start) % _TWO_PI
        angles[k] = start + inset * span
        angles[k + 1] = start + (1.0 - inset) * span
        k += 2
    return k


@njit(cache=True)
def face_contacts(pin, hole, points, coaxial_rel, rim_samples, golden_steps, arc_inset, out, n):
    """The pin's tip on the face around the hole's mouth, ``points`` points from the deepest (kind :data:`FACE`).

    :func:`fixplan.geometry.pins.tip_face_contacts` (its text derives it), rows appended after
    row ``n − 1`` while ``out`` has room; returns the new count. None when ``hole`` has no face.
    With ``points`` above 1, the ends of the edge's arcs over the face (:func:`_arc_ends_over_face`).
    """
    if hole.shape[0] < FACE_COLUMNS or hole[10] == 0.0 or _tip_over_mouth(pin, hole):
        return n
    outer = hole[6] + hole[8]
    u, a, m, base = pin[3:6], hole[3:6], hole[0:3], pin[0:3]
    fc, fn, fe1 = hole[11:14], hole[14:17], hole[17:20]
    fe2 = np.cross(fn, fe1)
    h1, h2, disk = hole[20], hole[21], hole[10] == 2.0
    down = -(fn - (fn @ u) * u)
    sin_tilt = np.linalg.norm(down)
    c, rho = base + pin[7] * u, pin[6] - pin[8]
    if pin[8] > 0.0:  # the chamfer's base circle is the nearer beyond 45° of tilt
        c2 = base + (pin[7] - pin[8]) * u
        if (c2 - fc) @ fn - pin[6] * sin_tilt < (c - fc) @ fn - rho * sin_tilt:
            c, rho = c2, pin[6]
    if sin_tilt > coaxial_rel:
        d1 = down / sin_tilt
    else:  # flat on the face: the point farthest from the hole's axis
        w = (c - m) - ((c - m) @ u) * u
        norm_w = np.linalg.norm(w)
        if norm_w > coaxial_rel * hole[6]:
            d1 = w / norm_w
        else:
            d1, _e2 = _perp_basis(u, u, False)
    d2 = np.cross(u, d1)
    count = points if rho > 0.0 and points > 1 else 1
    angles = np.empty(count + 2 * _MAX_ARCS)
    for j in range(count):
        angles[j] = _TWO_PI * j / count
    k = count
    if points > 1 and rho > 0.0:  # where the edge leaves the face for the mouth: each such arc's ends
        k = _arc_ends_over_face(c, rho, d1, d2, m, a, outer, rim_samples, golden_steps, arc_inset, angles, k)
    for j in range(k):
        if n >= out.shape[0]:
            break
        phi = angles[j]
        x = c + rho * (math.cos(phi) * d1 + math.sin(phi) * d2)
        gap = (x - fc) @ fn
        v = x - m
        beyond_mouth = np.linalg.norm(v - (v @ a) * a) - outer
        q1, q2 = (x - fc) @ fe1, (x - fc) @ fe2
        inside = h1 - math.hypot(q1, q2) if disk else min(h1 - abs(q1), h2 - abs(q2))
        for jo in range(_others(hole)):  # the other holes' mouths in the face: no material there either
            o = FACE_COLUMNS + 1 + 10 * jo
            w = x - hole[o : o + 3]
            aj = hole[o + 3 : o + 6]
            beyond_mouth = min(beyond_mouth, np.linalg.norm(w - (w @ aj) * aj) - (hole[o + 6] + hole[o + 8]))
        if beyond_mouth < 0.0 or inside < 0.0 or (gap < 0.0 and -gap > min(beyond_mouth, inside)):
            continue  # over a hole, off the part, or nearer a mouth's edge or the part's side
        n = _put(out, n, FACE, x, x - gap * fn, -fn, gap)
    return n


@njit(cache=True)
def pose_contacts(
    pins, holes_body, bores, peg, R, p, rim_samples, newton_steps, golden_steps, coaxial_rel, face_points, arc_inset,
    out,
):  # fmt: skip
    """Every contact of every pin (in its hole of the part at the pose ``(R, p)``) and bore (with the part as its peg).

    ``pins`` (k, 14) and ``holes_body`` (k, 10) or (k, :data:`FACE_COLUMNS`): each pin and its hole
    in body coordinates (with the face around its mouth: the pin's tip on it, :func:`face_contacts`,
    ``face_points`` points of it, at least the deepest);
    ``bores`` (j, 10) or (j, :data:`FACE_COLUMNS`) in world coordinates (with the fixture's face
    around the mouth: the part's leading end on it, :func:`face_contacts`), ``peg`` = (radius,
    length) of the cylindrical part (its end deeper in the bore leads). ``arc_inset``: the face's
    arc ends (:func:`_arc_ends_over_face`). ``out`` ((k + j)·:data:`MAX_CONTACTS`, 13): one row per contact,
    ``[owner (pins then bores), is a bore, kind, point on the pin or peg (3), point on the hole's or
    bore's body (3), normal from the pin into the hole's body (3), gap]``. Returns the number of rows.
    A tip face on a blind hole's bottom adds its rim's points (:func:`_face_points`, ``face_points``
    of them; 0 or 1: the deepest point only, as :func:`contacts`).
    """
    rows = np.zeros((MAX_CONTACTS, 11))
    more = np.zeros((MAX_CONTACTS, 11))
    hole = np.zeros(holes_body.shape[1])
    other = np.zeros(10)
    faced = holes_body.shape[1] >= FACE_COLUMNS
    n = 0
    for i in range(pins.shape[0]):
        hole[:] = holes_body[i]
        hole[0:3] = p + R @ holes_body[i, 0:3]
        hole[3:6] = R @ holes_body[i, 3:6]
        for j in range(_others(hole)):  # the other holes' mouths in the face, moved
            o = FACE_COLUMNS + 1 + 10 * j
            hole[o : o + 3] = p + R @ holes_body[i, o : o + 3]
            hole[o + 3 : o + 6] = R @ holes_body[i, o + 3 : o + 6]
        k = 0
        if _over_mouth(pins[i], hole):  # far from its hole (on the face, or in another hole) it touches none of it
            k = contacts(pins[i], hole, rim_samples, newton_steps, golden_steps, coaxial_rel, rows)
        for r in range(k):
            if rows[r, 0] == BOTTOM:
                k = _face_points(pins[i], hole, face_points, coaxial_rel, rows, k)
                break
        if faced and hole[10] != 0.0 and not _tip_over_mouth(pins[i], hole):  # the face, moved only when needed
            hole[11:14] = p + R @ holes_body[i, 11:14]
            hole[14:17] = R @ holes_body[i, 14:17]
            hole[17:20] = R @ holes_body[i, 17:20]
            k = face_contacts(pins[i], hole, max(face_points, 1), coaxial_rel, rim_samples, golden_steps, arc_inset,
                              rows, k)  # fmt: skip
        for j in range(_others(hole)):  # the pin on (or in) another hole of the face: its contacts with it
            o = FACE_COLUMNS + 1 + 10 * j
            other[:] = hole[o : o + 10]
            if not _over_mouth(pins[i], other):
                continue
            m = contacts(pins[i], other, rim_samples, newton_steps, golden_steps, coaxial_rel, more)
            for r in range(m):
                if more[r, 0] == BOTTOM:
                    m = _face_points(pins[i], other, face_points, coaxial_rel, more, m)
                    break
            for r in range(m):
                if k < MAX_CONTACTS:
                    rows[k] = more[r]
                    k += 1
        for r in range(k):
            out[n, 0], out[n, 1] = i, 0.0
            out[n, 2:13] = rows[r]
            n += 1
    if bores.shape[0] == 0:
        return n
    radius, length = peg[0], peg[1]
    z = R[:, 2].copy()
    e0 = p + 0.5 * length * z
    e1 = p - 0.5 * length * z
    pg = np.zeros(14)
    for j in range(bores.shape[0]):
        a, mouth = bores[j, 3:6], bores[j, 0:3]
        if (mouth - e0) @ a >= (mouth - e1) @ a:
            pg[0:3], pg[3:6] = e1, z
        else:
            pg[0:3], pg[3:6] = e0, -z
        pg[6], pg[7] = radius, length
        k = contacts(pg, bores[j], rim_samples, newton_steps, golden_steps, coaxial_rel, rows)
        for r in range(k):
            if rows[r, 0] == BOTTOM:
                k = _face_points(pg, bores[j], face_points, coaxial_rel, rows, k)
                break
        if bores.shape[1] >= FACE_COLUMNS:  # the fixture's face around the mouth (world frame already)
            k = face_contacts(pg, bores[j], max(face_points, 1), coaxial_rel, rim_samples, golden_steps, arc_inset,
                              rows, k)  # fmt: skip
        for r in range(k):
            out[n, 0], out[n, 1] = pins.shape[0] + j, 1.0
            out[n, 2:13] = rows[r]
            n += 1
    return n
