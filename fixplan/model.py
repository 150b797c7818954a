"""The validated model of a fixture: workpiece, locators, contacts, hand, and the located pose.

Plain frozen dataclasses with no file format in them: :mod:`fixplan.fixture` reads a TOML file
into them (and checks it), everything else takes them. Positions are world coordinates [m], the
workpiece's mass properties are about its centre of mass in body axes.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from fixplan.errors import InfeasibleError, Issue
from fixplan.geometry import Cylinder, Disk, Shape, Sphere
from fixplan.settings import DEFAULT_TOLERANCES as DEFAULT
from fixplan.settings import Tolerances
from fixplan.spatial import Pose, exp_so3, rot2, skew

FloatArray = NDArray[np.float64]


STANDARD_GRAVITY_M_S2 = 9.81  # [m/s²]: the scale of default pushes and limits in a weightless scene


@dataclass(frozen=True)
class Locator:
    """A fixed locator: a spherical tip (radius 0: a point) at ``p_world``."""

    name: str
    p_world: FloatArray
    radius_m: float
    friction: float
    torsion_m: float = 0.0
    face: str | None = None


@dataclass(frozen=True)
class ExplicitContact:
    """A geometry-free contact given at the start pose."""

    name: str
    point_world: FloatArray
    normal_world: FloatArray  # unit, the direction in which the fixture pushes the workpiece
    friction: float
    torsion_m: float = 0.0


@dataclass(frozen=True)
class Hole:
    """A cylindrical hole in the workpiece (``[[workpiece.hole]]``), body frame.

    ``axis_body`` is unit and points out of the part through the mouth ``p_body``; ``through``:
    the hole's bottom lies on or outside the part's surface (set at load).
    """

    name: str
    p_body: FloatArray
    axis_body: FloatArray
    diameter_m: float
    depth_m: float
    chamfer_m: float = 0.0
    through: bool = False


@dataclass(frozen=True)
class Pin:
    """A locating pin fixed in the fixture (``[[pin]]``), world frame; it enters the part's hole ``hole``.

    A round pin locates the hole's axis in both directions normal to it (2 constraints), a diamond
    pin only along ``land_direction_world`` (1 constraint): its side is relieved but for two lands.
    """

    name: str
    kind: str  # "round" or "diamond"
    hole: str
    p_world: FloatArray  # centre of the base
    axis_world: FloatArray  # unit, base to tip
    diameter_m: float
    length_m: float
    friction: float
    chamfer_m: float = 0.0
    land_direction_world: FloatArray | None = None  # unit, normal to the axis (diamond)
    land_width_m: float = 0.0

    @property
    def constraints(self) -> int:
        """The directions it locates the part in: 2 (round), 1 (diamond)."""
        return 2 if self.kind == "round" else 1


@dataclass(frozen=True)
class Bore:
    """A cylindrical hole in the fixture (``[[bore]]``), world frame, for a cylindrical part (a peg)."""

    name: str
    p_world: FloatArray  # centre of the mouth
    axis_world: FloatArray  # unit, out of the fixture through the mouth
    diameter_m: float
    depth_m: float
    friction: float
    chamfer_m: float = 0.0


@dataclass(frozen=True)
class Obstacle:
    """A fixed body for collision only (a floor, a base plate, the fixture's body): never a locator.

    The part may touch it and it pushes back with Coulomb friction in the engine, but it is not
    a locator: it takes no part in contact states, the goal pose or the rank of ``G``.
    ``kind``: ``"plane"`` or ``"box"`` (2D: ``"line"`` or ``"rectangle"``). A plane's frame has
    its origin on the plane and its last axis along the normal, towards the free side; a box is
    centred on its frame's origin with half extents ``half_m`` along its axes
    (:mod:`fixplan.geometry.collision`).
    """

    name: str
    kind: str
    R_world_obstacle: FloatArray
    o_world: FloatArray
    half_m: FloatArray  # box / rectangle half extents [m]; empty for a plane / line
    friction: float

    @property
    def is_plane(self) -> bool:
        return self.kind in ("plane", "line")


@dataclass(frozen=True)
class Clamp:
    """A clamp applied after loading (``[[clamp]]``): its tip touches the located part and pushes along a direction.

    ``p_world`` is the centre of the spherical tip (radius ``radius_m``) when it touches the part
    at the located pose; ``direction_world`` (unit) the direction it pushes the part;
    ``force_N`` a fixed force (a toggle clamp), else None: the force is computed within
    ``max_force_N``.
    """

    name: str
    p_world: FloatArray
    direction_world: FloatArray
    radius_m: float
    friction: float
    max_force_N: float
    force_N: float | None = None


@dataclass(frozen=True)
class ProcessLoad:
    """A process load the clamped part must hold (``[[load]]``): a wrench about the body origin, world axes."""

    name: str
    wrench: FloatArray  # (6,) in 3D, (Fx, Fy, Mz) in 2D


@dataclass(frozen=True)
class Manipulator:
    """What the hand or robot can exert on the workpiece."""

    max_force_N: float = float("inf")
    max_torque_Nm: float = float("inf")


@dataclass(frozen=True)
class RobotSpec:
    """The ``[robot]`` table: the arm that carries the part (its model is loaded by :mod:`fixplan.robot_file`).

    ``urdf`` is what the file says; ``urdf_path`` the file it names (None for a robot of
    example-robot-data, named by ``urdf``). ``base`` is the world pose of the URDF's root frame,
    ``grasp`` the tool frame's pose in the workpiece body frame: the part's world pose ``X`` puts
    the tool at ``X · grasp``. ``tool_frame`` None: the URDF's last frame.
    """

    urdf: str
    urdf_path: Path | None
    base: Pose
    grasp: Pose
    tool_frame: str | None = None
    repeatability_m: float | None = None


@dataclass(frozen=True)
class SimulationSettings:
    """Defaults for the simulator, overridable on the command line."""

    timestep_s: float = 1e-3
    restitution: float = 0.0
    tolerance: float = 1e-8


@dataclass(frozen=True)
class Workpiece:
    """The rigid part: its shape, mass and inertia about the centre of mass (body axes)."""

    shape: Shape
    mass_kg: float
    inertia_body: FloatArray  # (3,3) in 3D, (1,1) in 2D
    com_body: FloatArray
    holes: tuple[Hole, ...] = ()  # [[workpiece.hole]]: the holes the fixture's pins enter

    def hole(self, name: str) -> Hole:
        for h in self.holes:
            if h.name == name:
                return h
        raise KeyError(name)


@dataclass(frozen=True)
class Fixture:
    """A validated fixture file."""

    source: str
    name: str
    dimension: int
    gravity: FloatArray  # [m/s²], world frame
    workpiece: Workpiece
    locators: tuple[Locator, ...]
    contacts: tuple[ExplicitContact, ...]
    manipulator: Manipulator
    simulation: SimulationSettings
    start: Pose
    goal_given: Pose | None = None  # the file's [workpiece.goal], checked at load
    goal_pose: Pose | None = None  # the located pose: the given goal or the one solved at load (full fixtures)
    goal_starts: int = 0  # starts goal finding tried for ``goal_pose`` (0: given, or not full)
    tolerances: Tolerances = field(default=DEFAULT)
    warnings: tuple[Issue, ...] = ()  # plausibility warnings (not errors): `validate` prints them
    obstacles: tuple[Obstacle, ...] = ()  # collision-only bodies ([[obstacle]]): never locators
    # (k, ndof): twists (v, ω) of the centre of mass in body axes that keep every locator touching at
    # the located pose and map the part onto itself (a cylinder's spin about its axis). Set at load
    # (:func:`fixplan.locating.with_free_motions`) when fewer locators than a full fixture leave only
    # these free: such a fixture is located up to them, and planning leaves them free. None: none.
    free_motions_body: FloatArray | None = None
    unlocated: str = ""  # a fixture that is not full: the motions its locators leave free, for people
    pins: tuple[Pin, ...] = ()  # [[pin]]: locating pins in the part's holes
    bores: tuple[Bore, ...] = ()  # [[bore]]: holes in the fixture for a cylindrical part
    robot: RobotSpec | None = None  # [robot]: the arm that carries the part (checked along a plan)
    clamps: tuple[Clamp, ...] = ()  # [[clamp]]: applied after loading, at the located pose
    loads: tuple[ProcessLoad, ...] = ()  # [[load]]: process loads the clamped part must hold

    @property
    def has_pins(self) -> bool:
        """Pins or bores: contacts of cylinders in holes (planned by :mod:`fixplan.planner.insertion`)."""
        return bool(self.pins or self.bores)

    @property
    def ndof(self) -> int:
        return 6 if self.dimension == 3 else 3

    @property
    def is_full(self) -> bool:
        """The locators locate the part: six in 3D, three in 2D, or fewer that leave only the part's symmetry free."""
        located = len(self.locators) + sum(p.constraints for p in self.pins)
        return located >= (6 if self.dimension == 3 else 3) or self.free_motions_body is not None

    @property
    def free_motions(self) -> FloatArray:
        """:attr:`free_motions_body`, or an empty ``(0, ndof)`` array: the motions planning leaves free."""
        if self.free_motions_body is None:
            return np.zeros((0, self.ndof))
        return self.free_motions_body

    def free_motions_world(self, pose: Pose) -> FloatArray:
        """The free motions at ``pose`` as world-axes twists of the centre of mass, ``(k, ndof)`` (orthonormal rows)."""
        free = self.free_motions
        d = self.dimension
        v_world = free[:, :d] @ pose.R_world_body.T
        w_world = free[:, d:] @ pose.R_world_body.T if d == 3 else free[:, d:]
        return np.hstack([v_world, w_world])

    def goal_near(self, pose: Pose) -> Pose:
        """The located pose nearest ``pose`` modulo the free motions (:attr:`goal` without them).

        With a free spin the located poses are a family (the goal turned about the symmetry axis);
        this is its member at the least rotation angle from ``pose``: ``pose``'s spin carried over.
        """
        goal = self.goal
        if self.free_motions_body is None:
            return goal
        return nearest_symmetric_pose(self.workpiece.shape, goal, pose)

    @property
    def names(self) -> list[str]:
        return (
            [loc.name for loc in self.locators]
            + [c.name for c in self.contacts]
            + [p.name for p in self.pins]
            + [b.name for b in self.bores]
        )

    @property
    def goal(self) -> Pose:
        """The located pose (every locator touching); only defined for a full fixture.

        Computed once when the file is loaded (:func:`fixplan.fixture.load`) and kept in
        :attr:`goal_pose`; a model built by hand gets it from :func:`fixplan.locating.with_goal`.
        """
        require_full(self, "the goal pose")
        if self.goal_pose is None:
            raise InfeasibleError(f"{self.source}: no goal pose (the model was built without locating it)")
        return self.goal_pose

    @property
    def gravity_m_s2(self) -> float:
        """``|g|`` [m/s²]; standard gravity for a weightless scene (the scale of default pushes and limits)."""
        return float(np.linalg.norm(self.gravity)) or STANDARD_GRAVITY_M_S2

    @property
    def weight_N(self) -> float:
        """The part's weight ``m |g|`` [N] (with standard gravity in a weightless scene)."""
        return self.workpiece.mass_kg * self.gravity_m_s2

    def hand_limits(self) -> tuple[float, float, str]:
        """The hand's force [N] and torque [N·m] limits, with the defaults used without them, and a note.

        Without ``[manipulator]`` limits: ``5 m |g|`` and that force times the part's bounding radius;
        the note says so. The wrench search, the planner's executor and its verification use these.
        """
        F_max, T_max = self.manipulator.max_force_N, self.manipulator.max_torque_Nm
        notes = ""
        if not np.isfinite(F_max):
            F_max = 5.0 * self.weight_N
            notes += f" (no manipulator.max_force: bounded at 5 m|g| = {F_max:.4g} N)"
        if not np.isfinite(T_max):
            T_max = F_max * self.workpiece.shape.bounding_radius
            notes += f" (no manipulator.max_torque: bounded at {T_max:.4g} N·m)"
        return F_max, T_max, notes

    def gravity_wrench(self) -> FloatArray:
        """Gravity as a wrench about the centre of mass, world axes."""
        g = self.workpiece.mass_kg * self.gravity
        return np.concatenate([g, np.zeros(3)]) if self.dimension == 3 else np.array([g[0], g[1], 0.0])

    def locator(self, name: str) -> Locator:
        for loc in self.locators:
            if loc.name == name:
                return loc
        raise KeyError(name)


def symmetry_axes_body(shape: Shape) -> FloatArray:
    """The axes (body, through the body origin) about which turning maps ``shape`` onto itself, ``(k, 3)``.

    A cylinder: its own axis (body z); a sphere: all three body axes; a disk (2D): its centre
    (one row ``[0, 0, 1]``). Other shapes: none (a box's symmetry is discrete, it locates).
    """
    if isinstance(shape, Cylinder):
        return np.array([[0.0, 0.0, 1.0]])
    if isinstance(shape, Sphere):
        return np.eye(3)
    if isinstance(shape, Disk):
        return np.array([[0.0, 0.0, 1.0]])
    return np.zeros((0, 3))


def symmetry_motions_body(workpiece: Workpiece) -> FloatArray:
    """The part's continuous symmetry as twists ``(v, ω)`` of its centre of mass in body axes, ``(k, ndof)``.

    A turn ``ω`` about an axis through the body origin moves the centre of mass ``c`` at ``ω × c``.
    """
    axes = symmetry_axes_body(workpiece.shape)
    c = np.zeros(3)
    c[: len(workpiece.com_body)] = workpiece.com_body
    if workpiece.shape.dimension == 2:
        return np.array([[-a[2] * c[1], a[2] * c[0], a[2]] for a in axes]).reshape(len(axes), 3)
    return np.array([[*np.cross(a, c), *a] for a in axes]).reshape(len(axes), 6)


def nearest_symmetric_pose(shape: Shape, pose: Pose, near: Pose) -> Pose:
    """``pose`` turned about the shape's symmetry axes (:func:`symmetry_axes_body`) to the least rotation from ``near``.

    Closed forms: a disk takes ``near``'s angle, a sphere ``near``'s rotation; a cylinder turns by
    θ about its axis ``a`` (``K = [a]×``, ``A = R_nearᵀ R``): ``tr(A exp(θ K))`` is largest at
    ``θ = atan2(tr(A K), −tr(A K²))``. The body origin (on every axis) stays where it is.
    """
    axes = symmetry_axes_body(shape)
    if len(axes) == 0:
        return pose
    if pose.dimension == 2:
        return Pose(rot2(near.angle_rad), pose.p_world)
    if len(axes) == 3:
        return Pose(near.R_world_body, pose.p_world)
    K = skew(axes[0])
    A = near.R_world_body.T @ pose.R_world_body
    theta = float(np.arctan2(np.trace(A @ K), -np.trace(A @ K @ K)))
    return Pose(pose.R_world_body @ exp_so3(theta * axes[0]), pose.p_world)


def require_full(fixture: Fixture, what: str) -> None:
    """Raise a clear error when ``what`` needs a full fixture (6 locators in 3D, 3 in 2D, or fewer on a symmetric part).

    Fewer locators will do when they leave only the part's symmetry free (five on a cylinder: its
    spin); the message names the motions the locators leave free (:attr:`Fixture.unlocated`).
    """
    need = 6 if fixture.dimension == 3 else 3
    if not fixture.is_full:
        sym = len(symmetry_axes_body(fixture.workpiece.shape))
        fewer = f", or {need - sym} that leave only the {fixture.workpiece.shape.name}'s symmetry free" if sym else ""
        free = f": its locators leave free {fixture.unlocated}" if fixture.unlocated else ""
        raise InfeasibleError(
            f"{what} needs a full fixture ({need} locators in {fixture.dimension}D{fewer}); "
            f"{fixture.source} has {len(fixture.locators)}{free}"
        )


__all__ = [
    "Bore",
    "Clamp",
    "ExplicitContact",
    "Fixture",
    "Hole",
    "Locator",
    "Manipulator",
    "Obstacle",
    "Pin",
    "RobotSpec",
    "ProcessLoad",
    "SimulationSettings",
    "Workpiece",
    "nearest_symmetric_pose",
    "require_full",
    "symmetry_axes_body",
    "symmetry_motions_body",
]
