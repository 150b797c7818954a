"""The push along one step of a path, asked as one question: at this pose, on these contacts, with this hand.

:func:`push_at` takes the contacts of the names given that touch at the pose. On them it is the
non-jamming search (:func:`~fixplan.jamming.search.search_wrench_in`, the least-effort push that
presses them by the margin asked for, confirmed by the classifier) with their wedging force
(:func:`~fixplan.jamming.wedge.wedge_force`: forces that balance with no push, whatever the push).
With none touching the part flies free: the push is determined, ``M a − w_g``
(:func:`free_wrench`), and only checked against the hand's limits and the arm's joints.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from fixplan.jamming.hand_set import TorqueBox, worst_joint
from fixplan.jamming.search import search_wrench_in, too_weak_reason
from fixplan.jamming.wedge import wedge_force
from fixplan.locating import contact_set
from fixplan.settings import DEFAULT, Settings
from fixplan.spatial import shift_wrench

if TYPE_CHECKING:
    from fixplan.model import Fixture
    from fixplan.spatial import Pose

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Push:
    """A step's push, or why there is none, with what it was found on."""

    found: bool
    wrench: FloatArray  # about the body origin, world axes; NaN where none was found
    reason: str
    contacts: tuple[str, ...]  # the touching contacts it was searched on; none: free motion
    wedge_force: float | None = None  # their wedging force (of 1); None: fewer than two contacts
    margin_N: float | None = None  # the least normal force on the kept contacts; None: none kept


def push_at(
    fixture: Fixture,
    pose: Pose,
    names: Sequence[str],
    a_com: FloatArray,
    *,
    min_margin_N: float | None = None,
    settings: Settings = DEFAULT,
) -> Push:
    """The push giving the part the acceleration ``a_com`` (of its centre of mass) at ``pose``, on the contacts of ``names`` that touch there (module text).

    ``min_margin_N``: the normal force the search presses the kept contacts by, where it can;
    ``settings``: the search's thresholds (:func:`~fixplan.jamming.search.search_wrench_in`).
    """
    cs = contact_set(fixture, pose, list(names)).touching(fixture.tolerances.touch_m)
    if len(cs):
        r = search_wrench_in(
            cs, a_com, fixture, objective="effort", min_margin_N=min_margin_N, confirm=True, settings=settings
        )
        wrench = r.wrench if r.wrench is not None else np.full(fixture.ndof, np.nan)
        wedge = wedge_force(cs) if len(cs) >= 2 else None
        return Push(r.found, wrench, r.reason, tuple(cs.names), wedge, r.margin_N)
    found, wrench, reason = free_wrench(fixture, pose, a_com, cs.mass_matrix)
    return Push(found, wrench, reason, ())


def free_wrench(
    fixture: Fixture, pose: Pose, a_com: FloatArray, M: FloatArray, boxes: Sequence[TorqueBox] = ()
) -> tuple[bool, FloatArray, str]:
    """Free flight: ``w = M a − w_g`` about the centre of mass, reported about the body origin.

    ``boxes``: the arm's joint-torque boxes the push must also lie in (the most loaded joint is named).
    """
    d = fixture.dimension
    w_c = M @ a_com - fixture.gravity_wrench()
    w_o = shift_wrench(w_c, pose.point_world_from_body(fixture.workpiece.com_body), pose.p_world)
    T = float(np.linalg.norm(w_o[3:])) if d == 3 else abs(float(w_o[2]))
    F = float(np.linalg.norm(w_o[:d]))
    F_max, T_max = fixture.manipulator.max_force_N, fixture.manipulator.max_torque_Nm
    if F > F_max or T > T_max:
        # the push is determined (no contact force): its force and torque are the least needed
        reason, _ = too_weak_reason(F, F, T, T, F_max, T_max)
        return False, w_o, reason + " (free motion: the push is M a − w_g)"
    if boxes:
        ratio, joint, label = worst_joint(boxes, w_o, pose.p_world)
        if ratio > 1.0:
            return (
                False,
                w_o,
                (
                    f"the arm cannot exert the push M a − w_g: joint {joint} needs {ratio:.3g} times its effort limit at "
                    f"{label} (free motion)"
                ),
            )
    return True, w_o, f"free motion: ‖F‖ = {F:.3g} N, ‖T‖ = {T:.3g} N·m"


__all__ = ["Push", "free_wrench", "push_at"]
