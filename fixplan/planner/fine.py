"""The fine plan of one transition: a body path (CasADi Opti + IPOPT) and its applied wrenches.

A contact state is a set of touched locators. From ``start``, where the ``established``
locators touch, :func:`plan_transition` finds ``knots + 1`` poses ending where ``target`` touches
too (docs/math.md "Planning", Section IV of the paper):

- every established locator keeps touching (gap = 0) at every knot;
- the target's gap never increases and is exactly 0 at the last knot;
- every other locator keeps a gap ≥ ``clearance_m`` at every knot (or its start gap, if that is
  smaller);
- **roll** or **slide** on the established contacts. With fewer than three established contacts
  the body rolls (docs/math.md: n < 3): the material point at each established contact does not
  slip, to first order — its displacement between consecutive knots has no tangential
  component. Three or more contacts leave too few rolling motions, and the body slides on all
  of them (Theorem 1). In 2D rolling on two contacts leaves no motion at all (2 normal +
  2 tangent rows on 3 dof), so in 2D the body rolls on at most one contact and slides on two:
  the planar reading of "n < 3 of 6" is "n < 2 of 3". ``kind=`` overrides the choice.
- smooth: the objective is the discrete kinetic energy ``K Σ_k ‖ξ_{k+1} − ξ_k‖²_M`` with the
  mass matrix ``M = diag(m I, R₀ I_b R₀ᵀ)`` at the start; its minimiser spaces the knots evenly in
  the metric of the body's inertia, the geodesic-like path an operator would push;
- toward the goal: plus ``GOAL_PULL · ‖ξ_K − ξ_goal‖²_M`` (both terms normalised by the initial
  guess's ``‖ξ_K‖²_M``), the end pose's distance from the located pose. The least energy alone
  closes the target's gap by turning the part to bring that point forward — away from the goal's
  orientation, which the later transitions then have to undo with long pivots: 24 generated
  3-2-1 boxes (``fixplan generate box-321 --seed 7`` and ``8``) verified 20 without the pull and
  24 with it.

Poses are parametrised by a twist ``ξ_k`` of the centre of mass relative to ``start``:
``c = c₀ + ξ[:3]``, ``R = exp(ξ[3:]) R₀`` (Rodrigues, written in CasADi with a Taylor branch
at 0); in 2D ``c = c₀ + ξ[:2]``, ``θ = θ₀ + ξ[2]``. ``ξ_0 = 0`` is fixed. The decision
variables are scaled, ``ξ = diag(L,…,L, 1,…,1) y`` with ``L`` the part's bounding radius, so
that metres and radians are both O(1); gaps are divided by ``L`` too.

Gaps in closed form
-------------------
A spherical tip of radius ρ at ``p`` (world) is seen in the body frame at
``q = Rᵀ(p − c) + com_body``. Its gap is written against one *feature* of the shape — the one it
touches at the goal pose (established locators: the one they touch at the start; every
locator when the fixture is not full and the goal is undefined: the nearest one at the start):

- a face plane (box/rectangle face from ``shape.face_of``, cylinder end, polygon edge line):
  ``g = n·q − h − ρ``;
- the lateral surface of a cylinder ``g = ‖q_xy‖ − r − ρ``; a sphere or disk ``g = ‖q‖ − r − ρ``.

For a convex shape each of these is a lower bound of the true signed distance (the body lies
inside the feature's half-space, cylinder or ball), so the clearance constraints are safe — a
locator whose goal face has a negative plane gap at the start (it lies beside another face) is
kept clear of a smooth maximum with the face that separates it there
(:func:`~fixplan.planner.features.clearance_features`) — and
it is exact where the closest point lies on the feature; established contacts and the target are
therefore also kept on their feature (face bounds, edge segment, cylinder length). Every planned
pose is checked afterwards with the exact :func:`~fixplan.locating.locator_contact` gaps; the
largest violation is reported as ``max_constraint_violation_m``.

Where complementarity would appear
----------------------------------
Nowhere here: the plan fixes the contact mode of every locator for the whole transition
(established: ``g = 0``; target: ``g ≥ 0`` decreasing to 0; others: ``g ≥ clearance``), so the
program is a smooth NLP without contact forces. Complementarity ``0 ≤ g_i ⊥ λ_i ≥ 0`` would
appear if the transcription carried the contact forces (a dynamic, force-based trajectory) or
let the solver choose which locators touch — a mathematical program with complementarity
constraints, which violates the constraint qualifications IPOPT relies on and needs relaxation
(``g_i λ_i ≤ ε``) or penalty homotopies. The forces are found instead per segment, after the path,
by the non-jamming wrench search (docs/math.md program 2 for sliding, program 3 for rolling).

Its pieces live apart: the closed-form surface features in :mod:`fixplan.planner.features`, the
applied wrench of each segment in :mod:`fixplan.planner.segments`.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from fixplan.errors import InputError, SolverError
from fixplan.kinematics import mass_matrix
from fixplan.locating import contact_set, locator_contact
from fixplan.planner.features import Feature, clearance_features, feature_at, smooth_max
from fixplan.planner.segments import segment_wrenches
from fixplan.settings import DEFAULT, PlannerSettings
from fixplan.spatial import Pose, log_so3, tangent_seed

if TYPE_CHECKING:
    from fixplan.model import Fixture, Locator

FloatArray = NDArray[np.float64]

KINDS = ("roll", "slide")
IPOPT_PATH_FOUND = ("Solve_Succeeded", "Solved_To_Acceptable_Level")  # IPOPT statuses that give a path


# ---------------------------------------------------------------------------------------------
# Result
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Transition:
    """The fine plan of one transition ``established → established + {target}``.

    Attributes
    ----------
    poses : list of Pose
        ``knots + 1`` poses ``T_world_body``, the first the start, the last where the target touches.
    wrenches : (knots, ndof) array
        Applied wrench per segment (about the body origin, world axes, as ``search_wrench``
        reports it); a row of NaN where the search failed or was not run.
    margins_N : (knots,) array
        Least normal force over the established contacts per segment [N] (NaN when not found);
        ``margins`` is a read-only alias, and ``"margins"`` its JSON key.
    found : (knots,) bool array
        Whether each segment's wrench search succeeded.
    segment_reasons : list of str
        The search's reason per segment.
    max_constraint_violation_m : float
        Largest violation of the plan's constraints measured with the exact numpy gaps [m].
    max_slip_m : float
        Rolling only: largest tangential displacement of an established contact's material point
        between two knots, measured with the exact contacts [m] (second order in the step).
    cost : float
        Mass-weighted path length ``Σ ‖Δξ_k‖_M / √m`` [m] (what the coarse search adds up).
    ipopt_status : str
        IPOPT's return status (``Solve_Succeeded``, ``Infeasible_Problem_Detected``, ...).
    """

    established: tuple[str, ...]
    target: str
    kind: str
    poses: list[Pose]
    wrenches: FloatArray
    margins_N: FloatArray
    success: bool
    reason: str
    max_constraint_violation_m: float
    solve_time_s: float
    ipopt_status: str
    found: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, dtype=bool))
    segment_reasons: list[str] = field(default_factory=list)
    max_slip_m: float = 0.0
    cost: float = float("inf")
    ipopt_iterations: int = 0

    @property
    def end_pose(self) -> Pose:
        """Where the target touches (the start of the next transition)."""
        return self.poses[-1]

    @property
    def knots(self) -> int:
        return len(self.poses) - 1

    @property
    def margins(self) -> FloatArray:
        """Alias of :attr:`margins_N` (least normal force per segment [N])."""
        return self.margins_N

    def to_json(self) -> dict[str, Any]:
        """Snake-case JSON with poses in the fixture spec's form."""

        def num(x: float) -> float | None:
            return float(x) if np.isfinite(x) else None

        return {
            "established": list(self.established),
            "target": self.target,
            "kind": self.kind,
            "success": bool(self.success),
            "reason": self.reason,
            "poses": [p.to_json() for p in self.poses],
            "wrenches": [[num(x) for x in row] for row in self.wrenches],
            "margins": [num(x) for x in self.margins_N],
            "found": [bool(x) for x in self.found],
            "segment_reasons": list(self.segment_reasons),
            "max_constraint_violation_m": float(self.max_constraint_violation_m),
            "max_slip_m": float(self.max_slip_m),
            "cost": num(self.cost),
            "solve_time_s": float(self.solve_time_s),
            "ipopt_status": self.ipopt_status,
            "ipopt_iterations": int(self.ipopt_iterations),
        }


GOAL_PULL = 1.0  # weight of the end pose's distance from the goal, relative to the path's energy


# ---------------------------------------------------------------------------------------------
# Poses from twists relative to the start
# ---------------------------------------------------------------------------------------------


def _exp_so3_ca(ca: Any, w: Any) -> Any:
    """Rodrigues' formula in CasADi, with a Taylor branch near 0 (both branches stay finite)."""
    th2 = ca.dot(w, w)
    small = th2 < DEFAULT.numerics.taylor_switch_rad2
    th2_safe = ca.if_else(small, 1.0, th2)
    th = ca.sqrt(th2_safe)
    a = ca.if_else(small, 1.0 - th2 / 6.0, ca.sin(th) / th)
    b = ca.if_else(small, 0.5 - th2 / 24.0, (1.0 - ca.cos(th)) / th2_safe)
    K = ca.skew(w)
    return ca.DM.eye(3) + a * K + b * ca.mtimes(K, K)


def pose_from_twist(start: Pose, xi: FloatArray, com_body: FloatArray) -> Pose:
    """The pose ``ξ`` away from ``start`` (``c = c₀ + v``, ``R = exp(ω) R₀``)."""
    return start.retract(np.asarray(xi, dtype=float), com_body)


def twist_from_pose(start: Pose, pose: Pose, com_body: FloatArray) -> FloatArray:
    """Inverse of :func:`pose_from_twist`."""
    d = start.dimension
    dc = pose.point_world_from_body(com_body) - start.point_world_from_body(com_body)
    if d == 3:
        return np.concatenate([dc, log_so3(pose.R_world_body @ start.R_world_body.T)])
    dth = (pose.angle_rad - start.angle_rad + np.pi) % (2 * np.pi) - np.pi
    return np.concatenate([dc, [dth]])


# ---------------------------------------------------------------------------------------------
# The planner
# ---------------------------------------------------------------------------------------------


def default_kind(dimension: int, n_established: int) -> str:
    """Roll on fewer than three contacts in 3D (fewer than two in 2D), else slide."""
    return "roll" if n_established < (3 if dimension == 3 else 2) else "slide"


def plan_transition(
    fixture: Fixture,
    start: Pose,
    established: Sequence[str],
    target: str,
    *,
    knots: int = 20,
    clearance_m: float = 1e-3,
    warm_start: Transition | None = None,
    kind: str | None = None,
    acceleration_mps2: float = 1.0,
    max_iter: int | None = None,
    tol: float | None = None,
    friction_margin: float = 0.0,
    margin_N: float | None = None,
    settings: PlannerSettings = DEFAULT.planner,
) -> Transition:
    """Plan the path and wrenches that add ``target`` to the ``established`` contacts.

    Parameters
    ----------
    start : Pose
        Where the body is; the established locators must touch there (|gap| ≤ ``touch_m``).
    established : sequence of str
        Locators kept touching throughout.
    target : str
        The locator that must touch at the last knot.
    knots : int
        Number of segments; the plan has ``knots + 1`` poses.
    clearance_m : float
        Least gap of every other locator [m].
    warm_start : Transition, optional
        A plan starting at ``start`` (e.g. a previous solve with other options) used as the initial
        guess, resampled to ``knots``; otherwise a straight line toward the goal pose, stopped
        where the target touches (or a linearised step toward the target without a goal).
    kind : "roll" or "slide", optional
        Override :func:`default_kind`.
    acceleration_mps2 : float
        Size of the desired acceleration per segment, ``sqrt(âᵀ M â / m)`` [m/s²]. With many
        contacts a very small one can be statically balanced by the search's wrench (on
        default.toml, {B1,B2,B3,S1,S2} → E1 is reported jammed at 0.1 m/s² and moves at 1 m/s²).
    friction_margin : float
        δ: each segment's push must move the part with friction anywhere in ``μ(1 ± δ)``
        (:func:`~fixplan.jamming.search.search_wrench`).
    margin_N : float, optional
        Least normal force on the kept contacts (default: the part's weight).

    Returns
    -------
    Transition
        Always returned for a well-posed question; ``success`` is False, with the reason, when
        IPOPT finds no path, the exact gaps violate the plan by more than ``touch_m``, or a
        segment's wrench search fails.

    Raises
    ------
    InputError
        Unknown or repeated names, a target among the established, a non-touching established
        locator, fewer than one knot, an unknown kind.
    """
    import casadi as ca

    est = tuple(established)
    names = [loc.name for loc in fixture.locators]
    for n in (*est, target):
        if n not in names:
            raise InputError(f"unknown locator {n!r} (known: {', '.join(names)})")
    if len(set(est)) != len(est):
        raise InputError(f"established locators repeat: {', '.join(est)}")
    if target in est:
        raise InputError(f"target {target!r} is already established")
    if knots < 1:
        raise InputError(f"knots must be ≥ 1, got {knots}")
    if not clearance_m >= 0.0:
        raise InputError(f"clearance_m must be ≥ 0, got {clearance_m}")
    if start.dimension != fixture.dimension:
        raise InputError(f"expected a {fixture.dimension}D start pose, got {start.dimension}D")
    kind = kind or default_kind(fixture.dimension, len(est))
    if kind not in KINDS:
        raise InputError(f"kind must be one of {KINDS}, got {kind!r}")

    wp = fixture.workpiece
    d = fixture.dimension
    nv = fixture.ndof
    K = int(knots)
    com_b = np.asarray(wp.com_body, dtype=float)
    tol_touch = fixture.tolerances.touch_m
    locs = {loc.name: loc for loc in fixture.locators}
    others = [n for n in names if n not in est and n != target]

    start_gaps = {n: locator_contact(wp, start, locs[n]).gap_m for n in names}
    loose = [f"{n} ({start_gaps[n]:.3g} m)" for n in est if abs(start_gaps[n]) > tol_touch]
    if loose:
        raise InputError(f"established locators must touch at the start (|gap| ≤ {tol_touch:g} m): {', '.join(loose)}")

    goal: Pose | None = None
    if fixture.is_full:
        try:
            goal = fixture.goal
        except Exception:  # noqa: BLE001 - no goal: fall back to the start's features
            goal = None
    features = {n: feature_at(fixture, locs[n], start if (n in est or goal is None) else goal) for n in names}
    second: dict[str, Feature] = {}  # a second face for locators beside the goal's face (see clearance_features)
    for n in names:
        if n not in est and n != target:
            extra = clearance_features(fixture, locs[n], start, features[n])[1:]
            if extra:
                second[n] = extra[0]

    # --- scaling and the metric -------------------------------------------------------------
    L = max(wp.shape.bounding_radius, 1e-6)
    scale = np.concatenate([np.full(d, L), np.ones(nv - d)])
    M0 = mass_matrix(wp.mass_kg, wp.inertia_body, start.R_world_body)
    W = np.diag(scale) @ M0 @ np.diag(scale) / (wp.mass_kg * L * L)  # metric on y

    # --- initial guess ------------------------------------------------------------------------
    xi_guess, guess_note = _initial_guess(fixture, start, est, target, goal, warm_start, K, kind, com_b)
    y_guess = xi_guess / scale[:, None]

    # --- the NLP ------------------------------------------------------------------------------
    opti = ca.Opti()
    Y = opti.variable(nv, K)
    c0 = start.point_world_from_body(com_b)
    R0 = start.R_world_body

    def knot(k: int) -> tuple[Any, Any]:
        """(R, c) at knot k as CasADi expressions (knot 0 numeric)."""
        if k == 0:
            return ca.DM(R0), ca.DM(c0)
        xi = ca.DM(scale) * Y[:, k - 1]
        c = ca.DM(c0) + xi[:d]
        if d == 3:
            R = ca.mtimes(_exp_so3_ca(ca, xi[3:6]), ca.DM(R0))
        else:
            th = start.angle_rad + xi[2]
            R = ca.vertcat(ca.horzcat(ca.cos(th), -ca.sin(th)), ca.horzcat(ca.sin(th), ca.cos(th)))
        return R, c

    frames = [knot(k) for k in range(K + 1)]

    def q_of(k: int, name: str) -> Any:
        R, c = frames[k]
        return ca.mtimes(R.T, ca.DM(locs[name].p_world) - c) + ca.DM(com_b)

    gaps: dict[tuple[int, str], Any] = {}

    def gap(k: int, name: str) -> Any:
        if (k, name) not in gaps:
            q = q_of(k, name)
            dist = features[name].distance(ca, q)
            if name in second:
                dist = smooth_max(ca, dist, second[name].distance(ca, q))
            gaps[k, name] = dist - locs[name].radius_m
        return gaps[k, name]

    # constraints are collected and handed to Opti as two vectors (one call each: scalar
    # subject_to calls were a fifth of the transition's time)
    eqs: list[Any] = []
    ineqs: list[Any] = []  # each ≥ 0
    plane_start = {n: float(gap(0, n)) for n in names}
    for k in range(1, K + 1):
        for n in est:
            eqs.append(gap(k, n) / L)
            ineqs.extend(e / L for e in features[n].inside(ca, features[n].point_at(ca, q_of(k, n))))
        for n in others:
            ineqs.append((gap(k, n) - min(clearance_m, plane_start[n])) / L)
        ineqs.append((gap(k - 1, target) - gap(k, target)) / L)
    eqs.append(gap(K, target) / L)
    ineqs.extend(e / L for e in features[target].inside(ca, features[target].point_at(ca, q_of(K, target))))
    if kind == "roll":
        for k in range(K):
            eqs.extend(expr / L for expr in _no_slip(ca, frames, k, est, features, locs, q_of, com_b, start, d))
    if eqs:
        opti.subject_to(ca.vertcat(*eqs) == 0)
    if ineqs:
        opti.subject_to(ca.vertcat(*ineqs) >= 0)

    # objective: K Σ ‖Δy‖²_W, normalised by the guess's end point
    norm = float(y_guess[:, -1] @ W @ y_guess[:, -1]) or 1.0
    dY = Y - ca.horzcat(ca.DM.zeros(nv, 1), Y[:, : K - 1])
    energy = ca.sum2(ca.sum1(dY * ca.mtimes(ca.DM(W), dY)))
    objective = K * energy / norm
    if goal is not None and GOAL_PULL > 0:
        # ... plus the distance of the end pose from the goal pose (same metric): the least-energy
        # path to one locator turns the part to bring that point forward, away from the goal's
        # orientation, and the later transitions have to undo it (a generated box turned from
        # 5.6° to 11° to touch its first side locator, then to 18° when a push went astray)
        y_goal = twist_from_pose(start, goal, com_b) / scale
        e_goal = Y[:, K - 1] - ca.DM(y_goal)
        objective = objective + GOAL_PULL * ca.dot(e_goal, ca.mtimes(ca.DM(W), e_goal)) / norm
    opti.minimize(objective)
    opti.set_initial(Y, y_guess[:, 1:])
    opti.solver(
        "ipopt",
        {"print_time": False},
        settings.ipopt_options(tol, max_iter),
    )
    t0 = time.perf_counter()
    try:
        y_val = opti.solve_limited().value(Y)  # accepts hitting max_iter; the status is read below
    except RuntimeError as exc:
        # Opti raises on every unsuccessful IPOPT return (infeasible, restoration failed, ...):
        # keep IPOPT's status and last iterate; anything without a status is a real error.
        stats = opti.stats()
        if "return_status" not in stats:
            raise SolverError(f"IPOPT failed on {_state(est)} + {target}: {exc}", extras={"guess": guess_note}) from exc
        y_val = opti.debug.value(Y)
    solve_time = time.perf_counter() - t0
    stats = opti.stats()
    status = str(stats.get("return_status", "unknown"))
    iterations = int(stats.get("iter_count", 0))
    ipopt_ok = status in IPOPT_PATH_FOUND
    y_sol = np.asarray(y_val, dtype=float).reshape(nv, K)
    xi_sol = np.concatenate([np.zeros((nv, 1)), y_sol * scale[:, None]], axis=1)
    poses = [pose_from_twist(start, xi_sol[:, k], com_b) for k in range(K + 1)]

    # --- exact check --------------------------------------------------------------------------
    # the other locators are held against the model's start gaps (a lower bound of the exact
    # ones: with a second face the smooth maximum sits up to ~0.7 SMOOTH_MAX_M below), which is
    # what the NLP enforced; the exact start gap asked 28 µm more of a generated box and
    # rejected a sound path ("a feature's closed form does not hold")
    held = {n: min(start_gaps[n], plane_start[n]) for n in others}
    violation = _violation(fixture, poses, est, target, others, clearance_m, {**start_gaps, **held})
    slip = _slip(fixture, poses, est) if kind == "roll" else 0.0
    dxi = np.diff(xi_sol, axis=1)
    cost = float(sum(np.sqrt(max(float(v @ M0 @ v), 0.0)) for v in dxi.T) / np.sqrt(wp.mass_kg))

    def failed(reason: str) -> Transition:
        """A transition with no path (or an unsound one): no wrenches, infinite cost."""
        return Transition(
            est, target, kind, poses, np.full((K, nv), np.nan), np.full(K, np.nan), False, reason, violation,
            solve_time, status, np.zeros(K, dtype=bool), [], slip, float("inf"), iterations,
        )  # fmt: skip

    if not ipopt_ok:
        return failed(
            f"no path from {_state(est)} to touch {target} keeping the others ≥ {clearance_m:g} m away "
            f"(IPOPT: {status}, {guess_note})"
        )
    if violation > tol_touch:
        return failed(
            f"the planned poses violate the contacts by {violation:.3g} m with the exact gaps (allowed {tol_touch:g} m): "
            "a feature's closed form does not hold along the path"
        )

    # --- wrenches per segment -----------------------------------------------------------------
    wrenches, margins, found, reasons = segment_wrenches(
        fixture, poses, est, kind, acceleration_mps2, friction_margin=friction_margin, margin_N=margin_N
    )
    bad = [k for k in range(K) if not found[k]]
    if bad:
        k = bad[0]
        reason = f"segment {k} of {K} ({_state(est)} → {target}): {reasons[k]}"
        success = False
    else:
        margin = f"least margin {float(np.min(margins)):.3g} N" if est else "free motion, no contact to press"
        reason = f"{kind} on {_state(est)} to touch {target}: {K} segments, {margin}"
        success = True
    return Transition(
        est,
        target,
        kind,
        poses,
        wrenches,
        margins,
        success,
        reason,
        violation,
        solve_time,
        status,
        found,
        reasons,
        slip,
        cost if success else float("inf"),
        iterations,
    )


def _state(est: tuple[str, ...]) -> str:
    return "{" + ", ".join(est) + "}" if est else "free"


def _no_slip(
    ca: Any,
    frames: list,
    k: int,
    est: tuple[str, ...],
    features: dict,
    locs: dict,
    q_of: Any,
    com_b: FloatArray,
    start: Pose,
    d: int,
) -> list[Any]:
    """First-order no-slip rows of segment k: ``t·(R_kᵀ Δ(material point)) = 0`` (body frame).

    In 3D two rolling contacts leave one motion (the axis through both points), and the
    tangents along that axis are dependent: the second contact keeps only the tangent across it.
    """
    R_k, c_k = frames[k]
    R_n, c_n = frames[k + 1]
    out = []
    points = {}
    for n in est:
        q = q_of(k, n)
        f = features[n]
        x_b = f.point_at(ca, q)  # material point (body frame, relative to the body origin)
        n_b = f.normal_at(ca, q)
        # displacement of the material point, in body axes at knot k
        xc = x_b - ca.DM(com_b)  # relative to the centre of mass
        disp = ca.mtimes(R_k.T, ca.mtimes(R_n, xc) + c_n - c_k) - xc
        points[n] = (x_b, n_b, disp)
    axis_b = None
    if d == 3 and len(est) == 2:
        q0 = [start.point_body_from_world(locs[n].p_world) for n in est]
        axis_b = q0[1] - q0[0]
    for j, n in enumerate(est):
        x_b, n_b, disp = points[n]
        if d == 2:
            t = ca.vertcat(-n_b[1], n_b[0])
            out.append(ca.dot(t, disp))
            continue
        n0 = _numeric_normal(features[n], start, locs[n])
        a = tangent_seed(n0)
        if axis_b is not None and j == 1:
            along = axis_b - (axis_b @ n0) * n0
            if np.linalg.norm(along) > DEFAULT.numerics.zero_rel:
                a = along / np.linalg.norm(along)
        # spatial.tangent_basis, in CasADi: t1 = the seed projected off n, t2 = n × t1
        t1 = ca.DM(a) - ca.dot(ca.DM(a), n_b) * n_b
        t1 = t1 / ca.sqrt(ca.dot(t1, t1))
        t2 = ca.cross(n_b, t1)
        if not (axis_b is not None and j == 1):
            out.append(ca.dot(t1, disp))
        out.append(ca.dot(t2, disp))
    return out


def _numeric_normal(feature: Feature, pose: Pose, locator: Locator) -> FloatArray:
    import casadi as ca

    q = pose.point_body_from_world(locator.p_world)
    return np.asarray(ca.evalf(feature.normal_at(ca, ca.DM(q))), dtype=float).ravel()


def _initial_guess(
    fixture: Fixture,
    start: Pose,
    est: tuple[str, ...],
    target: str,
    goal: Pose | None,
    warm: Transition | None,
    K: int,
    kind: str,
    com_b: FloatArray,
) -> tuple[FloatArray, str]:
    """Twists ξ_0..ξ_K (ndof × K+1) to start IPOPT from, and a note of where they came from."""
    wp = fixture.workpiece
    if warm is not None and len(warm.poses) >= 2:
        dp, ang = warm.poses[0].distance_to(start)
        if dp <= DEFAULT.planner.same_pose_m and ang <= DEFAULT.planner.same_pose_m:
            xs = np.array([twist_from_pose(start, p, com_b) for p in warm.poses]).T
            s_old = np.linspace(0.0, 1.0, xs.shape[1])
            s_new = np.linspace(0.0, 1.0, K + 1)
            return np.array([np.interp(s_new, s_old, row) for row in xs]), "warm start"
    loc_t = fixture.locator(target)
    if goal is not None:
        xi_goal = twist_from_pose(start, goal, com_b)
        g0 = locator_contact(wp, start, loc_t).gap_m
        alphas = np.linspace(0.0, 1.0, 51)
        gaps = [locator_contact(wp, pose_from_twist(start, a * xi_goal, com_b), loc_t).gap_m for a in alphas]
        hit = next((i for i, g in enumerate(gaps) if g <= 0.0), len(alphas) - 1)
        if g0 > 0 and hit > 0:
            lo, hi = alphas[hit - 1], alphas[hit]
            for _ in range(40):
                mid = 0.5 * (lo + hi)
                if locator_contact(wp, pose_from_twist(start, mid * xi_goal, com_b), loc_t).gap_m > 0:
                    lo = mid
                else:
                    hi = mid
            end = hi * xi_goal
            return np.outer(end, np.linspace(0.0, 1.0, K + 1)), "straight line toward the goal"
    # Linearised: the least-M-norm step that closes the target's gap and keeps the contacts.
    cs = contact_set(fixture, start, [*est, target])
    rows = cs.J if kind == "roll" else cs.G
    n_rows_est = sum(c.size for c in cs.contacts[:-1]) if kind == "roll" else len(est)
    A = rows[: n_rows_est + 1] if kind != "roll" else np.vstack([rows[:n_rows_est], cs.G[-1:]])
    b = np.zeros(A.shape[0])
    b[-1] = -cs.contacts[-1].gap_m
    Minv = cs.M_inv
    end = Minv @ A.T @ np.linalg.pinv(A @ Minv @ A.T) @ b
    return np.outer(end, np.linspace(0.0, 1.0, K + 1)), "linearised step toward the target"


def _violation(
    fixture: Fixture,
    poses: list[Pose],
    est: tuple[str, ...],
    target: str,
    others: list[str],
    clearance_m: float,
    start_gaps: dict[str, float],
) -> float:
    """Largest violation of the plan's constraints with the exact gaps [m] (knots 1..K)."""
    wp = fixture.workpiece
    worst = 0.0
    K = len(poses) - 1
    prev_t = start_gaps[target]
    for k in range(1, K + 1):
        g = {loc.name: locator_contact(wp, poses[k], loc).gap_m for loc in fixture.locators}
        for n in est:
            worst = max(worst, abs(g[n]))
        for n in others:
            worst = max(worst, min(clearance_m, start_gaps[n]) - g[n])
        worst = max(worst, -g[target], g[target] - prev_t)
        prev_t = g[target]
        if k == K:
            worst = max(worst, abs(g[target]))
    return float(worst)


def _slip(fixture: Fixture, poses: list[Pose], est: tuple[str, ...]) -> float:
    """Largest tangential displacement of an established contact's material point per segment [m]."""
    wp = fixture.workpiece
    worst = 0.0
    for a, b in zip(poses[:-1], poses[1:], strict=True):
        for n in est:
            c = locator_contact(wp, a, fixture.locator(n))
            x_b = a.point_body_from_world(c.point_world)
            disp = b.point_world_from_body(x_b) - c.point_world
            tang = disp - (disp @ c.normal_world) * c.normal_world
            worst = max(worst, float(np.linalg.norm(tang)))
    return worst


__all__ = [
    "Transition",
    "default_kind",
    "plan_transition",
    "pose_from_twist",
    "twist_from_pose",
]
