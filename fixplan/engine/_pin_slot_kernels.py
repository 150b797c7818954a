"""The pins' and bores' contacts at a pose as the compiled step's slots, in one compiled call (:mod:`.pin_slots`).

The Python assembly of the slots (a dozen NumPy calls per step) cost more than the contacts
themselves; this is the same arithmetic compiled, pinned to the NumPy reference
(:meth:`fixplan.engine.pin_slots.PinGeometry.slots_reference`) by ``tests/engine/test_pin_slots.py``.
(A change of :func:`fixplan.geometry._pin_kernels.pose_contacts` must touch this file too: numba's
on-disk cache of a kernel is keyed by its own file only, not by the kernels it calls.)
"""

from __future__ import annotations

import math

from numba import njit

from fixplan.geometry._pin_kernels import pose_contacts

_PLANE = 0.0  # fixplan.geometry.collision.PLANE


@njit(cache=True)
def pin_slots(
    pins, holes_body, bores, peg, R, p, rim_samples, newton_steps, golden_steps, coaxial_rel, face_points, arc_inset,
    band_m,
    raw, obs, slots, meta, normals, least,
):  # fmt: skip
    """The contacts within ``band_m`` as slots; returns how many (``m``).

    ``raw``: scratch for :func:`fixplan.geometry._pin_kernels.pose_contacts`. Fills the first
    ``m`` rows of ``obs`` (m, 16: a plane through the fixture's point, normal from the fixture into
    the part), ``slots`` (m, 5: the part's point in body coordinates, radius 0, its plane's row),
    ``meta`` (m, 4: owner, kind, ordinal among the owner's contacts of that kind, gap) and
    ``normals`` (m, 3); ``least`` (owners,): each owner's least gap over all its contacts.
    """
    n = pose_contacts(
        pins, holes_body, bores, peg, R, p, rim_samples, newton_steps, golden_steps, coaxial_rel, face_points, arc_inset,
        raw,
    )  # fmt: skip
    for i in range(least.shape[0]):
        least[i] = math.inf
    m = 0
    for r in range(n):
        owner, kind, gap = int(raw[r, 0]), raw[r, 2], raw[r, 12]
        ordinal = 0
        for q in range(r):
            if int(raw[q, 0]) == owner and raw[q, 2] == kind:
                ordinal += 1
        if gap < least[owner]:
            least[owner] = gap
        if gap > band_m:
            continue
        bore = raw[r, 1] != 0.0
        sign = -1.0 if bore else 1.0
        n0, n1, n2 = sign * raw[r, 9], sign * raw[r, 10], sign * raw[r, 11]
        # a pin: the part's point is on its hole (the hole's point); a bore: on the peg (the pin's)
        xo = 3 if bore else 6
        oo = 6 if bore else 3
        d0, d1, d2 = raw[r, xo] - p[0], raw[r, xo + 1] - p[1], raw[r, xo + 2] - p[2]
        slots[m, 0] = R[0, 0] * d0 + R[1, 0] * d1 + R[2, 0] * d2
        slots[m, 1] = R[0, 1] * d0 + R[1, 1] * d1 + R[2, 1] * d2
        slots[m, 2] = R[0, 2] * d0 + R[1, 2] * d1 + R[2, 2] * d2
        slots[m, 3] = 0.0
        slots[m, 4] = m
        # the plane's frame, columns t1, t2 = n × t1, n (fixplan.geometry.collision.plane_frame)
        a0, a1, a2 = abs(n0), abs(n1), abs(n2)
        k = 0 if (a0 <= a1 and a0 <= a2) else (1 if a1 <= a2 else 2)
        nk = n0 if k == 0 else (n1 if k == 1 else n2)
        t0, t1, t2 = -nk * n0, -nk * n1, -nk * n2
        if k == 0:
            t0 += 1.0
        elif k == 1:
            t1 += 1.0
        else:
            t2 += 1.0
        tn = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
        t0, t1, t2 = t0 / tn, t1 / tn, t2 / tn
        b0, b1, b2 = n1 * t2 - n2 * t1, n2 * t0 - n0 * t2, n0 * t1 - n1 * t0
        obs[m, 0] = _PLANE
        obs[m, 1], obs[m, 2], obs[m, 3] = raw[r, oo], raw[r, oo + 1], raw[r, oo + 2]
        obs[m, 4], obs[m, 5], obs[m, 6] = t0, b0, n0
        obs[m, 7], obs[m, 8], obs[m, 9] = t1, b1, n1
        obs[m, 10], obs[m, 11], obs[m, 12] = t2, b2, n2
        obs[m, 13], obs[m, 14], obs[m, 15] = 0.0, 0.0, 0.0
        meta[m, 0], meta[m, 1], meta[m, 2], meta[m, 3] = owner, kind, ordinal, gap
        normals[m, 0], normals[m, 1], normals[m, 2] = n0, n1, n2
        m += 1
    return m
