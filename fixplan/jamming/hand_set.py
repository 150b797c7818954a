"""The pushes an arm can exert at one pose, as linear inequalities the wrench search accepts.

An arm at ``q`` holding the part pushes it with the wrench ``w = (f, m)`` (at the tool frame's
origin ``p``, world axes) by the joint torques ``τ = τ_g(q) + J(q)ᵀ w`` (``τ_g``: what holds its
own weight, ``J``: the tool's Jacobian at ``p`` in world axes; :meth:`fixplan.robot.Arm.torques`).
Every joint must stay within its effort limit, ``|τ_g,i + J_iᵀ w| ≤ τ_max,i``: a box in torque
space pulled back through ``Jᵀ``, which is ``2 nq`` linear inequalities in ``w``. The set is the
arm's zonotope of wrenches (shifted by its weight) where ``Jᵀ`` is onto, and a slab where it is
not; either way a cone program takes it directly as a non-negative cone, with no inscribed ball
in between. :class:`TorqueBox` holds one pose's; :func:`torque_rows` writes several (a segment's
two knots) as ``A w ≤ b`` for a wrench about any point.

Headroom: at a fraction ``s`` of the limits the joints keep ``|τ_i| ≤ s τ_max,i`` (the torques the
joints carry, the arm's weight included, not the push scaled), as the search's ``limit_fraction``
does for the hand's force and torque.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fixplan.spatial import shift_wrench, skew

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class TorqueBox:
    """One pose of the arm: the wrenches ``w`` at ``point_world`` with ``|bias_Nm + jacobian_T w| ≤ limit_Nm``.

    Attributes
    ----------
    jacobian_T : (nq, 6) array
        ``J(q)ᵀ``: joint ``i``'s torque per unit wrench at ``point_world`` (world axes) [m or 1].
    bias_Nm : (nq,) array
        The torques that hold the arm's own weight at ``q`` [N·m].
    limit_Nm : (nq,) array
        The joints' effort limits [N·m].
    point_world : (3,) array
        The tool frame's origin, the point the wrench is taken about [m].
    joints : tuple of str
        The joints' names, for the reasons.
    label : str
        Where the arm is (``"knot 3"``), for the reasons.
    """

    jacobian_T: FloatArray
    bias_Nm: FloatArray
    limit_Nm: FloatArray
    point_world: FloatArray
    joints: tuple[str, ...]
    label: str = ""

    def torques(self, wrench: ArrayLike, about_world: ArrayLike) -> FloatArray:
        """``τ_g + Jᵀ w`` for the wrench ``w`` given about ``about_world`` [N·m]."""
        w_tool = shift_wrench(np.asarray(wrench, dtype=float), about_world, self.point_world)
        return np.asarray(self.bias_Nm + self.jacobian_T @ w_tool, dtype=float)

    def ratios(self, wrench: ArrayLike, about_world: ArrayLike) -> FloatArray:
        """``|τ_i| / τ_max,i`` per joint for that wrench (inf where a joint has no effort at all)."""
        tau = np.abs(self.torques(wrench, about_world))
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(self.limit_Nm > 0.0, tau / self.limit_Nm, np.where(tau > 0.0, np.inf, 0.0))

    def rows(self, about_world: ArrayLike, fraction: float = 1.0) -> tuple[FloatArray, FloatArray]:
        """``(A, b)``: the box as ``A w ≤ b`` for ``w`` about ``about_world``, within ``fraction`` of the limits.

        ``w_tool = S w`` with ``S = [[I, 0], [[c − p]×, I]]`` (``c`` = ``about_world``, ``p`` =
        ``point_world``: :func:`fixplan.spatial.shift_wrench`), so ``A = [JᵀS; −JᵀS]`` and
        ``b = [s τ_max − τ_g; s τ_max + τ_g]``. Joints the push does not load (a zero row of
        ``JᵀS``, a finger) are left out when their weight alone is within the limit.
        """
        c = np.asarray(about_world, dtype=float)
        S = np.eye(6)
        S[3:, :3] = skew(c - self.point_world)
        JS = self.jacobian_T @ S
        lim = fraction * self.limit_Nm
        A = np.vstack([JS, -JS])
        b = np.concatenate([lim - self.bias_Nm, lim + self.bias_Nm])
        keep = (np.abs(A).max(axis=1) > 0.0) | (b < 0.0)
        return A[keep], b[keep]


def torque_rows(
    boxes: Sequence[TorqueBox], about_world: ArrayLike, fraction: float = 1.0
) -> tuple[FloatArray, FloatArray]:
    """Every box's rows (:meth:`TorqueBox.rows`) stacked: the wrenches all of them allow, ``A w ≤ b``."""
    if not boxes:
        return np.zeros((0, 6)), np.zeros(0)
    parts = [box.rows(about_world, fraction) for box in boxes]
    return np.vstack([A for A, _ in parts]), np.concatenate([b for _, b in parts])


def worst_joint(boxes: Sequence[TorqueBox], wrench: ArrayLike, about_world: ArrayLike) -> tuple[float, str, str]:
    """``(ratio, joint, label)``: the most loaded joint over ``boxes`` for that wrench (``|τ| / τ_max``)."""
    best = (0.0, "", "")
    for box in boxes:
        r = box.ratios(wrench, about_world)
        if r.size and float(np.max(r)) >= best[0]:
            i = int(np.argmax(r))
            best = (float(r[i]), box.joints[i], box.label)
    return best


__all__ = ["TorqueBox", "torque_rows", "worst_joint"]
