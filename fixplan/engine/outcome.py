"""What a finished simulation run says: the final state, the contacts, and the solver's quality.

``fixplan simulate`` prints :class:`RunOutcome` (``--json``: :meth:`RunOutcome.to_json`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from fixplan.engine.simulator import ContactReport, ObstacleReport, Simulator, Trajectory
    from fixplan.spatial import Pose

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class RunOutcome:
    """The end of a run of :class:`~fixplan.engine.simulator.Simulator`, and how well it was solved.

    ``v_com`` and ``w`` are the centre of mass's linear [m/s] and the angular velocity [rad/s],
    world axes. ``max_error`` is the largest FCLib residual of the recorded steps, ``converged``
    whether it stays within ``tolerance``.
    """

    steps: int
    time_s: float  # simulated [s]
    dt: float  # [s]
    pose: Pose  # T_world_body at the end
    v_com: FloatArray
    w: FloatArray
    max_penetration_m: float
    contacts: tuple[ContactReport, ...]
    max_error: float
    mean_iterations: float
    tolerance: float
    wall_time_s: float
    obstacles: tuple[ObstacleReport, ...] = ()  # collision-only bodies: gap and force, never contacts

    @property
    def converged(self) -> bool:
        return bool(self.max_error <= self.tolerance)

    @classmethod
    def of(cls, sim: Simulator, traj: Trajectory) -> RunOutcome:
        """The outcome of ``sim`` after the run that recorded ``traj``."""
        twist = sim.twist
        d = sim.pose.dimension
        return cls(
            steps=sim.steps,
            time_s=sim.time_s,
            dt=sim.dt,
            pose=sim.pose,
            v_com=np.array(twist[:d], dtype=float),
            w=np.array(twist[d:], dtype=float),
            max_penetration_m=float(traj.max_penetration_m),
            contacts=tuple(sim.contacts()),
            max_error=float(max(traj.error, default=0.0)),
            mean_iterations=float(np.mean(traj.iterations)) if len(traj.iterations) else 0.0,
            tolerance=sim.tolerance,
            wall_time_s=traj.wall_time_s,
            obstacles=tuple(sim.obstacles()),
        )

    def to_json(self) -> dict[str, Any]:
        return {
            "steps": self.steps,
            "time": self.time_s,
            "pose": self.pose.to_json(),
            "velocity": {"linear": [float(x) for x in self.v_com], "angular": [float(x) for x in self.w]},
            "max_penetration": self.max_penetration_m,
            "contacts": [c.to_json() for c in self.contacts],
            "obstacles": [o.to_json() for o in self.obstacles],
            "solver": {
                "max_error": self.max_error,
                "mean_iterations": self.mean_iterations,
                "converged": self.converged,
                "tolerance": self.tolerance,
            },
            "wall_time_s": self.wall_time_s,
        }
