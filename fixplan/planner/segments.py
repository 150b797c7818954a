"""The applied wrench of each segment of a planned path (the fine planner's second half).

Wrenches
--------
Each segment ``k → k+1`` is pushed from rest at knot ``k`` (quasi-static loading): its desired
acceleration is the direction of the finite-difference twist of the body origin
``(p_{k+1} − p_k, log(R_{k+1} R_kᵀ))``, projected (in the ``M``-metric) onto the motions that
keep the established contacts exactly at knot ``k`` (normal rows for sliding, all rows for
rolling), scaled to ``acceleration_mps2``, and given as the acceleration of the centre of mass,
with the contact set of the established contacts at the knot (built once per segment), to
:func:`~fixplan.jamming.search.search_wrench_in`. A segment whose search fails makes the
transition fail with its reason. With no established contact (free motion) the wrench is
``M a − w_g``, checked against the limits.

With a ``[robot]`` every segment's push must also be one the arm can exert at both of its knots:
the arm's joint-torque boxes there (:func:`fixplan.robot.exertable.knot_boxes`, the joints by
inverse kinematics along the transition) go to the search as ``hand_sets``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from fixplan.errors import InputError
from fixplan.locating import contact_set
from fixplan.settings import DEFAULT, PlannerSettings, Settings
from fixplan.spatial import Pose, log_so3, shift_twist

if TYPE_CHECKING:
    from fixplan.kinematics import ContactSet
    from fixplan.model import Fixture

FloatArray = NDArray[np.float64]


def segment_wrenches(
    fixture: Fixture,
    poses: list[Pose],
    est: tuple[str, ...],
    kind: str,
    acceleration_mps2: float,
    *,
    friction_margin: float = 0.0,
    margin_N: float | None = None,
    needs: list[tuple[float | None, float | None]] | None = None,
    settings: Settings = DEFAULT,
) -> tuple[FloatArray, FloatArray, NDArray[np.bool_], list[str]]:
    """The non-jamming wrench search for every segment (see the module docstring).

    Every search runs with ``settings`` (its ``search``, ``witness`` and ``numerics`` groups): the
    caller's profile (:class:`~fixplan.planner.solve.Planner` passes its own).

    ``needs``, when given, is filled with one ``(force [N], torque [N·m])`` per segment: the least
    a push needs where the hand is too weak (:attr:`WrenchSearch.needed_force_N`, ``None`` where
    that limit does not bind or the segment has a push), for the planner's reasons.
    """
    from fixplan.jamming.push import free_wrench
    from fixplan.jamming.search import search_wrench_in

    wp = fixture.workpiece
    d, nv, K = fixture.dimension, fixture.ndof, len(poses) - 1
    wrenches = np.full((K, nv), np.nan)
    margins = np.full(K, np.nan)
    found = np.zeros(K, dtype=bool)
    reasons: list[str] = []
    need: list[tuple[float | None, float | None]] = []
    arm_boxes: list = [None] * len(poses)
    if fixture.robot is not None and d == 3:
        from fixplan.robot.exertable import knot_boxes

        arm_boxes = list(knot_boxes(fixture, poses))
    for k in range(K):
        need.append((None, None))
        a, b = poses[k], poses[k + 1]
        cs = contact_set(fixture, a, list(est))
        if d == 3:
            w = log_so3(b.R_world_body @ a.R_world_body.T)
        else:
            w = np.array([(b.angle_rad - a.angle_rad + np.pi) % (2 * np.pi) - np.pi])
        nu_origin = np.concatenate([b.p_world - a.p_world, w])  # displacement twist of the body origin
        nu = shift_twist(nu_origin, a.p_world, cs.com_world)  # ... and of the centre of mass
        M = cs.mass_matrix
        Minv = cs.M_inv
        if len(est):
            A = cs.J if kind == "roll" else cs.G
            nu = nu - Minv @ A.T @ np.linalg.pinv(A @ Minv @ A.T, rcond=settings.numerics.rcond) @ (A @ nu)
        size = float(np.sqrt(max(float(nu @ M @ nu), 0.0) / wp.mass_kg))
        if size <= 1e-15:
            reasons.append("the segment does not move")
            continue
        a_com = nu * (acceleration_mps2 / size)
        boxes = tuple(b for b in (arm_boxes[k], arm_boxes[k + 1]) if b is not None)
        if not est:
            ok, wr, why = free_wrench(fixture, a, a_com, M, boxes)
            found[k], reasons = ok, [*reasons, why]
            wrenches[k] = wr
            if not ok:  # the push is determined: it is the least needed (with the other limit kept, if it is)
                F, T = float(np.linalg.norm(wr[:d])), float(np.linalg.norm(wr[d:]))
                F_max, T_max = fixture.manipulator.max_force_N, fixture.manipulator.max_torque_Nm
                need[k] = (F if T <= T_max else None, T if F <= F_max else None)
            continue
        try:
            # the contact set and the motion of the centre of mass as they are (built once)
            res = search_wrench_in(
                cs,
                a_com,
                fixture,
                objective="effort",
                min_margin_N=margin_N,
                friction_margin=friction_margin,
                hand_sets=boxes,
                settings=settings,
            )
        except InputError as exc:
            reasons.append(str(exc))
            continue
        found[k] = res.found
        reasons.append(res.reason)
        need[k] = (res.needed_force_N, res.needed_torque_Nm)
        if res.found and res.wrench is not None:
            wrenches[k] = res.wrench
            margins[k] = res.margin_N
    if needs is not None:
        needs.extend(need)
    return wrenches, margins, found, reasons


def needed_scale(need: tuple[float | None, float | None], F_max: float, T_max: float) -> float | None:
    """The least factor one of the hand's limits must grow by for a push to exist (None: not too weak).

    ``need`` is ``(least force with the torque within T_max, least torque with the force within
    F_max)`` (:func:`~fixplan.jamming.search.search_wrench`'s ``needed_force_N``,
    ``needed_torque_Nm``): raising ``max_force`` to the first, or ``max_torque`` to the second,
    is enough; the smaller ratio is the transition's demand.
    """
    F_need, T_need = need
    ratios = [x / lim for x, lim in ((F_need, F_max), (T_need, T_max)) if x is not None and x > lim]
    return min(ratios) if ratios else None


def carried_fraction(
    fixture: Fixture, pose: Pose, names: tuple[str, ...] | list[str], cs: ContactSet | None = None
) -> float:
    """The share of the weight the kept contacts' normals cannot carry at ``pose``: what the hand must.

    The least ``‖−m g − Σ f_i n_i‖`` over normal forces ``f ≥ 0``, over ``m|g|``: 0 when the part
    rests on something below it (one base contact will do: the hand may balance the moment, its
    force still goes into the push), 1 in free space or against walls only (the hand, or the
    friction its pressing raises, carries it all), ``sin θ`` on one contact whose normal is ``θ``
    off the vertical. 0 without gravity. ``cs``: a contact set at ``pose`` whose first contacts
    are ``names`` (reused, not rebuilt).
    """
    from fixplan.nnls import nnls

    d = fixture.dimension
    b = -np.asarray(fixture.gravity_wrench()[:d], dtype=float)
    weight = float(np.linalg.norm(b))
    if weight == 0.0:
        return 0.0
    if not names:
        return 1.0
    if cs is None:
        cs = contact_set(fixture, pose, list(names))
    rows = cs.rows_of(names) if cs.several else np.arange(len(names))  # every contact of the kept locators
    A = cs.G[rows, :d].T  # the unit normal forces, one column per kept contact
    f, _ = nnls(A, b)
    return min(1.0, float(np.linalg.norm(b - A @ f)) / weight)


def carry_factor(
    fixture: Fixture,
    pose: Pose,
    names: tuple[str, ...] | list[str],
    cs: ContactSet | None = None,
    settings: PlannerSettings = DEFAULT.planner,
) -> float:
    """A transition's cost factor: ``1 + carry_cost × carried_fraction`` (``settings.carry_cost``).

    A move with the weight on the locators asks the hand only for the push; a move in the air or
    along walls asks it to carry the part as well (or leans on friction to), leaving less of its
    force for pressing the kept contacts. Pricing the carried
    share makes the coarse search seat the part on what holds its weight first where the paths
    are otherwise alike (a thin box hung on its end and side locators and slid down them lost
    its walls and fell).
    """
    return 1.0 + settings.carry_cost * carried_fraction(fixture, pose, names, cs)


__all__ = ["carried_fraction", "carry_factor", "needed_scale", "segment_wrenches"]
