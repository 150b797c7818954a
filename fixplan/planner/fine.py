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

When there is no path
---------------------
The program above is the first rung of :data:`LADDER`, an ordered list of formulations tried
until one finds a path (so a transition that plans at once costs what it always did): the
linearised gap-closing step as the initial guess; a *compliant* guess (short linearised steps,
each settled back onto the kept contacts: the pivot about a kept point, the turn about the axis
through two, the slide along a face — a straight line in twist coordinates cuts through them);
no pull toward the goal; sliding where the default rolls; kept contacts on the whole surface of
a box, so that one may cross an edge (when one touches another face than at the goal); two short
moves through the compliant guess's middle; and the target's gap free to open before it closes.
``Transition.formulation`` records the rung that found the path.

When none does, the reason names the cause. Locators that close together with the target
(:func:`closing_together`: at the goal, the target's normal row is a combination of the kept
rows and another locator's with a positive coefficient — a redundant layout, the rows' rank
below the locator count) are named first. Otherwise :func:`blocking_constraints` re-solves in
elastic mode (phase 1: a slack per constraint group — each other locator's clearance, the
target's monotone gap; then, if the kept motion cannot close the target even so, each kept
contact, feature bounds and no-slip rows too — minimising the slacks' sum) and names the groups
left with a slack, largest first.

Its pieces live apart: the closed-form surface features in :mod:`fixplan.planner.features`, the
applied wrench of each segment in :mod:`fixplan.planner.segments`.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from fixplan.errors import InputError, SolverError
from fixplan.kinematics import mass_matrix
from fixplan.locating import contact_set, locator_contact, solve_goal
from fixplan.planner.features import Feature, clearance_features, feature_at, smooth_max, surface_feature
from fixplan.planner.segments import carry_factor, needed_scale, segment_wrenches
from fixplan.settings import DEFAULT, PlannerSettings, SearchSettings, Settings
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
        IPOPT's return status (``Solve_Succeeded``, ``Infeasible_Problem_Detected``, ...) of the
        formulation that found the path (of the first one tried when none did).
    formulation : str
        The rung of :data:`LADDER` that found the path (``"default"``: the plain program); ``""``
        when none did (the reason lists each one's IPOPT status).
    wrenches_checked : bool
        False for a path whose segments' wrenches are not searched yet (``success`` then says
        only that a path exists; :func:`with_wrenches` completes it).
    together : tuple of str
        The locators that close together with ``target`` (:func:`closing_group`: a redundant
        layout where geometry makes them touch at the same instant); they touch at the last knot
        too, and the transition is ``established → established + {target} + together``.
    needed_scale : float or None
        Where the hand is too weak for some segment: the least factor by which one of its limits
        must grow for every segment to have a push (the most demanding segment's
        :func:`~fixplan.planner.segments.needed_scale`; its reason is the transition's). None
        otherwise.
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
    formulation: str = "default"
    together: tuple[str, ...] = ()
    needed_scale: float | None = None
    wrenches_checked: bool = True  # False: the path alone (``plan_transition(..., wrenches=False)``)

    @property
    def added(self) -> tuple[str, ...]:
        """Every locator the transition adds: the target, then those closing together with it."""
        return (self.target, *self.together)

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
            "formulation": self.formulation,
            "together": list(self.together),
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


@dataclass(frozen=True)
class Formulation:
    """One way of posing a transition's path program: a rung of :data:`LADDER`.

    Attributes
    ----------
    name : str
        What the Transition records (``Transition.formulation``).
    guess : str
        The initial guess: ``"default"`` (a warm start, else the straight line toward the goal
        stopped where the target touches, else the linearised step), ``"linearised"`` (the
        least-``M``-norm step that closes the target's gap keeping the kept contacts, to first
        order) or ``"compliant"`` (a chain of such short steps, each followed by settling the kept
        contacts back to touch: a screw about the kept contacts — the rotation about the axis
        through two kept points, about a kept contact's normal, ...).
    goal_pull : bool
        Whether the objective pulls the end pose toward the goal pose.
    other_kind : bool
        Slide where the default rolls (skipped when the caller gave ``kind``; rolling where the
        default slides leaves no motion: Theorem 1).
    kept : str
        ``"feature"``: each kept contact stays on the feature it touches at the start (face
        bounds); ``"surface"``: on the whole surface of a box or rectangle, so it may cross an
        edge (tried only when a kept contact touches another face than at the goal).
    waypoint : bool
        Two short programs chained through the compliant guess's middle pose (where the target's
        gap is half closed), each warm-started from its half of that guess.
    monotone : bool
        The target's gap never grows (else it only stays ≥ 0 until it closes: the part may back
        off the target first, e.g. to turn past it on five kept contacts).
    """

    name: str
    guess: str = "default"
    goal_pull: bool = True
    other_kind: bool = False
    kept: str = "feature"
    waypoint: bool = False
    monotone: bool = True


# The ordered ladder of formulations tried until one finds a path (one place). The first is the
# plain program; the others run only when it reports no path, so the common case costs the same.
LADDER: tuple[Formulation, ...] = (
    Formulation("default"),
    Formulation("linearised guess", guess="linearised"),
    Formulation("compliant guess", guess="compliant"),
    Formulation("compliant guess, no goal pull", guess="compliant", goal_pull=False),
    Formulation("slide instead of roll", guess="compliant", other_kind=True),
    Formulation("kept contacts across edges", guess="compliant", kept="surface"),
    Formulation("via a waypoint", guess="compliant", goal_pull=False, waypoint=True),
    Formulation("target may open first", guess="compliant", goal_pull=False, monotone=False),
    Formulation("slide, target may open first", guess="compliant", goal_pull=False, other_kind=True, monotone=False),
)


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
    ladder: Sequence[Formulation] = LADDER,
    diagnose: bool = True,
    together: Sequence[str] = (),
    wrenches: bool = True,
    profile: Settings = DEFAULT,
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
        Override :func:`default_kind` (the ladder then keeps it).
    acceleration_mps2 : float
        Size of the desired acceleration per segment, ``sqrt(âᵀ M â / m)`` [m/s²]. With many
        contacts a very small one can be statically balanced by the search's wrench (on
        default.toml, {B1,B2,B3,S1,S2} → E1 is reported jammed at 0.1 m/s² and moves at 1 m/s²).
    friction_margin : float
        δ: each segment's push must move the part with friction anywhere in ``μ(1 ± δ)``
        (:func:`~fixplan.jamming.search.search_wrench`).
    margin_N : float, optional
        Least normal force on the kept contacts (default: the part's weight).
    ladder : sequence of Formulation
        The formulations tried in turn until one finds a path (:data:`LADDER`; ``LADDER[:1]`` is
        the plain program alone). The one that found it is ``Transition.formulation``.
    diagnose : bool
        When no formulation finds a path, name what blocks it: locators that close together with
        the target (:func:`closing_together`), else the constraints an elastic re-solve has to
        relax (:func:`blocking_constraints`).
    together : sequence of str
        Locators that close together with ``target`` (:func:`closing_group`): planned as one
        transition. Their gaps stay ≥ 0 at every knot (no clearance: geometry closes them with
        the target, a second equality would only repeat the target's) and must touch at the last
        knot with the exact gaps (|gap| ≤ ``touch_m``). The wrench search is the target's: every
        locator of the group is open along each segment, pressed only at the end.
    wrenches : bool
        False: stop at the path (``wrenches_checked`` False, ``success`` meaning a path exists);
        :func:`with_wrenches` later searches its segments' wrenches. A search over sequences
        prices many transitions it then leaves: only those of the chosen sequence need wrenches.
    profile : Settings
        The settings the segments' wrench searches run with (``search``, ``witness``,
        ``numerics``; :func:`with_wrenches`); the path's thresholds are ``settings``.

    Returns
    -------
    Transition
        Always returned for a well-posed question; ``success`` is False, with the reason, when
        no formulation finds a path, the exact gaps violate the plan by more than ``touch_m``, or
        a segment's wrench search fails.

    Raises
    ------
    InputError
        Unknown or repeated names, a target among the established, a non-touching established
        locator, fewer than one knot, an unknown kind, a ladder with no formulation that applies.
    """
    est = tuple(established)
    group = tuple(together)
    names = [loc.name for loc in fixture.locators]
    for n in (*est, target, *group):
        if n not in names:
            raise InputError(f"unknown locator {n!r} (known: {', '.join(names)})")
    if len(set(est)) != len(est):
        raise InputError(f"established locators repeat: {', '.join(est)}")
    if target in est:
        raise InputError(f"target {target!r} is already established")
    if len(set((target, *group))) != len(group) + 1 or set(group) & set(est):
        raise InputError(
            f"together must name other locators than the target and the established ones, got {', '.join(group)}"
        )
    if knots < 1:
        raise InputError(f"knots must be ≥ 1, got {knots}")
    if not clearance_m >= 0.0:
        raise InputError(f"clearance_m must be ≥ 0, got {clearance_m}")
    if start.dimension != fixture.dimension:
        raise InputError(f"expected a {fixture.dimension}D start pose, got {start.dimension}D")
    if kind is not None and kind not in KINDS:
        raise InputError(f"kind must be one of {KINDS}, got {kind!r}")
    if not ladder:
        raise InputError("ladder must hold at least one formulation")
    base_kind = kind or default_kind(fixture.dimension, len(est))

    wp = fixture.workpiece
    tol_touch = fixture.tolerances.touch_m
    locs = {loc.name: loc for loc in fixture.locators}
    start_gaps = {n: locator_contact(wp, start, locs[n]).gap_m for n in names}
    loose = [f"{n} ({start_gaps[n]:.3g} m)" for n in est if abs(start_gaps[n]) > tol_touch]
    if loose:
        raise InputError(f"established locators must touch at the start (|gap| ≤ {tol_touch:g} m): {', '.join(loose)}")

    prob = _Problem.build(fixture, start, est, target, int(knots), clearance_m, settings, start_gaps, group)
    tried: list[str] = []
    first: _Path | None = None
    path: _Path | None = None
    compliant: FloatArray | None = None
    total_time = 0.0  # IPOPT's time over every formulation tried
    for form in ladder:
        k_form = base_kind
        if form.other_kind:
            if kind is not None or base_kind != "roll" or not est:
                continue  # the caller chose the motion; rolling where the default slides leaves no motion
            k_form = "slide"
        if form.kept == "surface" and not _off_goal_face(prob):
            continue  # every kept contact is on its goal face already: nothing to cross
        if form.guess == "compliant" and compliant is None:
            compliant = _compliant_guess(prob, k_form)
        later_iter = min(max_iter or settings.ipopt_max_iter, settings.ladder_max_iter)
        attempt = _solve_formulation(
            prob, form, k_form, warm_start, compliant, max_iter if first is None else later_iter, tol
        )
        total_time += attempt.solve_time_s
        tried.append(f"{form.name}: {attempt.status}")
        first = first or attempt
        if attempt.path_found:
            path = attempt
            break

    if first is None:
        raise InputError(
            f"no formulation of the ladder applies to {_state(est)} → {_added(target, group)} "
            f"(tried to skip: {', '.join(f.name for f in ladder)}); expected one without other_kind or kept='surface'"
        )
    if path is None:
        return _failed(prob, first, _no_path_reason(prob, first, tried, diagnose, max_iter, tol))

    pending = Transition(
        est, target, path.kind, path.poses, np.full((prob.K, fixture.ndof), np.nan), np.full(prob.K, np.nan),
        True, f"{path.kind} on {_state(est)} to touch {_added(target, group)}: a path, wrenches not searched yet",
        path.violation, total_time, path.status, np.zeros(prob.K, dtype=bool), [], path.slip, path.cost,
        path.iterations, path.formulation, group, wrenches_checked=False,
    )  # fmt: skip
    if not wrenches:
        return pending
    return with_wrenches(
        fixture, pending, acceleration_mps2=acceleration_mps2, friction_margin=friction_margin, margin_N=margin_N,
        plain=ladder[0].name, settings=profile,
    )  # fmt: skip


def with_wrenches(
    fixture: Fixture,
    transition: Transition,
    *,
    acceleration_mps2: float = 1.0,
    friction_margin: float = 0.0,
    margin_N: float | None = None,
    plain: str = "default",
    settings: Settings = DEFAULT,
) -> Transition:
    """Complete a path (``plan_transition(..., wrenches=False)``) with each segment's wrench.

    The same search :func:`plan_transition` runs; a transition already checked (or without a
    path) is returned as it is. ``plain`` names the ladder's first rung (the reason names any other).
    The searches run with ``settings`` (``search``, ``witness``, ``numerics``), whose
    ``search.limit_fraction`` is also the headroom the reason reports pushes beyond.
    """
    tr = transition
    if tr.wrenches_checked or not tr.success:
        return tr
    est, target, group, K = tr.established, tr.target, tr.together, tr.knots
    needs: list[tuple[float | None, float | None]] = []
    wrenches, margins, found, reasons = segment_wrenches(
        fixture, tr.poses, est, tr.kind, acceleration_mps2, friction_margin=friction_margin, margin_N=margin_N,
        needs=needs, settings=settings,
    )  # fmt: skip
    bad = [k for k in range(K) if not found[k]]
    via = "" if tr.formulation == plain else f" (formulation: {tr.formulation})"
    scale = None
    if bad:
        # where the hand is too weak, the most demanding segment says what the transition needs

        F_max, T_max, _ = fixture.hand_limits()
        scales = {k: needed_scale(needs[k], F_max, T_max) for k in bad}
        weak = {k: x for k, x in scales.items() if x is not None}
        k = max(weak, key=lambda j: (weak[j], -j)) if weak else bad[0]
        scale = weak.get(k)
        reason = f"segment {k} of {K} ({_state(est)} → {_added(target, group)}): {reasons[k]}"
        success = False
    else:
        margin = f"least margin {float(np.min(margins)):.3g} N" if est else "free motion, no contact to press"
        reason = f"{tr.kind} on {_state(est)} to touch {_added(target, group)}: {K} segments, {margin}{via}"
        reason += _beyond_headroom(fixture, wrenches, settings.search)
        success = True
    return replace(
        tr, wrenches=wrenches, margins_N=margins, success=success, reason=reason, found=found,
        segment_reasons=reasons, cost=tr.cost if success else float("inf"), wrenches_checked=True,
        needed_scale=scale,
    )  # fmt: skip


def _beyond_headroom(fixture: Fixture, wrenches: FloatArray, search: SearchSettings) -> str:
    """``"; 2 of 10 segments need more than 80 % of the hand's limits ..."``, or ``""``.

    The segments' searches keep within ``search.limit_fraction`` of the limits wherever a
    non-jamming push exists inside; the pushes beyond it are those where none does.
    """
    F_max, T_max, _ = fixture.hand_limits()
    frac = search.limit_fraction
    d = fixture.dimension
    rows = wrenches[np.isfinite(wrenches).all(axis=1)]
    if not len(rows) or frac >= 1.0:
        return ""
    cap = frac * (1.0 + search.binding_rel)
    over = (np.linalg.norm(rows[:, :d], axis=1) > cap * F_max) | (np.linalg.norm(rows[:, d:], axis=1) > cap * T_max)
    n = int(np.count_nonzero(over))
    if not n:
        return ""
    return (
        f"; {n} of {len(wrenches)} segments push beyond {frac:.0%} of the hand's limits"
        " (no non-jamming push exists inside there)"
    )


# ---------------------------------------------------------------------------------------------
# The path program
# ---------------------------------------------------------------------------------------------


@dataclass
class _Problem:
    """What every formulation of one transition shares (built once)."""

    fixture: Fixture
    start: Pose
    est: tuple[str, ...]
    target: str
    others: list[str]
    K: int
    clearance_m: float
    settings: PlannerSettings
    start_gaps: dict[str, float]
    goal: Pose | None
    features: dict[str, Feature]
    second: dict[str, Feature]
    scale: FloatArray
    M0: FloatArray
    W: FloatArray
    com_b: FloatArray
    L: float
    together: tuple[str, ...] = ()  # locators closing together with the target (gap ≥ 0, touch at the end)
    # kept contacts whose normal row at the goal is a combination of the other kept ones' (a group
    # added together earlier): their gap equality would repeat the others' (more equalities than
    # unknowns: IPOPT's Not_Enough_Degrees_Of_Freedom), so they are kept as gap ≥ 0 and checked exactly
    dependent: tuple[str, ...] = ()

    @staticmethod
    def build(
        fixture: Fixture,
        start: Pose,
        est: tuple[str, ...],
        target: str,
        K: int,
        clearance_m: float,
        settings: PlannerSettings,
        start_gaps: dict[str, float],
        together: tuple[str, ...] = (),
    ) -> _Problem:
        wp = fixture.workpiece
        d, nv = fixture.dimension, fixture.ndof
        names = [loc.name for loc in fixture.locators]
        locs = {loc.name: loc for loc in fixture.locators}
        goal: Pose | None = None
        if fixture.is_full:
            try:
                goal = fixture.goal_near(start)  # modulo the part's symmetry: the start's spin kept
            except Exception:  # noqa: BLE001 - no goal: fall back to the start's features
                goal = None
        features = {n: feature_at(fixture, locs[n], start if (n in est or goal is None) else goal) for n in names}
        second: dict[str, Feature] = {}  # a second face for locators beside the goal's face (see clearance_features)
        for n in names:
            if n not in est and n != target and n not in together:
                extra = clearance_features(fixture, locs[n], start, features[n])[1:]
                if extra:
                    second[n] = extra[0]
        # scaling and the metric
        L = max(wp.shape.bounding_radius, 1e-6)
        scale = np.concatenate([np.full(d, L), np.ones(nv - d)])
        M0 = mass_matrix(wp.mass_kg, wp.inertia_body, start.R_world_body)
        W = np.diag(scale) @ M0 @ np.diag(scale) / (wp.mass_kg * L * L)  # metric on y
        others = [n for n in names if n not in est and n != target and n not in together]
        com_b = np.asarray(wp.com_body, dtype=float)
        return _Problem(
            fixture, start, est, target, others, K, clearance_m, settings, start_gaps, goal, features, second,
            scale, M0, W, com_b, L, together, dependent_kept(fixture, est),
        )  # fmt: skip


@dataclass
class _Path:
    """One formulation's answer: the poses and their exact check."""

    formulation: str
    kind: str
    poses: list[Pose]
    status: str
    iterations: int
    solve_time_s: float
    violation: float
    slip: float
    cost: float
    guess_note: str
    path_found: bool


def _solve_formulation(
    prob: _Problem,
    form: Formulation,
    kind: str,
    warm: Transition | None,
    compliant: FloatArray | None,
    max_iter: int | None,
    tol: float | None,
) -> _Path:
    """Solve one rung of the ladder (two chained programs for a waypoint) and check it exactly."""
    K = prob.K
    if form.guess == "compliant" and compliant is not None:
        xi_guess, note = compliant, "compliant guess"
    elif form.guess == "linearised":
        xi_guess, note = _linearised_guess(prob, kind), "linearised step toward the target"
    else:
        xi_guess, note = _initial_guess(
            prob.fixture,
            prob.start,
            prob.est,
            prob.target,
            prob.goal,
            warm,
            K,
            kind,
            prob.com_b,
            prob.settings.same_pose_m,
        )
    features = dict(prob.features)
    if form.kept == "surface":
        surface = surface_feature(prob.fixture)
        if surface is not None:
            features.update({n: surface for n in prob.est})
    if form.waypoint and K >= 2 and compliant is not None:
        return _solve_via_waypoint(prob, form, kind, features, compliant, max_iter, tol)
    xi, status, iterations, solve_time = _solve_path(
        prob, kind, features, xi_guess, goal_pull=form.goal_pull, end_gap_m=0.0, max_iter=max_iter, tol=tol,
        monotone=form.monotone,
    )  # fmt: skip
    poses = [pose_from_twist(prob.start, xi[:, k], prob.com_b) for k in range(K + 1)]
    return _checked(prob, form.name, kind, poses, xi, status, iterations, solve_time, note, form.monotone)


def _solve_via_waypoint(
    prob: _Problem,
    form: Formulation,
    kind: str,
    features: dict[str, Feature],
    compliant: FloatArray,
    max_iter: int | None,
    tol: float | None,
) -> _Path:
    """A chain of two compliant moves: to the guess's middle (target half closed), then on."""
    K = prob.K
    K1 = K // 2
    fx, wp = prob.fixture, prob.fixture.workpiece
    loc_t = fx.locator(prob.target)
    mid = pose_from_twist(prob.start, compliant[:, K1], prob.com_b)
    g_mid = max(float(locator_contact(wp, mid, loc_t).gap_m), 0.0)
    xi1, st1, it1, t1 = _solve_path(
        prob, kind, features, compliant[:, : K1 + 1], goal_pull=False, end_gap_m=g_mid, max_iter=max_iter, tol=tol,
        knots=K1,
    )  # fmt: skip
    poses1 = [pose_from_twist(prob.start, xi1[:, k], prob.com_b) for k in range(K1 + 1)]
    note = "compliant guess, via its middle"
    if st1 not in IPOPT_PATH_FOUND:
        pad = poses1 + [poses1[-1]] * (K - K1)
        xi_pad = np.concatenate([xi1, np.repeat(xi1[:, -1:], K - K1, axis=1)], axis=1)
        return _checked(prob, form.name, kind, pad, xi_pad, st1, it1, t1, note)
    # the second move starts where the first ended: twists stay relative to the transition's start
    rest = compliant[:, K1:] - compliant[:, K1 : K1 + 1] + xi1[:, -1:]
    xi2, st2, it2, t2 = _solve_path(
        prob, kind, features, rest, goal_pull=form.goal_pull, end_gap_m=0.0, max_iter=max_iter, tol=tol,
        knots=K - K1, first=xi1[:, -1],
    )  # fmt: skip
    xi = np.concatenate([xi1, xi2[:, 1:]], axis=1)
    poses = [pose_from_twist(prob.start, xi[:, k], prob.com_b) for k in range(K + 1)]
    return _checked(prob, form.name, kind, poses, xi, st2, it1 + it2, t1 + t2, note)


def _checked(
    prob: _Problem,
    formulation: str,
    kind: str,
    poses: list[Pose],
    xi: FloatArray,
    status: str,
    iterations: int,
    solve_time: float,
    note: str,
    monotone: bool = True,
) -> _Path:
    """The exact check of a solved path: constraint violation, slip and mass-weighted length."""
    fx = prob.fixture
    # the other locators are held against the model's start gaps (a lower bound of the exact
    # ones: with a second face the smooth maximum sits up to ~0.7 smooth_max_m below), which is
    # what the NLP enforced; the exact start gap asked 28 µm more of a generated box and
    # rejected a sound path ("a feature's closed form does not hold")
    held = {n: min(prob.start_gaps[n], _model_gap(prob, n, prob.start)) for n in prob.others}
    violation = _violation(
        fx, poses, prob.est, prob.target, prob.others, prob.clearance_m, {**prob.start_gaps, **held}, monotone,
        prob.together,
    )  # fmt: skip
    slip = _slip(fx, poses, prob.est) if kind == "roll" else 0.0
    dxi = np.diff(xi, axis=1)
    cost = float(sum(np.sqrt(max(float(v @ prob.M0 @ v), 0.0)) for v in dxi.T) / np.sqrt(fx.workpiece.mass_kg))
    cost *= carry_factor(fx, prob.start, prob.est, settings=prob.settings)  # the same price as the coarse guess's
    found = status in IPOPT_PATH_FOUND and violation <= fx.tolerances.touch_m
    return _Path(formulation, kind, poses, status, iterations, solve_time, violation, slip, cost, note, found)


def _off_goal_face(prob: _Problem) -> list[str]:
    """Kept contacts on another face of a box or rectangle than at the goal (``"B2: -y, -z at the goal"``)."""
    if prob.goal is None or surface_feature(prob.fixture) is None:
        return []
    out = []
    for n in prob.est:
        at_goal = feature_at(prob.fixture, prob.fixture.locator(n), prob.goal).label
        if prob.features[n].label != at_goal:
            out.append(f"{n} touches face {prob.features[n].label} here, {at_goal} at the goal")
    return out


def _model_gap(prob: _Problem, name: str, pose: Pose) -> float:
    """The closed-form gap the program uses for ``name`` at ``pose`` (numeric)."""
    import casadi as ca

    loc = prob.fixture.locator(name)
    q = ca.DM(pose.point_body_from_world(loc.p_world))
    dist = prob.features[name].distance(ca, q)
    if name in prob.second:
        dist = smooth_max(ca, dist, prob.second[name].distance(ca, q), prob.settings.smooth_max_m)
    return float(dist) - loc.radius_m


def _numeric(ca: Any, expr: Any) -> float:
    """A constant CasADi expression's value (knot 0's gaps are built from numbers only)."""
    return float(ca.DM(expr)) if not isinstance(expr, ca.SX | ca.MX) else float(ca.evalf(expr))


def _solve_path(
    prob: _Problem,
    kind: str,
    features: dict[str, Feature],
    xi_guess: FloatArray,
    *,
    goal_pull: bool,
    end_gap_m: float,
    max_iter: int | None,
    tol: float | None,
    knots: int | None = None,
    first: FloatArray | None = None,
    elastic: Sequence[str] = (),
    monotone: bool = True,
) -> tuple[FloatArray, Any, int, float]:
    """Build and solve the path program; returns twists (ndof × K+1), status, iterations, time.

    ``first`` is the twist of knot 0 relative to the transition's start (a chained move starts
    where the previous one ended). ``elastic``: the constraint kinds (of :data:`CONSTRAINT_KINDS`)
    whose groups each get a slack ≥ 0, the objective then being their sum (the other groups and
    the target's end gap stay exact); the status is then ``(IPOPT status, {group: slack [m]})``.
    """
    import casadi as ca

    fx, start = prob.fixture, prob.start
    d, nv = fx.dimension, fx.ndof
    K = prob.K if knots is None else int(knots)
    est, target, L, scale, W, com_b = prob.est, prob.target, prob.L, prob.scale, prob.W, prob.com_b
    locs = {loc.name: loc for loc in fx.locators}
    y_guess = xi_guess / scale[:, None]
    y0 = np.zeros(nv) if first is None else np.asarray(first, dtype=float) / scale

    # SX symbols for the rows and the objective (Opti's MX graph of scalar rows built and evaluated
    # 2-3x slower); IPOPT is handed the program of _PathDerivatives: one knot's derivatives, mapped
    Y = ca.SX.sym("Y", nv, K)
    c0 = start.point_world_from_body(com_b)
    R0 = start.R_world_body

    p_first = start if first is None else pose_from_twist(start, np.asarray(first, dtype=float), com_b)
    frames = [(ca.DM(p_first.R_world_body), ca.DM(p_first.point_world_from_body(com_b)))]  # knot 0, numeric

    def q_of(k: int, name: str) -> Any:
        R, c = frames[k]
        return ca.mtimes(R.T, ca.DM(locs[name].p_world) - c) + ca.DM(com_b)

    def gap_of(q: Any, name: str) -> Any:
        dist = features[name].distance(ca, q)
        if name in prob.second:
            dist = smooth_max(ca, dist, prob.second[name].distance(ca, q), prob.settings.smooth_max_m)
        return dist - locs[name].radius_m

    # every knot's rows are the same function of its twist: built once on a symbol and called per
    # knot (one call, not the hundreds of scalar operations that rebuilding them took)
    gap_names = [*est, *prob.others, *prob.together, target]
    bound_names = [*est, target]

    def frame_of(y: Any) -> tuple[Any, Any]:
        """(R, c) of the scaled twist ``y`` from the transition's start (symbolic)."""
        xi = ca.DM(scale) * y
        if d == 3:
            R = ca.mtimes(_exp_so3_ca(ca, xi[3:6]), ca.DM(R0))
        else:
            th = start.angle_rad + xi[2]
            R = ca.vertcat(ca.horzcat(ca.cos(th), -ca.sin(th)), ca.horzcat(ca.sin(th), ca.cos(th)))
        return R, ca.DM(c0) + xi[:d]

    y_sym = ca.SX.sym("y", nv)
    R_sym, c_sym = frame_of(y_sym)

    def q_sym(name: str) -> Any:
        return ca.mtimes(R_sym.T, ca.DM(locs[name].p_world) - c_sym) + ca.DM(com_b)

    bounds_sym = [ca.vertcat(*features[n].inside(ca, features[n].point_at(ca, q_sym(n)))) for n in bound_names]
    floors = _plane_obstacles(prob)
    floors_sym = []
    for _name, n_w, offset, B, floor_m in floors:
        X = ca.mtimes(R_sym, ca.DM(B)) + ca.repmat(c_sym, 1, B.shape[1])
        floors_sym.append((ca.mtimes(ca.DM(n_w).T, X) - ca.DM(offset + floor_m).T).T)
    knot_rows = ca.Function(
        "knot_rows", [y_sym], [gap_of(q_sym(n), n) for n in gap_names] + bounds_sym + floors_sym
    )  # fmt: skip
    # every row below is affine in the knots' rows: it is written on placeholders Z (column k-1:
    # knot k's rows stacked) and its derivatives are assembled from one knot's (_PathDerivatives)
    sizes = [knot_rows.size1_out(i) for i in range(knot_rows.n_out())]
    Z = ca.SX.sym("Z", int(sum(sizes)), K)
    starts = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
    per_knot: list[Any] = [None] + [
        [Z[int(starts[i]) : int(starts[i + 1]), k - 1] for i in range(len(sizes))] for k in range(1, K + 1)
    ]
    gap_index = {n: i for i, n in enumerate(gap_names)}
    bound_index = {n: len(gap_names) + i for i, n in enumerate(bound_names)}

    def gap(k: int, name: str) -> Any:
        return gap_of(q_of(0, name), name) if k == 0 else per_knot[k][gap_index[name]]

    def bound_rows(k: int, name: str) -> list[Any]:
        rows = per_knot[k][bound_index[name]]
        return [rows[i] for i in range(rows.shape[0])]

    floor_index = {f[0]: len(gap_names) + len(bound_names) + i for i, f in enumerate(floors)}

    def obstacle_rows(k: int, name: str) -> list[Any]:
        rows = per_knot[k][floor_index[name]]
        return [rows[i] for i in range(rows.shape[0])]

    # constraint groups: (kind, locator) → rows; "eq" rows are = 0, the others ≥ 0. Collected and
    # handed to Opti as two vectors (one call each: scalar subject_to calls were a fifth of the
    # transition's time)
    groups: dict[tuple[str, str], tuple[str, list[Any]]] = {}

    def add(group: tuple[str, str], sense: str, rows: Sequence[Any]) -> None:
        groups.setdefault(group, (sense, []))[1].extend(rows)

    plane_start = {n: _numeric(ca, gap(0, n)) for n in prob.others}
    held = {n: min(prob.clearance_m, plane_start[n], _model_gap(prob, n, start)) for n in prob.others}
    for k in range(1, K + 1):
        for n in est:
            add(("kept contact", n), "ge" if n in prob.dependent else "eq", [gap(k, n) / L])
            add(("feature bounds", n), "ge", [e / L for e in bound_rows(k, n)])
        for n in prob.others:
            add(("clearance", n), "ge", [(gap(k, n) - held[n]) / L])
        for n in prob.together:
            # closing with the target: never through the part, touching where the target does
            # (geometry makes its gap a fixed multiple of the target's; no second end equality)
            add(("closing together", n), "ge", [gap(k, n) / L])
        for name, _n_w, _offset, _B, _floor_m in floors:
            # the part's collision points stay on the free side of every plane obstacle (a floor)
            add(("obstacle", name), "ge", [e / L for e in obstacle_rows(k, name)])
        if monotone:
            add(("monotone target gap", target), "ge", [(gap(k - 1, target) - gap(k, target)) / L])
        elif k < K:
            add(("clearance", target), "ge", [gap(k, target) / L])
    end_row = (gap(K, target) - end_gap_m) / L
    add(("feature bounds", target), "ge", [e / L for e in bound_rows(K, target)])
    if kind == "roll":
        # a segment's no-slip rows are one function of its two knots' twists (knot 0: y0)
        y_a, y_b = ca.SX.sym("ya", nv), ca.SX.sym("yb", nv)
        pair = [frame_of(y_a), frame_of(y_b)]

        def q_pair(k: int, name: str) -> Any:
            R, c = pair[k]
            return ca.mtimes(R.T, ca.DM(locs[name].p_world) - c) + ca.DM(com_b)

        rows_ns = _no_slip(ca, pair, 0, est, features, locs, q_pair, com_b, start, d)
        no_slip = ca.Function("no_slip", [y_a, y_b], [ca.vertcat(*[row for _, row in rows_ns])])
        Wp = ca.SX.sym("W", len(rows_ns), K)  # placeholders: segment k's no-slip rows
        for k in range(K):
            for i, (n, _) in enumerate(rows_ns):
                add(("no-slip", n), "eq", [Wp[i, k] / L])
    else:
        no_slip, Wp = None, ca.SX(0, K)
    keys = [g for g in groups if groups[g][1] and g[0] in elastic]
    eqs: list[Any] = [end_row]
    ineqs: list[Any] = []
    for g, (sense, rows) in groups.items():
        if g not in keys:
            (eqs if sense == "eq" else ineqs).extend(rows)
    S = ca.SX.sym("S", len(keys)) if keys else None
    if S is not None:
        for i, g in enumerate(keys):
            sense, rows = groups[g]
            if sense == "eq":
                ineqs.extend([S[i] - r for r in rows] + [S[i] + r for r in rows])
            else:
                ineqs.extend([r + S[i] for r in rows])
        ineqs.append(S)
    g_eq, g_ge = ca.vertcat(*eqs), (ca.vertcat(*ineqs) if ineqs else ca.SX(0, 1))
    n_eq, n_ge = int(g_eq.numel()), int(g_ge.numel())

    # objective: K Σ ‖Δy‖²_W, normalised by the guess's end point
    y_end = y_guess[:, -1] - y0
    norm = float(y_end @ W @ y_end) or 1.0
    dY = Y - ca.horzcat(ca.DM(y0), Y[:, : K - 1])
    energy = ca.sum2(ca.sum1(dY * ca.mtimes(ca.DM(W), dY)))
    objective = K * energy / norm
    if prob.goal is not None and GOAL_PULL > 0 and goal_pull:
        # ... plus the distance of the end pose from the goal pose (same metric): the least-energy
        # path to one locator turns the part to bring that point forward, away from the goal's
        # orientation, and the later transitions have to undo it (a generated box turned from
        # 5.6° to 11° to touch its first side locator, then to 18° when a push went astray)
        y_goal = twist_from_pose(start, prob.goal, com_b) / scale
        e_goal = Y[:, K - 1] - ca.DM(y_goal)
        objective = objective + GOAL_PULL * ca.dot(e_goal, ca.mtimes(ca.DM(W), e_goal)) / norm
    x0 = y_guess[:, 1:].reshape(-1, order="F")  # ca.vec stacks columns
    if S is not None:
        objective = ca.sum1(S) + prob.settings.elastic_regularisation * objective
        x0 = np.concatenate([x0, np.ones(len(keys))])
    derivs = _PathDerivatives(Y, S, Z, Wp, knot_rows, no_slip, y0, ca.vertcat(g_eq, g_ge), objective)
    solver = ca.nlpsol(
        "fine_path", "ipopt", {"x": derivs.x, "f": derivs.f, "g": derivs.g},
        {"print_time": False, "error_on_fail": False, "jac_g": derivs.jac_g, "hess_lag": derivs.hess_lag,
         "ipopt": prob.settings.ipopt_options(tol, max_iter)},
    )  # fmt: skip
    t0 = time.perf_counter()
    try:
        sol = solver(
            x0=x0, lbg=np.zeros(n_eq + n_ge), ubg=np.concatenate([np.zeros(n_eq), np.full(n_ge, np.inf)])
        )  # fmt: skip
    except RuntimeError as exc:
        raise SolverError(f"IPOPT failed on {_state(est)} + {target}: {exc}") from exc
    solve_time = time.perf_counter() - t0
    stats = solver.stats()
    if "return_status" not in stats:
        raise SolverError(f"IPOPT failed on {_state(est)} + {target}: no status ({stats.get('return_status')})")
    x_val = np.asarray(sol["x"], dtype=float).ravel()
    y_val = x_val[: nv * K]
    s_val = x_val[nv * K :]
    status: Any = str(stats.get("return_status", "unknown"))
    if elastic:
        s_arr = np.atleast_1d(np.asarray(s_val, dtype=float)) if S is not None else np.zeros(0)
        status = (status, {g: float(s) * L for g, s in zip(keys, s_arr, strict=True)})
    y_sol = np.asarray(y_val, dtype=float).reshape(nv, K, order="F")
    xi_sol = np.concatenate([y0[:, None], y_sol], axis=1) * scale[:, None]
    return xi_sol, status, int(stats.get("iter_count", 0)), solve_time


class _PathDerivatives:
    """The path program as IPOPT sees it: rows, their Jacobian and the Lagrangian's Hessian from one knot's.

    The rows ``g`` are affine in the knots' rows ``z(y_k)`` (each knot's gaps, feature bounds and
    obstacle rows: one function ``knot_rows`` of its twist) and in the segments' no-slip rows
    ``w(y_{k-1}, y_k)``: ``g = A_z vec(Z) + A_w vec(W) + A_s S + g₀``, read off the rows written on
    placeholders ``Z``, ``W``. So ``∂g/∂y_k`` is ``A_z`` times one knot's Jacobian ``∂z/∂y`` and
    the Hessian of ``λᵀg`` is the block diagonal of ``∇²(μ_kᵀ z)(y_k)`` with ``μ = A_zᵀ λ``, plus
    the no-slip pairs' blocks; ``f`` is quadratic (its Hessian a constant). The knot functions
    are differentiated once and mapped over the knots. CasADi's own derivatives of the whole
    program, every knot inlined, were most of a transition's time (30-150 ms to build against
    5-40 ms for IPOPT to solve).
    """

    def __init__(
        self,
        Y_sx: Any,
        S_sx: Any,
        Z: Any,
        W: Any,
        knot_rows: Any,
        no_slip: Any,
        y0: FloatArray,
        g_rows: Any,
        f_sx: Any,
    ) -> None:
        import casadi as ca

        nv, K = Y_sx.shape
        n_z, n_w = Z.shape[0], W.shape[0]
        n_s = 0 if S_sx is None else int(S_sx.numel())
        s_sym = S_sx if S_sx is not None else ca.SX(0, 1)
        z_sym, w_sym = ca.vec(Z), ca.vec(W)
        everything = ca.vertcat(z_sym, w_sym, s_sym)
        # the affine map (numbers): A_z, A_w, A_s and the constant g₀; a row that is not affine in
        # the placeholders leaves a free symbol, which Function refuses
        affine = ca.Function("affine", [], [
            ca.jacobian(g_rows, z_sym), ca.jacobian(g_rows, w_sym), ca.jacobian(g_rows, s_sym),
            ca.substitute(g_rows, everything, ca.SX.zeros(everything.numel())),
        ])  # fmt: skip
        A_z, A_w, A_s, g0 = affine.call([])
        x_sx = ca.vec(Y_sx) if S_sx is None else ca.vertcat(ca.vec(Y_sx), S_sx)
        hess_f = ca.Function("hess_f", [x_sx], [ca.hessian(f_sx, x_sx)[0]]).call([ca.DM.zeros(x_sx.numel())])[0]
        f_fn = ca.Function("f", [x_sx], [f_sx])

        # one knot's rows, Jacobian and weighted Hessian, mapped over the knots
        y = ca.SX.sym("y", nv)
        z_of = ca.vertcat(*knot_rows.call([y]))
        mu = ca.SX.sym("mu", n_z)
        z_map = ca.Function("z", [y], [z_of]).map(K)
        jz_map = ca.Function("jz", [y], [ca.jacobian(z_of, y)]).map(K)
        hz_map = ca.Function("hz", [y, mu], [ca.hessian(ca.dot(mu, z_of), y)[0]]).map(K)

        X = ca.MX.sym("x", nv * K + n_s)
        Y = ca.reshape(X[: nv * K], nv, K)
        lam_f = ca.MX.sym("lam_f")
        lam_g = ca.MX.sym("lam_g", g_rows.numel())
        g = ca.mtimes(A_z, ca.vec(z_map.call([Y])[0])) + g0
        JZ = jz_map.call([Y])[0]  # n_z × (nv K): knot k's block in columns k nv .. (k+1) nv
        J_blocks = [ca.mtimes(A_z[:, k * n_z : (k + 1) * n_z], JZ[:, k * nv : (k + 1) * nv]) for k in range(K)]
        HZ = hz_map.call([Y, ca.reshape(ca.mtimes(A_z.T, lam_g), n_z, K)])[0]
        H_blocks: list[list[Any]] = [[ca.MX(nv, nv) for _ in range(K)] for _ in range(K)]
        for k in range(K):
            H_blocks[k][k] = HZ[:, k * nv : (k + 1) * nv]
        if n_w:
            ya, yb = ca.SX.sym("ya", nv), ca.SX.sym("yb", nv)
            w_of = no_slip.call([ya, yb])[0]
            nu = ca.SX.sym("nu", n_w)
            pair = ca.vertcat(ya, yb)
            w_map = ca.Function("w", [ya, yb], [w_of]).map(K)
            jw_map = ca.Function("jw", [ya, yb], [ca.jacobian(w_of, pair)]).map(K)
            hw_map = ca.Function("hw", [ya, yb, nu], [ca.hessian(ca.dot(nu, w_of), pair)[0]]).map(K)
            before = ca.horzcat(ca.DM(y0), Y[:, : K - 1])
            g = g + ca.mtimes(A_w, ca.vec(w_map.call([before, Y])[0]))
            JW = jw_map.call([before, Y])[0]  # n_w × (2 nv K): segment k's [∂/∂y_(k-1), ∂/∂y_k]
            HW = hw_map.call([before, Y, ca.reshape(ca.mtimes(A_w.T, lam_g), n_w, K)])[0]  # 2nv × 2nv K
            for k in range(K):
                A_k = A_w[:, k * n_w : (k + 1) * n_w]
                c = 2 * nv * k
                J_blocks[k] = J_blocks[k] + ca.mtimes(A_k, JW[:, c + nv : c + 2 * nv])
                H_blocks[k][k] = H_blocks[k][k] + HW[nv:, c + nv : c + 2 * nv]
                if k:  # knot 0 is fixed: only a segment from a free knot couples two knots
                    J_blocks[k - 1] = J_blocks[k - 1] + ca.mtimes(A_k, JW[:, c : c + nv])
                    H_blocks[k - 1][k - 1] = H_blocks[k - 1][k - 1] + HW[:nv, c : c + nv]
                    H_blocks[k - 1][k] = HW[:nv, c + nv : c + 2 * nv]
                    H_blocks[k][k - 1] = HW[nv:, c : c + nv]
        J = ca.horzcat(*J_blocks)
        H = ca.blockcat(H_blocks)
        if n_s:
            S = X[nv * K :]
            g = g + ca.mtimes(A_s, S)
            J = ca.horzcat(J, A_s)
            H = ca.diagcat(H, ca.MX(n_s, n_s))
        H = H + lam_f * hess_f
        p = ca.MX.sym("p", 0)
        self.x, self.g, self.f = X, g, f_fn.call([X])[0]
        self.jac_g = ca.Function("nlp_jac_g", [X, p], [g, J], ["x", "p"], ["g", "jac_g_x"])
        self.hess_lag = ca.Function(
            "nlp_hess_l", [X, p, lam_f, lam_g], [ca.triu(H)], ["x", "p", "lam_f", "lam_g"], ["triu_hess_gamma_x_x"]
        )


HULL_MIN_POINTS = 64  # fewer collision points than this are kept whole (primitives' corners and rims)


def _plane_obstacles(prob: _Problem) -> list[tuple[str, FloatArray, float, FloatArray, FloatArray]]:
    """The plane obstacles as clearance rows: ``(name, normal, n·o + radius, points about the CoM (d × n), held)``.

    A collision point ``b`` (:mod:`fixplan.geometry.collision`) is at ``c + R (b − com)``; its gap
    to the plane ``n·x − n·o − ρ`` must stay ≥ ``held`` = min(0, its gap at the start) (a part
    that starts on the floor may stay there; none passes through it). Box obstacles are left to
    the engine (a box's gap is not smooth across its edges).
    """
    from fixplan.geometry.collision import collision_points

    fx = prob.fixture
    planes = [ob for ob in fx.obstacles if ob.is_plane]
    if not planes:
        return []
    pts, radii = collision_points(fx.workpiece.shape, DEFAULT.engine.rim_points)
    hull = _hull_points(pts, radii)
    B = (pts - prob.com_b).T
    c0 = prob.start.point_world_from_body(prob.com_b)
    out = []
    for ob in planes:
        n_w = ob.R_world_obstacle[:, -1]
        offset = float(n_w @ ob.o_world)
        g0 = n_w @ (prob.start.R_world_body @ B + c0[:, None]) - offset - radii
        # the lowest point over a plane is a vertex of the points' hull, so the hull's rows keep every
        # point clear; a point that starts below the plane keeps its own row (its own start gap)
        rows = np.union1d(hull, np.flatnonzero(g0 < 0.0))
        out.append((ob.name, n_w, offset, B[:, rows], radii[rows] + np.minimum(g0[rows], 0.0)))
    return out


def _hull_points(pts: FloatArray, radii: FloatArray) -> NDArray[np.intp]:
    """Indices of the collision points a plane's clearance needs: the vertices of their convex hull.

    A mesh part's collision points are its vertices (2.5·10⁴ for 5·10⁴ triangles: as many rows per
    knot in the path program, whose construction then took minutes); the primitives' few points,
    points with a radius, and flat or degenerate sets are kept whole.
    """
    n = pts.shape[0]
    if n <= HULL_MIN_POINTS or pts.shape[1] != 3 or np.any(radii != radii[0]):
        return np.arange(n)
    from scipy.spatial import ConvexHull, QhullError

    try:
        return np.asarray(ConvexHull(pts).vertices, dtype=np.intp)
    except (QhullError, ValueError):
        return np.arange(n)


def _failed(prob: _Problem, first: _Path, reason: str) -> Transition:
    """A transition with no path (or an unsound one): no wrenches, infinite cost; the first rung's poses."""
    K, nv = prob.K, prob.fixture.ndof
    return Transition(
        prob.est, prob.target, first.kind, first.poses, np.full((K, nv), np.nan), np.full(K, np.nan), False, reason,
        first.violation, first.solve_time_s, first.status, np.zeros(K, dtype=bool), [], first.slip, float("inf"),
        first.iterations, "", prob.together,
    )  # fmt: skip


def _no_path_reason(
    prob: _Problem, first: _Path, tried: list[str], diagnose: bool, max_iter: int | None, tol: float | None
) -> str:
    """Why no formulation found a path, naming the blocking locators and constraint kinds."""
    est, target = prob.est, prob.target
    tol_touch = prob.fixture.tolerances.touch_m
    head = f"no path from {_state(est)} to touch {_added(target, prob.together)}"
    forms = f"(IPOPT: {'; '.join(tried)}; first guess: {first.guess_note})"
    if first.status in IPOPT_PATH_FOUND and len(tried) == 1:
        return (
            f"the planned poses violate the contacts by {first.violation:.3g} m with the exact gaps (allowed {tol_touch:g} m): "
            "a feature's closed form does not hold along the path"
        )
    if not diagnose:
        return f"{head} keeping the others ≥ {prob.clearance_m:g} m away {forms}"
    together = [c for c in closing_together(prob.fixture, est, target) if c.locator not in prob.together]
    if together:
        rank = together[0].rank
        pairs = ", ".join(c.locator for c in together)
        return (
            f"{pairs} close{'s' if len(together) == 1 else ''} together with {target} (rank {rank} at the goal): "
            f"{head} keeping {pairs} ≥ {prob.clearance_m:g} m away {forms}"
        )
    blockers = blocking_constraints(
        prob, first.kind, min(max_iter or prob.settings.ipopt_max_iter, prob.settings.ladder_max_iter), tol
    )
    if not blockers:
        return f"{head} keeping the others ≥ {prob.clearance_m:g} m away {forms}"
    what = " and ".join(b.phrase(prob.clearance_m) for b in blockers)
    if est and all(b.kind in ("clearance", "monotone target gap") for b in blockers):
        what = f"{_state(est)} stay{'s' if len(est) == 1 else ''} touching and {what}"
    worst = blockers[0]
    # a kept contact on another face than the goal's (a part tipped onto a base locator) cannot be
    # seated by adding contacts: the part has to leave it
    moved = _off_goal_face(prob)
    note = f"; {', '.join(moved)}" if moved else ""
    return f"{head}: {target} cannot close while {what} ({worst.blame()}, blocks it{note}) {forms}"


# ---------------------------------------------------------------------------------------------
# What blocks a transition
# ---------------------------------------------------------------------------------------------

CONSTRAINT_KINDS = ("kept contact", "clearance", "feature bounds", "no-slip", "monotone target gap")


@dataclass(frozen=True)
class Blocker:
    """A constraint group an elastic re-solve had to relax for the target to close.

    ``kind`` is one of :data:`CONSTRAINT_KINDS`, ``locator`` the locator it belongs to, ``slack_m``
    how far it had to give way [m] (the largest over the path's knots).
    """

    kind: str
    locator: str
    slack_m: float
    feature: str = ""

    def phrase(self, clearance_m: float) -> str:
        """What the constraint asks, in words."""
        on = f" its {self.feature} face" if self.feature.startswith(("+", "-")) else ""
        if self.kind == "kept contact":
            return f"{self.locator} stays touching{on}"
        if self.kind == "clearance":
            return f"{self.locator} stays ≥ {clearance_m * 1e3:.3g} mm away"
        if self.kind == "feature bounds":
            return f"{self.locator} stays within{on or ' its face'}"
        if self.kind == "no-slip":
            return f"{self.locator} rolls without slipping"
        return f"{self.locator}'s gap never grows"

    def blame(self) -> str:
        """Which constraint gives way, and by how much."""
        return f"{self.locator}'s {self.kind} constraint, relaxed by {self.slack_m * 1e3:.3g} mm"


def blocking_constraints(
    prob: _Problem, kind: str, max_iter: int | None = None, tol: float | None = None
) -> list[Blocker]:
    """The constraint groups an elastic phase 1 relaxes so that the target can close, largest first.

    The same program with a slack ``s_g ≥ 0`` per group: ``|row| ≤ s_g`` for equalities,
    ``row + s_g ≥ 0`` for inequalities, the target's end gap exact, minimising ``Σ s_g`` (plus a
    small multiple of the path's objective). First only the other locators' clearances and the
    target's monotone gap are relaxed, the motion (kept contacts, feature bounds, no-slip) kept
    exact: when that solves, the clearances left with a slack above
    ``settings.blocking_slack_m`` are what forbids the move. When even that is infeasible the kept
    motion itself cannot close the target, and every group is relaxed (each kept contact, each
    locator's feature bounds, each contact's no-slip rows too).
    """
    guess = _compliant_guess(prob, kind)
    slacks: dict[tuple[str, str], float] = {}
    for relaxed in (("clearance", "monotone target gap"), CONSTRAINT_KINDS):
        _, (status, slacks), _, _ = _solve_path(
            prob, kind, prob.features, guess, goal_pull=False, end_gap_m=0.0, max_iter=max_iter, tol=tol,
            elastic=relaxed,
        )  # fmt: skip
        if status in IPOPT_PATH_FOUND:
            break
    out = [
        Blocker(g[0], g[1], s, prob.features[g[1]].label)
        for g, s in slacks.items()
        if s > prob.settings.blocking_slack_m
    ]
    return sorted(out, key=lambda b: -b.slack_m)


@dataclass(frozen=True)
class ClosingTogether:
    """A locator whose gap closes together with a target's while the kept contacts touch.

    At the goal the target's normal row ``G_t`` is ``Σ a_i G_i + c G_o`` over the kept rows and
    the other locator's row with ``c > 0`` (and not in the kept rows' span alone): every motion
    that keeps the kept contacts changes the target's gap ``c`` times as much as the other's, so
    both reach 0 together. ``rank`` is the rank of every locator's normal rows at the goal.
    """

    locator: str
    ratio: float
    rank: int


@dataclass(frozen=True)
class GoalRows:
    """Every locator's normal row at one pose (the goal) and their rank: the rank test's input.

    Built once per fixture (:func:`goal_rows`) so that the coarse search can ask
    :func:`closing_group` of every transition of its lattice without a contact set each time.
    """

    names: tuple[str, ...]
    G: FloatArray
    rank: int

    def row(self, name: str) -> FloatArray:
        return self.G[self.names.index(name)]


def goal_rows(fixture: Fixture, pose: Pose | None = None) -> GoalRows | None:
    """The normal rows of every locator at ``pose`` (default: the goal; None without a goal)."""
    if pose is None:
        if not fixture.is_full:
            return None
        try:
            pose = fixture.goal
        except Exception:  # noqa: BLE001 - no goal, nothing to compare
            return None
    names = tuple(loc.name for loc in fixture.locators)
    G = np.asarray(contact_set(fixture, pose, list(names)).nearest_only().G, dtype=float)  # a row per locator
    tol = DEFAULT.planner.span_rel
    rank = int(np.linalg.matrix_rank(G, tol=tol * max(float(np.abs(G).max()), 1.0)))
    return GoalRows(names, G, rank)


def closing_together(
    fixture: Fixture,
    established: Sequence[str],
    target: str,
    pose: Pose | None = None,
    rows: GoalRows | None = None,
) -> list[ClosingTogether]:
    """The locators that close together with ``target`` while ``established`` stay touching.

    Evaluated at ``pose`` (default: the goal; [] when the fixture has no goal), or on ``rows``
    from :func:`goal_rows`. A redundant layout (two side locators that always close together,
    base locators placed so that closing one closes another) has every locator's normal rows of
    rank below the locator count there; the coarse search plans such a group as one transition
    (:func:`closing_group`).
    """
    if rows is None:
        rows = goal_rows(fixture, pose)
        if rows is None:
            return []
    tol = DEFAULT.planner.span_rel
    t = rows.row(target)
    kept = np.array([rows.row(n) for n in established]).reshape(len(established), fixture.ndof)

    def residual(A: FloatArray) -> tuple[float, FloatArray]:
        if A.shape[0] == 0:
            return float(np.linalg.norm(t)), np.zeros(0)
        coef = np.asarray(np.linalg.lstsq(A.T, t, rcond=None)[0], dtype=float)
        return float(np.linalg.norm(A.T @ coef - t)), coef

    scale = float(np.linalg.norm(t)) or 1.0
    if residual(kept)[0] <= tol * scale:
        return []  # the target's gap cannot change at all while the kept ones touch: another cause
    out = []
    for n in rows.names:
        if n in established or n == target:
            continue
        r, coef = residual(np.vstack([kept, rows.row(n)[None, :]]))
        if r <= tol * scale and coef[-1] > 0:
            out.append(ClosingTogether(n, float(coef[-1]), rows.rank))
    return out


def dependent_kept(fixture: Fixture, established: Sequence[str], rows: GoalRows | None = None) -> tuple[str, ...]:
    """The kept locators whose normal row at the goal is a combination of the earlier kept ones'.

    After a group that closed together (E1 and E2 with the base seated) both stay touching, and
    the second's gap follows from the others': asking it to stay 0 too repeats a constraint.
    """
    if len(established) < 2:
        return ()
    if rows is None:
        rows = goal_rows(fixture)
        if rows is None:
            return ()
    tol = DEFAULT.planner.span_rel
    basis: list[FloatArray] = []
    out = []
    for n in established:
        r = rows.row(n)
        if basis:
            A = np.array(basis)
            coef = np.linalg.lstsq(A.T, r, rcond=None)[0]
            if float(np.linalg.norm(A.T @ coef - r)) <= tol * (float(np.linalg.norm(r)) or 1.0):
                out.append(n)
                continue
        basis.append(r)
    return tuple(out)


def closing_group(
    fixture: Fixture, established: Sequence[str], target: str, rows: GoalRows | None = None
) -> tuple[str, ...]:
    """``target`` and every locator that geometry makes touch at the same instant (sorted).

    The closure of :func:`closing_together` from ``established``: ``(target,)`` alone in a layout
    whose normal rows are independent; ``("E1", "E2")`` for two end locators that any motion
    keeping the base seated moves alike. The coarse search adds such a group in one transition.
    """
    group = {target}
    todo = [target]
    while todo:
        for c in closing_together(fixture, established, todo.pop(), rows=rows):
            if c.locator not in group:
                group.add(c.locator)
                todo.append(c.locator)
    return tuple(sorted(group))


# ---------------------------------------------------------------------------------------------
# Initial guesses
# ---------------------------------------------------------------------------------------------


def _step_rows(fixture: Fixture, pose: Pose, est: tuple[str, ...], target: str, kind: str) -> tuple[Any, FloatArray]:
    """(contact set, rows A) of the linearised step: the kept contacts' rows, then the target's normal."""
    cs = contact_set(fixture, pose, [*est, target]).nearest_of(target)  # kept contacts, then the target's nearest
    if kind == "roll":
        n_rows = sum(c.size for c in cs.contacts[:-1])
        A = np.vstack([cs.J[:n_rows], cs.G[-1:]])
    else:
        A = cs.G[: len(cs)]
    return cs, A


def _least_step(cs: Any, A: FloatArray, gap_m: float) -> FloatArray:
    """The least-``M``-norm twist with ``A ξ = (0, …, 0, −gap)``."""
    b = np.zeros(A.shape[0])
    b[-1] = -gap_m
    Minv = cs.M_inv
    return Minv @ A.T @ np.linalg.pinv(A @ Minv @ A.T, rcond=DEFAULT.numerics.rcond) @ b


def _linearised_guess(prob: _Problem, kind: str) -> FloatArray:
    """The linearised gap-closing step, as a straight line of K segments."""
    gap_t = prob.start_gaps[prob.target]
    cs, A = _step_rows(prob.fixture, prob.start, prob.est, prob.target, kind)
    end = _least_step(cs, A, gap_t)
    return np.outer(end, np.linspace(0.0, 1.0, prob.K + 1))


def _compliant_guess(prob: _Problem, kind: str) -> FloatArray:
    """Short linearised steps toward the target, each settled back onto the kept contacts.

    The path follows the kept contacts' manifold (a pivot about a kept point, a turn about the
    axis through two, a slide along a kept face), where a straight line in twist coordinates cuts
    through them. Resampled by length to ``K + 1`` knots.
    """
    fx, start, est, target = prob.fixture, prob.start, prob.est, prob.target
    wp = fx.workpiece
    tol_touch = fx.tolerances.touch_m
    kept = [fx.locator(n) for n in est]
    loc_t = fx.locator(target)
    step_max = prob.settings.compliant_step_rel * prob.L
    pose = start
    g_t = prob.start_gaps[target]
    poses = [start]
    for _ in range(prob.settings.compliant_max_steps):
        if g_t <= tol_touch:
            break
        cs, A = _step_rows(fx, pose, est, target, kind)
        xi = _least_step(cs, A, g_t)
        size = float(np.sqrt(max(float(xi @ cs.mass_matrix @ xi), 0.0) / wp.mass_kg))
        if not np.isfinite(size) or size <= 0.0:
            break
        if size > step_max:
            xi = xi * (step_max / size)
        new = pose.retract(xi, prob.com_b)
        if kept:
            settled = solve_goal(wp, kept, new, tol_m=prob.settings.settle_tol_m)
            if not settled.converged:
                break
            new = settled.pose
        g_new = float(locator_contact(wp, new, loc_t).gap_m)
        if not g_new < g_t:
            break  # no progress: the kept contacts stop the target here
        poses.append(new)
        pose, g_t = new, g_new
    xs = np.array([twist_from_pose(start, p, prob.com_b) for p in poses]).T
    if xs.shape[1] < 2:
        return np.zeros((fx.ndof, prob.K + 1))
    steps = np.sqrt(np.maximum(np.einsum("ik,ij,jk->k", np.diff(xs, axis=1), prob.M0, np.diff(xs, axis=1)), 0.0))
    s = np.concatenate([[0.0], np.cumsum(steps)])
    s = s / s[-1] if s[-1] > 0 else np.linspace(0.0, 1.0, len(s))
    s_new = np.linspace(0.0, 1.0, prob.K + 1)
    return np.array([np.interp(s_new, s, row) for row in xs])


def _state(est: tuple[str, ...]) -> str:
    return "{" + ", ".join(est) + "}" if est else "free"


def _added(target: str, together: Sequence[str] = ()) -> str:
    """``E1``, or ``{E1, E2}`` for a group closing together."""
    return "{" + ", ".join((target, *together)) + "}" if together else target


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
) -> list[tuple[str, Any]]:
    """First-order no-slip rows of segment k (each with its locator): ``t·(R_kᵀ Δ(material point)) = 0`` (body frame).

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
            out.append((n, ca.dot(t, disp)))
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
            out.append((n, ca.dot(t1, disp)))
        out.append((n, ca.dot(t2, disp)))
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
    same_pose_m: float,
) -> tuple[FloatArray, str]:
    """Twists ξ_0..ξ_K (ndof × K+1) to start IPOPT from, and a note of where they came from.

    A warm start is resampled when it starts within ``same_pose_m`` (and as many radians) of ``start``.
    """
    wp = fixture.workpiece
    if warm is not None and len(warm.poses) >= 2:
        dp, ang = warm.poses[0].distance_to(start)
        if dp <= same_pose_m and ang <= same_pose_m:
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
    cs = contact_set(fixture, start, [*est, target]).nearest_of(target)  # kept contacts, then the target's nearest
    rows = cs.J if kind == "roll" else cs.G
    n_rows_est = sum(c.size for c in cs.contacts[:-1]) if kind == "roll" else len(cs) - 1
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
    monotone: bool = True,
    together: Sequence[str] = (),
) -> float:
    """Largest violation of the plan's constraints with the exact gaps [m] (knots 1..K).

    The locators closing together with the target must not penetrate, and touch at the last knot.
    """
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
        worst = max(worst, -g[target], g[target] - prev_t if monotone else 0.0)
        for n in together:
            worst = max(worst, -g[n])
        prev_t = g[target]
        if k == K:
            worst = max(worst, abs(g[target]), *(abs(g[n]) for n in together))
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
    "CONSTRAINT_KINDS",
    "LADDER",
    "Blocker",
    "ClosingTogether",
    "Formulation",
    "GoalRows",
    "Transition",
    "blocking_constraints",
    "closing_group",
    "closing_together",
    "default_kind",
    "dependent_kept",
    "goal_rows",
    "plan_transition",
    "pose_from_twist",
    "twist_from_pose",
]
