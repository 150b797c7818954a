"""The validated model of a fixture: workpiece, locators, contacts, hand, and the located pose.

Plain frozen dataclasses with no file format in them: :mod:`fixplan.fixture` reads a TOML file
into them (and checks it), everything else takes them. Positions are world coordinates [m], the
workpiece's mass properties are about its centre of mass in body axes.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from fixplan.errors import InfeasibleError, Issue
from fixplan.geometry import Shape
from fixplan.settings import DEFAULT_TOLERANCES as DEFAULT
from fixplan.settings import Tolerances
from fixplan.spatial import Pose

FloatArray = NDArray[np.float64]


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
class Manipulator:
    """What the hand or robot can exert on the workpiece."""

    max_force_N: float = float("inf")
    max_torque_Nm: float = float("inf")


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

    @property
    def ndof(self) -> int:
        return 6 if self.dimension == 3 else 3

    @property
    def is_full(self) -> bool:
        """Six locators in 3D, three in 2D: enough to locate the part."""
        return len(self.locators) >= (6 if self.dimension == 3 else 3)

    @property
    def names(self) -> list[str]:
        return [loc.name for loc in self.locators] + [c.name for c in self.contacts]

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

    def gravity_wrench(self) -> FloatArray:
        """Gravity as a wrench about the centre of mass, world axes."""
        g = self.workpiece.mass_kg * self.gravity
        return np.concatenate([g, np.zeros(3)]) if self.dimension == 3 else np.array([g[0], g[1], 0.0])

    def locator(self, name: str) -> Locator:
        for loc in self.locators:
            if loc.name == name:
                return loc
        raise KeyError(name)


def require_full(fixture: Fixture, what: str) -> None:
    """Raise a clear error when ``what`` needs a full fixture (6 locators in 3D, 3 in 2D)."""
    need = 6 if fixture.dimension == 3 else 3
    if len(fixture.locators) < need:
        raise InfeasibleError(
            f"{what} needs a full fixture ({need} locators in {fixture.dimension}D); "
            f"{fixture.source} has {len(fixture.locators)}"
        )


__all__ = [
    "ExplicitContact",
    "Fixture",
    "Locator",
    "Manipulator",
    "Obstacle",
    "SimulationSettings",
    "Workpiece",
    "require_full",
]
