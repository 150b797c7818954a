"""The locating error from clearance: the range of located poses the pins' clearances allow.

A part on rests and pins is located up to the play of its holes on the pins. With pins,
"located" means the rest locators touch and every pin is in its hole: the set of
poses that satisfy both is small, and this module measures it about the located pose ``X``
(``fixture.goal``, the part pushed to one side of the clearance).

A small displacement of the part is the twist ``δ = (v, ω)``: the body origin moves by ``v``
and the part turns by the rotation vector ``ω`` (world axes), so a point ``p`` of the part moves
by ``v + ω × (p − o)``. Linearised at ``X``:

- every locator stays touching: ``nᵢᵀ (v + ω × rᵢ) = 0`` at its contact point (normal ``nᵢ``);
- a round pin (axis ``a``, diameter ``d``) stays in its hole (diameter ``D``): the hole's axis at
  its mouth ``h``, offset from the pin's axis by ``e = P (h − p_pin)`` (``P = I − a aᵀ``), keeps
  ``‖e + P (v + ω × (h − o))‖ ≤ (D − d)/2``, a second-order cone;
- a diamond pin locates only along its ``land_direction`` ``n``: ``|nᵀ (e + …)| ≤ (D − d)/2``.

For each of the part's axes the least and the largest translation of the body origin along it,
and rotation about it, over that set: twelve small second-order cone programs (Clarabel). An
axis no constraint bounds (a round pin alone leaves the turn about its axis free) is reported
as free (``None``). Closed forms the tests check: a centred round pin gives exactly
``±(D − d)/2`` of play; with a diamond pin at the spacing ``L`` the turn about the pin's axis
spans ``±(c₁ + c₂)/L`` (``cᵢ = (Dᵢ − dᵢ)/2``; ``±c₂/L`` with the round pin's hole held on its
axis), and the point midway between the pins moves ``±(c₁ + c₂)/2`` across the line of pins.
The rests fix the tilt, so the offset at the hole's mouth stands for the whole engagement.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fixplan.errors import InfeasibleError, SolverError
from fixplan.locating import contact_set
from fixplan.model import Fixture
from fixplan.settings import DEFAULT, Settings
from fixplan.spatial import skew

FloatArray = NDArray[np.float64]

AXES = ("x", "y", "z")


@dataclass(frozen=True)
class ClearancePoseRange:
    """The range of located poses the pins' clearances allow, about the located pose, in the part's axes.

    ``translation_m[i]`` is ``(least, largest)`` displacement of the body origin along the part's
    axis ``i`` [m]; ``rotation_rad[i]`` the turn about it [rad]; ``None`` for a side no
    constraint bounds (free). ``violation`` is the largest constraint violation of the
    extreme poses found [m] (the programs' residual).
    """

    translation_m: tuple[tuple[float | None, float | None], ...]
    rotation_rad: tuple[tuple[float | None, float | None], ...]
    pins: tuple[str, ...]
    violation: float

    def width(self, kind: str, axis: int) -> float | None:
        """``largest − least`` for ``kind`` ("translation" or "rotation") along ``axis``; None when free."""
        lo, hi = (self.translation_m if kind == "translation" else self.rotation_rad)[axis]
        return None if lo is None or hi is None else hi - lo

    def to_json(self) -> dict[str, object]:
        return {
            "translation_m": {a: list(r) for a, r in zip(AXES, self.translation_m, strict=True)},
            "rotation_rad": {a: list(r) for a, r in zip(AXES, self.rotation_rad, strict=True)},
            "pins": list(self.pins),
            "violation_m": self.violation,
        }

    def lines(self) -> list[str]:
        """For people: one line for the translations, one for the rotations (``validate --verbose``)."""

        def span(r: tuple[float | None, float | None], unit: float, name: str) -> str:
            lo, hi = r
            if lo is None or hi is None:
                return "free"
            lo, hi = (round(x * unit, 6) + 0.0 for x in (lo, hi))  # to the nanometre (nanoradian): no round-off
            return f"{lo:+.4g} .. {hi:+.4g} {name}"

        t = ", ".join(f"{a} {span(r, 1e3, 'mm')}" for a, r in zip(AXES, self.translation_m, strict=True))
        w = ", ".join(f"{a} {span(r, 1e3, 'mrad')}" for a, r in zip(AXES, self.rotation_rad, strict=True))
        return [
            f"clearance ({', '.join(self.pins)}): the body origin moves {t} (part axes, from the located pose)",
            f"clearance: the part turns {w}",
        ]


def clearance_pose_range(fixture: Fixture, settings: Settings = DEFAULT) -> ClearancePoseRange:
    """The range of located poses the clearances of ``fixture``'s pins allow (see the module docstring).

    Raises
    ------
    InfeasibleError
        No pins, not a full fixture, or a located pose outside the clearance (a hole off its pin).
    SolverError
        A program Clarabel could not solve.
    """
    import clarabel

    if not fixture.pins:
        raise InfeasibleError(f"{fixture.source}: no [[pin]] entries (the clearance range is the pins')")
    X = fixture.goal
    o = X.p_world
    wp = fixture.workpiece
    rows: list[FloatArray] = []  # A (rows of b − A x ∈ K)
    rhs: list[FloatArray] = []
    cones: list[object] = []
    cs = contact_set(fixture, X, [loc.name for loc in fixture.locators])
    eq = [np.concatenate([c.normal_world, np.cross(c.point_world - o, c.normal_world)]) for c in cs.contacts]
    if eq:
        rows.append(np.array(eq))
        rhs.append(np.zeros(len(eq)))
        cones.append(clarabel.ZeroConeT(len(eq)))
    checks: list[tuple[str, FloatArray, FloatArray, float, FloatArray | None]] = []
    for pin in fixture.pins:
        hole = wp.hole(pin.hole)
        a = pin.axis_world
        P = np.eye(3) - np.outer(a, a)
        h = X.point_world_from_body(hole.p_body)
        e = P @ (h - pin.p_world)
        J = P @ np.hstack([np.eye(3), -skew(h - o)])  # the offset's change per twist (v, ω)
        c = 0.5 * (hole.diameter_m - pin.diameter_m)
        if pin.kind == "round":
            rows.append(np.vstack([np.zeros((1, 6)), -J]))
            rhs.append(np.concatenate([[c], e]))
            cones.append(clarabel.SecondOrderConeT(4))
            checks.append(("round", e, J, c, None))
        else:
            n = pin.land_direction_world
            if n is None:
                raise InfeasibleError(f"pin.{pin.name}: a diamond pin without land_direction")
            rows.append(np.vstack([n @ J, -(n @ J)]))
            rhs.append(np.array([c - n @ e, c + n @ e]))
            cones.append(clarabel.NonnegativeConeT(2))
            checks.append(("diamond", e, J, c, n))
    A = np.vstack(rows)
    b = np.concatenate(rhs)
    from scipy import sparse

    A_csc = sparse.csc_matrix(A)
    P0 = sparse.csc_matrix((6, 6))
    opts = clarabel.DefaultSettings()
    opts.verbose = False
    eps = settings.tolerances.cone_eps
    opts.tol_gap_abs = opts.tol_gap_rel = opts.tol_feas = eps
    R = X.R_world_body
    worst = 0.0
    out: dict[str, list[tuple[float | None, float | None]]] = {"translation": [], "rotation": []}
    for kind, block in (("translation", slice(0, 3)), ("rotation", slice(3, 6))):
        for i in range(3):
            g = np.zeros(6)
            g[block] = R[:, i]  # the component along the part's axis i
            ends: list[float | None] = []
            for sign in (1.0, -1.0):
                # min sign·gᵀx: +1 finds the least, −1 the largest
                solver = clarabel.DefaultSolver(P0, sign * g, A_csc, b, cones, opts)
                sol = solver.solve()
                status = str(sol.status)
                if status in ("DualInfeasible", "AlmostDualInfeasible"):
                    ends.append(None)
                    continue
                if status in ("PrimalInfeasible", "AlmostPrimalInfeasible"):
                    raise InfeasibleError(
                        f"{fixture.source}: the located pose is outside the pins' clearance (a hole off its pin)"
                    )
                if status not in ("Solved", "AlmostSolved"):
                    raise SolverError(f"clearance range: Clarabel stopped with {status}")
                x = np.asarray(sol.x, dtype=float)
                worst = max(worst, _violation(x, eq, checks))
                ends.append(float(g @ x))
            out[kind].append((ends[0], ends[1]))
    return ClearancePoseRange(
        tuple(out["translation"]), tuple(out["rotation"]), tuple(p.name for p in fixture.pins), worst
    )


def _violation(x: FloatArray, eq: list[FloatArray], checks: list) -> float:
    """The largest violation [m] of the constraints at the twist ``x``."""
    worst = max((abs(float(r @ x)) for r in eq), default=0.0)
    for kind, e, J, c, n in checks:
        off = e + J @ x
        value = float(np.linalg.norm(off)) if kind == "round" else abs(float(n @ off))
        worst = max(worst, value - c)
    return worst
