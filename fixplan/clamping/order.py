"""The clamping order: one in which every prefix of clamps holds the part under gravity, without the hand.

A prefix holds when gravity and its clamps, each at its final force, are balanced by the
locators' forces in their exact friction cones: the jamming classifier's ``held`` or ``jammed``
(:class:`fixplan.jamming.Classifier`, the cone programs of :mod:`fixplan.jamming.programs`).
Ramping the last clamp of a prefix from 0 to its force passes only through balanced states:
the wrenches that locator forces in the cones balance form a convex cone, and both ends lie in it.

Whether a prefix holds depends on its *set* of clamps, not on their order, so the search walks
subsets (depth first, clamps in file order, each set tried once: 2ⁿ programs at most instead of
n! orders) and skips a clamp whose wrench equals an earlier untried one's (symmetric clamps are
interchangeable). A failing prefix is explained from the motion the classifier finds: the
locators it lifts and, when the part turns, the tipping moment of the clamps about the axis
against the weight's (``"K3 alone lifts A3: tipping moment 14 N·m about B1–B2 against 0.6 N·m of
weight"``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fixplan.clamping.forces import ClampScene
from fixplan.jamming import Classification, Classifier
from fixplan.settings import DEFAULT, Settings
from fixplan.spatial import cross2

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class PrefixCheck:
    """Whether the clamps ``clamps`` (at their forces) and gravity hold the part, and why not."""

    clamps: tuple[str, ...]
    holds: bool
    mode: str  # the classifier's mode (held, jammed, separates, slides, pivots, ...)
    balance_residual: float  # the classifier's [N/√kg]
    reason: str  # "" when it holds


class OrderSearch:
    """Checks prefixes (memoised by their set of clamps) and searches an order."""

    def __init__(self, scene: ClampScene, forces_N: dict[str, float], settings: Settings = DEFAULT):
        self.scene = scene
        self.forces_N = dict(forces_N)
        self.settings = settings
        self.classifier = Classifier(scene.cs, scene.gravity_com, tolerances=settings.tolerances)
        self._memo: dict[frozenset[str], PrefixCheck] = {}
        self.programs = 0  # classifications run

    def check(self, clamps: Sequence[str]) -> PrefixCheck:
        """The prefix ``clamps`` (its set: the order within does not matter) under gravity, without the hand."""
        key = frozenset(clamps)
        found = self._memo.get(key)
        if found is None:
            w = self.scene.clamp_wrench({k: self.forces_N[k] for k in key})
            c = self.classifier.classify(w)
            self.programs += 1
            holds = c.mode in ("held", "jammed")
            found = PrefixCheck(
                tuple(clamps), holds, c.mode, c.balance_residual, "" if holds else self.explain(tuple(clamps), c, w)
            )
            self._memo[key] = found
        return found

    def check_order(self, order: Sequence[str]) -> PrefixCheck | None:
        """The first prefix of ``order`` that does not hold, or None when every one does."""
        for i in range(1, len(order) + 1):
            p = self.check(order[:i])
            if not p.holds:
                return PrefixCheck(tuple(order[:i]), False, p.mode, p.balance_residual, p.reason)
        return None

    def search(self) -> tuple[tuple[str, ...] | None, PrefixCheck | None]:
        """An order whose prefixes all hold (file order preferred), or None and the deepest prefix's failure."""
        names = self.scene.names
        keys = {k: tuple(np.round(self.forces_N[k] * self.scene.clamp(k).wrench_per_N, 9)) for k in names}
        dead: set[frozenset[str]] = set()
        deepest: list[PrefixCheck | None] = [None]
        depth = [-1]

        def walk(done: tuple[str, ...]) -> tuple[str, ...] | None:
            if len(done) == len(names):
                return done
            if frozenset(done) in dead:
                return None
            tried: set[tuple] = set()
            for k in names:
                if k in done or keys[k] in tried:
                    continue
                tried.add(keys[k])
                p = self.check((*done, k))
                if not p.holds:
                    if len(done) > depth[0]:
                        depth[0] = len(done)
                        deepest[0] = PrefixCheck((*done, k), False, p.mode, p.balance_residual, p.reason)
                    continue
                found = walk((*done, k))
                if found is not None:
                    return found
            dead.add(frozenset(done))
            return None

        order = walk(())
        return order, (None if order is not None else deepest[0])

    # -- why a prefix fails --------------------------------------------------------------------
    def explain(self, clamps: tuple[str, ...], c: Classification, w_clamps: FloatArray) -> str:
        """One line: which locators the clamps lift and the tipping moment against the weight's."""
        scene, st = self.scene, self.settings.clamp
        who = f"{clamps[0]} alone" if len(clamps) == 1 else " + ".join(clamps)
        a = c.acceleration if c.acceleration is not None else self._least_acceleration(w_clamps)
        cs, d = scene.cs, scene.cs.dimension
        opening = cs.G @ a
        top = float(np.max(np.abs(opening), initial=0.0))
        lifted = [cs.contacts[i].owner for i in range(len(cs)) if opening[i] > st.lift_rel * top]
        lifted = list(dict.fromkeys(lifted))
        v, w = a[:d], a[d:]
        size = max(cs.max_lever_m, 1e-300)
        spin = float(np.linalg.norm(w))
        if top == 0.0 and spin == 0.0:
            return f"{who} does not hold: the part {c.mode} ({c.reason})"
        if spin * size > st.spin_rel * float(np.linalg.norm(v)):
            # the instantaneous axis (3D: a line along ω through q; 2D: the point q)
            com = cs.com_world
            if d == 3:
                u = w / spin
                q = com + np.cross(w, v) / spin**2
            else:
                u = np.array([np.sign(w[0])])
                q = com + np.array([-v[1], v[0]]) / w[0]
            on_axis: list[str] = []
            for contact in cs.contacts:
                r = contact.point_world - q
                off = float(np.linalg.norm(np.cross(r, u))) if d == 3 else float(np.linalg.norm(r))
                if off <= st.axis_rel * size and contact.owner not in on_axis:
                    on_axis.append(contact.owner)
            lifted = [name for name in lifted if name not in on_axis]
            verb = f"lifts {', '.join(lifted)}" if lifted else f"turns the part ({c.mode})"
            where = "–".join(on_axis) if on_axis else "an axis through (" + ", ".join(f"{x:.3g}" for x in q) + ") m"
            if on_axis:  # the moments about the axis through the named locators' points (hand-checkable)
                points = [next(x.point_world for x in cs.contacts if x.owner == name) for name in on_axis]
                q = points[0]
                if d == 3 and len(points) > 1 and np.linalg.norm(points[-1] - points[0]) > 0.0:
                    e = (points[-1] - points[0]) / np.linalg.norm(points[-1] - points[0])
                    u = e if float(e @ u) >= 0.0 else -e
            tip = _moment_about(w_clamps, com, q, u)
            weight = -_moment_about(scene.gravity_com, com, q, u)
            against = (
                f"against {weight:.3g} N·m of weight"
                if weight >= 0.0
                else f"with {-weight:.3g} N·m of weight adding to it"
            )
            return f"{who} {verb}: tipping moment {tip:.3g} N·m about {where} {against}"
        verb = f"lifts {', '.join(lifted)}" if lifted else f"moves the part ({c.mode})"
        unit = v / max(float(np.linalg.norm(v)), 1e-300)
        push = float(w_clamps[:d] @ unit)
        along = "(" + ", ".join(f"{x:.2g}" for x in unit) + ")"
        return f"{who} {verb}: the part {c.mode} along {along} under {push:.3g} N of clamping along the motion"

    def _least_acceleration(self, w_clamps: FloatArray) -> FloatArray:
        """``M⁻¹ (w + Jᵀλ)`` at the least ``M⁻¹``-weighted static-balance residual (the motion nothing balances)."""
        from fixplan.jamming.backends import ClarabelProgram
        from fixplan.jamming.programs import ProgramBuilder, into_cones

        cs = self.scene.cs
        b = ProgramBuilder(cs)
        P = np.eye(cs.ndof)
        program = b.residual_program("balance", P)
        w = w_clamps + self.scene.gravity_com
        sol = ClarabelProgram(program, eps=self.settings.tolerances.cone_eps).solve(b.rhs(program, P, w))
        lam = into_cones(cs, b.layout.S @ sol.x[: program.nf])
        return np.asarray(cs.M_inv @ (w + cs.J.T @ lam), dtype=float)


def _moment_about(w_com: FloatArray, com: FloatArray, q: FloatArray, u: FloatArray) -> float:
    """The moment of a wrench given about ``com`` about the axis through ``q`` along ``u`` (2D: the point ``q``, sign ``u``)."""
    d = len(com)
    f, m = w_com[:d], w_com[d:]
    if d == 3:
        return float(u @ (m + np.cross(com - q, f)))
    return float(u[0] * (m[0] + cross2(com - q, f)))
