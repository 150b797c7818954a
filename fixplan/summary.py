"""What a loaded fixture is: its kind, each locator's gap at the start, the goal, and whether the locators determine the pose.

``fixplan validate`` prints :func:`summarize`'s answer (``--verbose``: its details);
``fixplan solve`` warns with :func:`goal_rank` when the locators leave the pose free.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from fixplan.errors import Issue
from fixplan.geometry import Mesh
from fixplan.settings import DEFAULT

if TYPE_CHECKING:
    from fixplan.model import Fixture
    from fixplan.spatial import Pose


def goal_rank(fixture: Fixture) -> int:
    """The rank of ``G`` (the locators' contact normals as wrenches) at the goal, every locator touching.

    The locators determine the pose when it is ``fixture.ndof``; below, the part can move while
    touching every locator.
    """
    from fixplan.locating import contact_set

    cs = contact_set(fixture, "goal", [loc.name for loc in fixture.locators])
    return int(np.linalg.matrix_rank(cs.G, tol=DEFAULT.numerics.rank_tol))


def locating_sensitivity(fixture: Fixture, error_m: float) -> tuple[str, float, float, float]:
    """How far one locator's error moves the located pose: the worst locator, by the part's farthest point.

    A locator tip ``error_m`` off along its contact normal changes the located pose by the twist
    ``δξ`` with ``G_nᵀ δξ = error_m e_i`` (``G_n``: the locators' normal rows ``[n; r × n]`` at the
    goal, about the centre of mass; least squares beyond 6). Returns ``(locator, centre-of-mass
    shift [m], turn [rad], largest shift of a point of the part [m])`` for the locator whose error
    moves a point of the part (within its bounding radius) the most.
    """
    from fixplan.locating import locator_contact

    wp, goal = fixture.workpiece, fixture.goal
    d = fixture.dimension
    c = goal.point_world_from_body(wp.com_body)
    rows = []
    for loc in fixture.locators:
        ct = locator_contact(wp, goal, loc)
        n, r = np.asarray(ct.normal_world), np.asarray(ct.point_world) - c
        moment = np.cross(r, n) if d == 3 else np.array([r[0] * n[1] - r[1] * n[0]])
        rows.append(np.concatenate([n, moment]))
    A = np.array(rows)
    R = wp.shape.bounding_radius
    worst = ("", 0.0, 0.0, -1.0)
    for i, loc in enumerate(fixture.locators):
        e = np.zeros(len(rows))
        e[i] = error_m
        xi = np.linalg.lstsq(A, e, rcond=DEFAULT.numerics.rcond)[0]
        v, w = float(np.linalg.norm(xi[:d])), float(np.linalg.norm(xi[d:]))
        if v + w * R > worst[3]:
            worst = (loc.name, v, w, v + w * R)
    return worst


@dataclass(frozen=True)
class FixtureSummary:
    """What :func:`summarize` found.

    Attributes
    ----------
    kind : str
        ``3D box, 6 locators, 0 contacts``.
    goal : {"given", "computed"} or None
        Where the goal pose comes from; None without a goal (fewer locators than a full fixture).
    start_gaps_m : dict
        Each locator's gap at the start pose [m].
    rank : int or None
        :func:`goal_rank` (None without a goal).
    warnings : tuple of Issue
        The loader's warnings, and an under-determined pose.
    details : tuple of str
        One line per fact, for people (``fixplan validate --verbose``).
    """

    kind: str
    goal: str | None
    start_gaps_m: dict[str, float]
    rank: int | None
    ndof: int
    warnings: tuple[Issue, ...]
    details: tuple[str, ...]
    free: int = 0  # motions left free by the part's symmetry (a cylinder's spin: 1)

    @property
    def determines_pose(self) -> bool | None:
        """Whether the locators determine the pose at the goal (None without a goal)."""
        return None if self.rank is None else self.rank >= self.ndof - self.free

    @property
    def note(self) -> str:
        """``, goal given and checked`` / ``, goal computed`` / empty: the tail of validate's ok line.

        A part located up to its symmetry adds what is free: ``, goal computed, spin free`` (a
        cylinder, a disk), ``, rotation free`` (a sphere).
        """
        if self.goal is None:
            return ""
        spin = ", spin free" if self.free == 1 else ", rotation free" if self.free else ""
        return ", goal " + ("given and checked" if self.goal == "given" else "computed") + spin


def summarize(fixture: Fixture) -> FixtureSummary:
    """The kind, start gaps, goal and determinacy of a loaded fixture (see :class:`FixtureSummary`)."""
    from fixplan.locating import locator_contact
    from fixplan.spatial import rpy_from_matrix

    d = fixture.dimension
    kind = f"{d}D {fixture.workpiece.shape.name}, {len(fixture.locators)} locators, {len(fixture.contacts)} contacts"
    warnings = list(fixture.warnings)
    details: list[str] = []

    def pose_text(pose: Pose) -> str:
        pos = ", ".join(f"{x:.6g}" for x in pose.p_world)
        if d == 3:
            rpy = ", ".join(f"{x:.4g}" for x in np.degrees(rpy_from_matrix(pose.R_world_body)))
            return f"position [{pos}] m, rpy [{rpy}] deg"
        return f"position [{pos}] m, angle {np.degrees(pose.angle_rad):.4g} deg"

    shape = fixture.workpiece.shape
    if isinstance(shape, Mesh):
        mesh = shape
        details.append(
            f"mesh: {mesh.faces.shape[0]} triangles, {mesh.vertices.shape[0]} vertices, volume {mesh.volume_m3:.6g} m³"
        )
        details.extend(f"mesh: {note}" for note in mesh.notes)
    details.append(f"start: {pose_text(fixture.start)}")
    gaps: dict[str, float] = {}
    for loc in fixture.locators:
        gap = float(locator_contact(fixture.workpiece, fixture.start, loc).gap_m)
        gaps[loc.name] = gap
        touching = "touching" if gap <= fixture.tolerances.touch_m else "open"
        details.append(f"  {loc.name}: gap {gap:.3g} m at the start ({touching})")
    goal: str | None = None
    rank: int | None = None
    if fixture.is_full:
        goal = "given" if fixture.goal_given is not None else "computed"
        # with pins the rank of the rests' and pins' constraint normals was checked at load (6, or refused)
        rank = fixture.ndof if fixture.has_pins else goal_rank(fixture)
        for pin in fixture.pins:
            hole = fixture.workpiece.hole(pin.hole)
            details.append(
                f"  {pin.name}: {pin.kind} pin in {hole.name}, radial play (D - d)/2 = "
                f"{0.5 * (hole.diameter_m - pin.diameter_m):.3g} m"
            )
        free = len(fixture.free_motions)  # the part's symmetry, left free (a cylinder's spin)
        determined = rank >= fixture.ndof - free
        details.append(f"goal ({goal}): {pose_text(fixture.goal)}")
        if isinstance(shape, Mesh):
            for loc in fixture.locators:
                centre = fixture.goal.point_body_from_world(loc.p_world)
                touches = shape.contacts(centre)
                if len(touches) > 1:
                    details.append(
                        f"  {loc.name} touches the mesh at {len(touches)} places at the goal (a concave corner); "
                        "the commands use the nearest one only for now"
                    )
        if fixture.goal_starts:
            n = fixture.goal_starts
            how = "Gauss–Newton from the start pose" if n == 1 else "the start pose alone did not lead there"
            details.append(f"goal found from {n} start{'s' if n != 1 else ''} ({how})")
        if free:
            from fixplan.locating import describe_motions

            what = describe_motions(fixture, fixture.goal, fixture.free_motions_world(fixture.goal))
            details.append(f"free at the goal: {what} (the part's symmetry; the goal keeps the start's)")
        details.append(
            f"rank of G at the goal: {rank} of {fixture.ndof}: "
            + (
                (
                    "the locators determine the pose up to the part's symmetry"
                    if free
                    else "the locators determine the pose"
                )
                if determined
                else "the locators do NOT determine the pose"
            )
        )
        if determined and not fixture.has_pins and not free:
            err = DEFAULT.verification.final_gap_m  # the located tolerance: a locator worn or set that far off
            name, v, w, _ = locating_sensitivity(fixture, err)
            details.append(
                f"locating error: {name} {err * 1e3:g} mm off along its normal moves the located pose "
                f"{v * 1e3:.3g} mm (centre of mass) and turns it {np.degrees(w):.3g}° (the worst locator)"
            )
        if not determined:
            warnings.append(
                Issue(
                    "locator",
                    f"warning: the locators do not determine the pose (rank G = {rank} < {fixture.ndof}): "
                    "the part can move while touching every locator",
                )
            )
    else:
        need = 6 if d == 3 else 3
        details.append(f"no goal: {len(fixture.locators)} locators, a full fixture has {need} (analysis only)")
        if fixture.unlocated:
            details.append(f"free: {fixture.unlocated}")
    return FixtureSummary(
        kind, goal, gaps, rank, fixture.ndof, tuple(warnings), tuple(details), len(fixture.free_motions)
    )
