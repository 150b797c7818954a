"""The plan of a fixture load and its timeline, in memory and as the JSON of a plan file: the types.

A :class:`Plan` is what ``fixplan solve`` answers: the status, the sequence of contact states,
per transition its policy (:class:`PlannedTransition`: the added locator, the motion, the mean
planned wrench, the least margin, the knot poses), what was tried, and the
:class:`Verification` (the simulated haptic loop's outcome, with its :class:`Timeline`).
``fixplan solve --out`` writes :meth:`Plan.to_json`; :meth:`Plan.from_json` reads the object back
after checking it against the format (:func:`check_plan_document`). Reading a plan *file* for a
fixture (its locators, start pose and claims) is :mod:`fixplan.planner.plan`'s, which also
re-exports every name here.

A :class:`Timeline` is the one sampled history of a load: times, poses, pressed locators, and
where known the gaps, normal and world contact forces, the hand's push and the felt wrench. The
verification records one; :func:`fixplan.planner.plan.knot_timeline` makes one of the planned
knot poses; the plan figure (:mod:`fixplan.present.plots`) and the scene page
(:mod:`fixplan.present.scene`) draw them.

JSON is strict: no NaN or Infinity; an undefined number is ``null``. ``to_json`` then
``from_json`` gives the same object, and ``from_json`` then ``to_json`` the same JSON (poses are
kept in the form they were read, since quaternion → matrix → quaternion is not exact to the
last bit). A few in-memory details of a freshly solved plan are not in the file (the wrench per
segment, the fine planner's kind of motion): they compare as equal and read back as ``None``.

Wrenches are about the body origin, in world axes [N, N·m]; forces on the workpiece, world axes [N].
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, cast, get_args

import numpy as np
from numpy.typing import NDArray

from fixplan.errors import InputError
from fixplan.planner.policy import Policy
from fixplan.spatial import Pose, matrix_from_quaternion_wxyz, rot2

if TYPE_CHECKING:
    from fixplan.haptics import LoopRecord
    from fixplan.planner.execute import ExecutionLog

FloatArray = NDArray[np.float64]

NOT_A_PLAN = "not a fixplan plan (expected the JSON object written by 'fixplan solve --out')"

# a plan's status as words ("plan planned" read as a typo)
STATUS_WORDS = {"planned": "plan found", "unverified": "plan unverified", "infeasible": "no plan (infeasible)"}


# -- JSON pieces -----------------------------------------------------------------------------------
def _short(obj: Any) -> str:
    text = json.dumps(obj) if not isinstance(obj, str) else repr(obj)
    return text if len(text) <= 40 else text[:37] + "..."


def _is_number(x: Any) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x)


def _vector(obj: Any, where: str) -> FloatArray:
    if not isinstance(obj, list) or not all(_is_number(x) for x in obj):
        raise InputError(f"{where}: expected a list of finite numbers, got {_short(obj)}")
    return np.asarray(obj, dtype=float)


def _names(obj: Any, where: str) -> list[str]:
    if not isinstance(obj, list) or not all(isinstance(x, str) for x in obj):
        raise InputError(f"{where}: expected a list of locator names, got {_short(obj)}")
    return list(obj)


def _number(obj: Any, where: str, *, default: float | None = None, optional: bool = False) -> float | None:
    """A finite number, ``None`` for JSON null (when ``optional``), ``default`` when absent (``obj is ...``)."""
    if obj is ...:
        return default
    if obj is None and optional:
        return None
    if not _is_number(obj):
        raise InputError(f"{where}: expected a number, got {_short(obj)}")
    return float(obj)


def _rows(a: FloatArray) -> list[list[float]]:
    return [[float(x) for x in r] for r in a]


def _matrix(obj: Any, where: str, shape: tuple[int, int]) -> FloatArray:
    """A (T, k) array of finite numbers."""
    try:
        a = np.asarray(obj, dtype=float)
    except (TypeError, ValueError):
        a = None
    if a is None or a.shape != shape or not np.all(np.isfinite(a)):
        raise InputError(f"{where}: expected {shape[0]} rows of {shape[1]} finite numbers")
    return a


def _dimension_of(pose_json: Any) -> int:
    """The dimension a JSON pose is written for (3 when it has a quaternion), for files read without a fixture."""
    return 3 if isinstance(pose_json, dict) and "quaternion_wxyz" in pose_json else 2


@dataclass(frozen=True)
class ReadPose(Pose):
    """A pose read from a plan file: it writes back the very numbers it was read from.

    (Quaternion → matrix → quaternion, and degrees → radians → degrees, are not exact to the last
    bit; a plan read and written again must be the same file.)
    """

    source_json: dict[str, Any] = field(default_factory=dict, compare=False, repr=False)

    def to_json(self) -> dict[str, Any]:
        return {k: (list(v) if isinstance(v, list) else v) for k, v in self.source_json.items()}


def pose_from_json(obj: Any, dimension: int, where: str) -> Pose:
    """A pose in the spec's JSON form: 3D ``{position, quaternion_wxyz}``, 2D ``{position, angle_deg}``."""
    if not isinstance(obj, dict) or "position" not in obj:
        raise InputError(f"{where}: expected a pose {{'position', ...}}, got {_short(obj)}")
    other = 2 if dimension == 3 else 3
    if dimension == 3 and "quaternion_wxyz" not in obj and "angle_deg" in obj:
        raise InputError(f"{where}: a 2D pose (angle_deg) in a plan for a 3D fixture: the plan is for another fixture")
    if dimension == 2 and "quaternion_wxyz" in obj:
        raise InputError(
            f"{where}: a 3D pose (quaternion_wxyz) in a plan for a 2D fixture: the plan is for another fixture"
        )
    position = _vector(obj["position"], f"{where}.position")
    if position.shape[0] != dimension:
        raise InputError(
            f"{where}.position: expected {dimension} numbers, got {position.shape[0]} (a plan for a {other}D fixture?)"
        )
    written = {"position": [float(x) for x in position]}
    if dimension == 3:
        q = _vector(obj.get("quaternion_wxyz"), f"{where}.quaternion_wxyz")
        if q.shape[0] != 4 or not np.linalg.norm(q) > 0.0:
            raise InputError(f"{where}.quaternion_wxyz: expected 4 numbers, not all zero")
        return ReadPose(matrix_from_quaternion_wxyz(q), position, {**written, "quaternion_wxyz": [float(x) for x in q]})
    angle: Any = obj.get("angle_deg")
    if not _is_number(angle):
        raise InputError(f"{where}.angle_deg: expected a number [deg], got {_short(angle)}")
    return ReadPose(rot2(math.radians(angle)), position, {**written, "angle_deg": float(angle)})


def _poses(objs: list[Any], dimension: int, where: str) -> tuple[Pose, ...]:
    return tuple(pose_from_json(p, dimension, f"{where}[{k}]") for k, p in enumerate(objs))


# -- the timeline ----------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Timeline:
    """A load sampled over time: poses, pressed locators, and where known gaps, forces and wrenches.

    Attributes
    ----------
    names : tuple of str
        The locators, in fixture order (the columns of the per-locator arrays).
    time_s : (T,) array
        Sample times [s].
    poses : tuple of Pose
        ``T_world_body`` per sample.
    pressed : tuple of tuple of str
        Locators pushing on the part at each sample.
    gaps_m, normal_forces_N : (T, n) arrays or None
        Gap [m] and normal force [N] per locator; None: not known.
    forces_world_N : (T, n, d) array or None
        Force on the workpiece at each locator, world axes [N].
    coupling_wrench : (T, ndof) array or None
        The hand's push on the workpiece (the virtual coupling's wrench; for planned knots, the
        plan's mean wrench), about the body origin, world axes.
    felt_wrench : (T, ndof) array or None
        What the haptic device displayed to the user (saturated).
    command_wrench : (T, ndof) array or None
        The executor's push at the sample (what the hand was asked to apply; the coupling's wrench
        follows it with the coupling's lag), about the body origin, world axes.
    every_s : float or None
        The sampling step of a recorded timeline [s] (None for planned knots).
    """

    names: tuple[str, ...]
    time_s: FloatArray
    poses: tuple[Pose, ...]
    pressed: tuple[tuple[str, ...], ...]
    gaps_m: FloatArray | None = None
    normal_forces_N: FloatArray | None = None
    forces_world_N: FloatArray | None = None
    coupling_wrench: FloatArray | None = None
    felt_wrench: FloatArray | None = None
    every_s: float | None = None
    command_wrench: FloatArray | None = None

    def __len__(self) -> int:
        return len(self.poses)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Timeline):
            return NotImplemented
        return self.to_json() == other.to_json()

    __hash__ = None  # type: ignore[assignment]

    def to_json(self) -> dict[str, Any]:
        def per_locator(a: FloatArray | None) -> dict[str, list[float]] | None:
            return None if a is None else {n: [float(x) for x in a[:, i]] for i, n in enumerate(self.names)}

        return {
            "every_s": self.every_s,
            "names": list(self.names),
            "time_s": [float(t) for t in self.time_s],
            "poses": [p.to_json() for p in self.poses],
            "gaps_m": per_locator(self.gaps_m),
            "normal_forces_N": per_locator(self.normal_forces_N),
            "forces_world_N": None
            if self.forces_world_N is None
            else {n: _rows(self.forces_world_N[:, i]) for i, n in enumerate(self.names)},
            "coupling_wrench": None if self.coupling_wrench is None else _rows(self.coupling_wrench),
            "felt_wrench": None if self.felt_wrench is None else _rows(self.felt_wrench),
            **({} if self.command_wrench is None else {"command_wrench": _rows(self.command_wrench)}),
            "pressed": [list(s) for s in self.pressed],
        }

    @classmethod
    def from_json(cls, obj: Any, *, dimension: int | None = None, where: str = "trace") -> Timeline:
        """Read :meth:`to_json`'s form; ``dimension`` (of the fixture) checks the poses' kind and the widths.

        Raises :class:`InputError` naming the first malformed entry.
        """
        if not isinstance(obj, dict):
            raise InputError(f"{where}: expected an object, got {_short(obj)}")
        names = tuple(_names(obj.get("names"), f"{where}.names"))
        time_s = _vector(obj.get("time_s"), f"{where}.time_s")
        T = time_s.shape[0]
        if T == 0:
            raise InputError(f"{where}.time_s: empty (expected the sample times)")
        poses_json = obj.get("poses")
        if not isinstance(poses_json, list) or len(poses_json) != T:
            raise InputError(f"{where}.poses: expected {T} poses (one per time_s), got {_short(poses_json)}")
        d = dimension if dimension is not None else _dimension_of(poses_json[0])
        ndof = 6 if d == 3 else 3
        poses = _poses(poses_json, d, f"{where}.poses")
        forces_json = obj.get("forces_world_N")
        forces = None
        if forces_json is not None:
            if not isinstance(forces_json, dict):
                raise InputError(
                    f"{where}.forces_world_N: expected {{locator: [[f...]...]}}, got {_short(forces_json)}"
                )
            forces = np.zeros((T, len(names), d))
            for i, name in enumerate(names):
                try:
                    f = np.asarray(forces_json[name], dtype=float)
                except (KeyError, TypeError, ValueError):
                    raise InputError(f"{where}.forces_world_N.{name}: expected {T} rows of {d} numbers") from None
                if f.shape != (T, d) or not np.all(np.isfinite(f)):
                    raise InputError(
                        f"{where}.forces_world_N.{name}: expected {T} rows of {d} finite numbers, got {f.shape}"
                    )
                forces[:, i] = f
        elif "forces_world_N" not in obj:
            raise InputError(f"{where}.forces_world_N: expected {{locator: [[f...]...]}}, got null")
        pressed_json = obj.get("pressed")
        if not isinstance(pressed_json, list) or len(pressed_json) != T:
            raise InputError(f"{where}.pressed: expected {T} lists of locator names")
        pressed = tuple(tuple(_names(s, f"{where}.pressed[{k}]")) for k, s in enumerate(pressed_json))

        def wrenches(key: str) -> FloatArray | None:
            if obj.get(key) is None:
                return None
            return _matrix(obj[key], f"{where}.{key}", (T, ndof))

        def per_locator(key: str) -> FloatArray | None:
            columns = obj.get(key)
            if columns is None:
                return None
            if not isinstance(columns, dict):
                raise InputError(f"{where}.{key}: expected {{locator: [numbers...]}}, got {_short(columns)}")
            out = np.zeros((T, len(names)))
            for i, name in enumerate(names):
                v = _vector(columns.get(name), f"{where}.{key}.{name}")
                if v.shape[0] != T:
                    raise InputError(f"{where}.{key}.{name}: expected {T} numbers, got {v.shape[0]}")
                out[:, i] = v
            return out

        coupling = wrenches("coupling_wrench")
        every = _number(obj.get("every_s", ...), f"{where}.every_s", optional=True)
        return cls(
            names=names,
            time_s=time_s,
            poses=poses,
            pressed=pressed,
            gaps_m=per_locator("gaps_m"),
            normal_forces_N=per_locator("normal_forces_N"),
            forces_world_N=forces,
            coupling_wrench=coupling,
            felt_wrench=wrenches("felt_wrench"),
            every_s=every,
            command_wrench=wrenches("command_wrench"),
        )

    @classmethod
    def from_record(cls, rec: LoopRecord, names: Sequence[str], every: int) -> Timeline:
        """The haptic loop's sampled trace (``HapticLoop.run(..., trace_every=every)``) as a timeline."""
        ticks = [k for k, _, _, _ in rec.trace]
        return cls(
            every_s=every * rec.period_s,
            names=tuple(names),
            time_s=np.array([t for _, t, _, _ in rec.trace]),
            poses=tuple(p for _, _, p, _ in rec.trace),
            gaps_m=np.array([[c.gap_m for c in cs] for _, _, _, cs in rec.trace]),
            normal_forces_N=np.array([[c.normal_force_N for c in cs] for _, _, _, cs in rec.trace]),
            forces_world_N=np.array([[c.force_world for c in cs] for _, _, _, cs in rec.trace]),
            coupling_wrench=np.array([rec.coupling_wrench[k] for k in ticks]),
            felt_wrench=np.array([rec.felt_wrench[k] for k in ticks]),
            pressed=tuple(rec.active_contacts[k] for k in ticks),
        )


# -- the verification ------------------------------------------------------------------------------
# JSON key ↔ field, in the file's order (the keys predate the unit suffixes of the fields)
_VERIFICATION_KEYS = (
    ("passed", "passed"),
    ("reason", "reason"),
    ("final_pose", "final_pose"),
    ("max_penetration", "max_penetration_m"),
    ("deadline_misses", "deadline_misses"),
    ("tick_mean_us", "tick_mean_us"),
    ("tick_max_us", "tick_max_us"),
    ("observed_sequence", "observed_sequence"),
    ("final_gaps", "final_gaps_m"),
    ("duration_s", "duration_s"),
    ("felt_force_max", "felt_force_max_N"),
    ("unconverged_steps", "unconverged_steps"),
    ("max_solver_error", "max_solver_error"),
    ("max_push_force", "max_push_force_N"),
    ("max_push_torque", "max_push_torque_Nm"),
    ("saturated_ticks", "saturated_ticks"),
    ("limit_fraction", "limit_fraction"),
    ("peak_force_fraction", "peak_force_fraction"),
    ("peak_torque_fraction", "peak_torque_fraction"),
    ("ticks_above_fraction", "ticks_above_fraction"),
    ("planner_wall_time_in_loop_s", "planner_wall_time_in_loop_s"),
    ("failed_checks", "failed_checks"),
    ("execution", "execution"),
    ("trace", "trace"),
)


@dataclass(eq=False)
class Verification:
    """The outcome of running a plan through the haptic loop.

    ``None`` where the run does not know (a diverged loop has no tick timing; a file may leave a
    quantity out). ``extras`` keeps the keys of a file that are not fields (a recorded session's
    ``kind``); they are written back after the others.
    """

    passed: bool
    reason: str
    final_pose: Pose | None
    max_penetration_m: float | None
    deadline_misses: int | None  # None: the loop did not finish (diverged)
    tick_mean_us: float | None
    tick_max_us: float | None
    observed_sequence: list[tuple[str, ...]]
    final_gaps_m: dict[str, float]
    duration_s: float | None
    felt_force_max_N: float | None
    unconverged_steps: int | None = None  # None: the loop did not finish (diverged)
    max_solver_error: float | None = None  # None: no tick finished
    trace: Timeline | None = None
    execution: ExecutionLog | None = None
    max_push_force_N: float | None = None  # on the part, averaged over 10 ms
    max_push_torque_Nm: float | None = None
    # ticks where the coupling asked more than the hand's limits (capped there); None: not known
    saturated_ticks: int | None = None
    # wall time of the re-plans the executor ran from inside ticks [s] (counted in the tick timing);
    # None: not known (a file without it)
    planner_wall_time_in_loop_s: float | None = None
    # the headroom: the fraction of the hand's limits the executor's pushes keep within where they
    # can, the peak ‖F‖ / max_force and ‖T‖ / max_torque of its push over the ticks, and the ticks
    # where either exceeded the fraction; None: not known (a file without them)
    limit_fraction: float | None = None
    peak_force_fraction: float | None = None
    peak_torque_fraction: float | None = None
    ticks_above_fraction: int | None = None
    # "executor", "final gap", "penetration", "solver", "limits"
    failed_checks: list[str] = field(default_factory=list)
    extras: dict[str, Any] = field(default_factory=dict)
    present: tuple[str, ...] | None = field(default=None, repr=False)  # the keys a file had

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Verification):
            return NotImplemented
        return self.to_json() == other.to_json()

    __hash__ = None  # type: ignore[assignment]

    def to_json(self) -> dict[str, Any]:
        values: dict[str, Any] = {
            "final_pose": None if self.final_pose is None else self.final_pose.to_json(),
            "observed_sequence": [list(s) for s in self.observed_sequence],
            "failed_checks": list(self.failed_checks),
            "final_gaps": dict(self.final_gaps_m),
            "execution": None if self.execution is None else self.execution.to_json(),
            "trace": None if self.trace is None else self.trace.to_json(),
        }
        out = {}
        for key, attr in _VERIFICATION_KEYS:
            if self.present is None or key in self.present:
                out[key] = values[key] if key in values else getattr(self, attr)
        return {**out, **self.extras}

    @classmethod
    def from_json(cls, obj: Any, *, dimension: int | None = None, where: str = "verification") -> Verification:
        """Read :meth:`to_json`'s form (a file may leave quantities out: they read as ``None`` or empty)."""
        if not isinstance(obj, dict):
            raise InputError(f"{where}: expected an object, got {_short(obj)}")
        trace = obj.get("trace")
        timeline = None if trace is None else Timeline.from_json(trace, dimension=dimension, where=f"{where}.trace")
        if dimension is None and timeline is not None:
            dimension = timeline.poses[0].dimension
        final_pose = obj.get("final_pose")
        pose = None
        if final_pose is not None:
            pose = pose_from_json(final_pose, dimension or _dimension_of(final_pose), f"{where}.final_pose")
        observed = obj.get("observed_sequence") or []
        if not isinstance(observed, list):
            raise InputError(f"{where}.observed_sequence: expected lists of locator names, got {_short(observed)}")
        gaps = obj.get("final_gaps") or {}
        if not isinstance(gaps, dict) or not all(_is_number(g) for g in gaps.values()):
            raise InputError(f"{where}.final_gaps: expected {{locator: gap [m]}}, got {_short(gaps)}")
        checks = obj.get("failed_checks") or []
        if not isinstance(checks, list):
            raise InputError(f"{where}.failed_checks: expected a list of names, got {_short(checks)}")

        def num(key: str, default: float | None = None) -> Any:
            return _number(obj.get(key, ...), f"{where}.{key}", default=default, optional=True)

        def count(key: str, default: int | None) -> int | None:
            x = num(key, default)
            return None if x is None else int(x)

        execution = obj.get("execution")
        known = {key for key, _ in _VERIFICATION_KEYS}
        return cls(
            passed=bool(obj.get("passed")),
            reason=str(obj.get("reason", "")),
            final_pose=pose,
            max_penetration_m=num("max_penetration"),
            deadline_misses=count("deadline_misses", None),
            tick_mean_us=num("tick_mean_us"),
            tick_max_us=num("tick_max_us"),
            observed_sequence=[tuple(_names(s, f"{where}.observed_sequence[{k}]")) for k, s in enumerate(observed)],
            final_gaps_m={str(n): float(g) for n, g in gaps.items()},
            duration_s=num("duration_s"),
            felt_force_max_N=num("felt_force_max"),
            unconverged_steps=count("unconverged_steps", None),
            max_solver_error=num("max_solver_error"),
            trace=timeline,
            execution=None if execution is None else execution_from_json(execution, f"{where}.execution"),
            max_push_force_N=num("max_push_force"),
            max_push_torque_Nm=num("max_push_torque"),
            saturated_ticks=count("saturated_ticks", None),
            planner_wall_time_in_loop_s=num("planner_wall_time_in_loop_s"),
            limit_fraction=num("limit_fraction"),
            peak_force_fraction=num("peak_force_fraction"),
            peak_torque_fraction=num("peak_torque_fraction"),
            ticks_above_fraction=count("ticks_above_fraction", None),
            failed_checks=[str(c) for c in checks],
            extras={k: v for k, v in obj.items() if k not in known},
            present=tuple(k for k in obj if k in known),
        )


def execution_from_json(obj: Any, where: str = "execution") -> ExecutionLog:
    """The executor's log from its JSON form (``ExecutionLog.to_json``; the debounced states are not in it)."""
    from fixplan.planner.execute import ExecutionLog, Outcome

    if not isinstance(obj, dict):
        raise InputError(f"{where}: expected an object, got {_short(obj)}")
    events = obj.get("events") or []
    if not isinstance(events, list) or not all(isinstance(e, dict) for e in events):
        raise InputError(f"{where}.events: expected a list of {{time_s, kind, message}}")
    counts = obj.get("counts") or {}
    if not isinstance(counts, dict):
        raise InputError(f"{where}.counts: expected {{name: count}}, got {_short(counts)}")
    outcome = str(obj.get("outcome", "running"))
    if outcome not in get_args(Outcome):
        raise InputError(f"{where}.outcome: expected one of {', '.join(get_args(Outcome))}, got {_short(outcome)}")
    log = ExecutionLog(
        events=[(float(e.get("time_s", 0.0)), str(e.get("kind", "")), str(e.get("message", ""))) for e in events],
        outcome=cast(Outcome, outcome),
        reason=str(obj.get("reason", "")),
        failure_kind=obj.get("failure_kind"),
        max_command_force_N=float(obj.get("max_command_force_N", 0.0)),
        max_command_torque_Nm=float(obj.get("max_command_torque_Nm", 0.0)),
        beyond_fraction_solves=int(obj.get("beyond_fraction_solves", 0)),
        max_arm_torque_ratio=None if obj.get("max_arm_torque_ratio") is None else float(obj["max_arm_torque_ratio"]),
        arm_unreached_solves=int(obj.get("arm_unreached_solves", 0)),
    )
    log.counts = {str(k): int(v) for k, v in counts.items()}
    return log


# -- the plan --------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class PlannedTransition:
    """One transition of a plan, ``from_state → to_state``, and the policy that makes it.

    ``wrench`` is the mean planned push over the transition's segments (None when no segment has
    one), ``margin_N`` the least normal force on the kept contacts along it (None from no contact:
    nothing to press), ``friction_robustness`` the largest δ of friction ``μ(1 ± δ)`` the first push
    survives (None: nothing to slip). ``motion`` is ``free`` from no contact, else the fine planner's
    kind (``slide`` or ``roll``). ``extras`` keeps the keys of a file that are not fields (a recorded
    session's ``pushes``, ``t_start_s``, ``lost``).

    ``added`` is the locator the transition closes; ``together`` the locators that geometry closes
    at the same instant (a redundant layout, planned as one transition: ``{B1,B2,B3,S1,S2} +
    {E1,E2}``). In the file ``"added"`` is then the list of them all, ``["E1", "E2"]``; a transition
    that adds one locator keeps the string, ``"E1"``.
    """

    from_state: tuple[str, ...]
    to_state: tuple[str, ...]
    added: str | None
    motion: str
    wrench: FloatArray | None
    margin_N: float | None
    friction_robustness: float | None
    time_s: float
    path_length_m: float | None
    max_constraint_violation_m: float | None
    solve_time_s: float | None
    poses: tuple[Pose, ...]
    extras: dict[str, Any] = field(default_factory=dict)
    # in memory only (not in the file): the fine plan's wrench per segment (K, ndof) and its kind of motion
    segment_wrenches: FloatArray | None = field(default=None, repr=False)
    kind: str | None = field(default=None, repr=False)
    together: tuple[str, ...] = ()
    # the largest planned push over the segments as fractions of the hand's limits (‖F‖ / max_force,
    # ‖T‖ / max_torque); None: not known (a file without them, no segment with a push)
    peak_force_fraction: float | None = None
    peak_torque_fraction: float | None = None

    @property
    def added_names(self) -> tuple[str, ...]:
        """Every locator the transition adds (``()`` for a recorded transition that added none)."""
        return () if self.added is None else (self.added, *self.together)

    @property
    def added_label(self) -> str:
        """``E1``, or ``{E1,E2}`` for a group closing together (what the CLI and reports print)."""
        return "{" + ",".join(self.added_names) + "}" if self.together else str(self.added)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, PlannedTransition):
            return NotImplemented
        return self.to_json() == other.to_json()

    __hash__ = None  # type: ignore[assignment]

    @property
    def planned_kind(self) -> str:
        """The fine planner's kind of motion when known (a free transition is planned as a roll), else ``motion``."""
        return self.kind if self.kind is not None else self.motion

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {"from": list(self.from_state), "to": list(self.to_state)}
        if self.added is not None:
            out["added"] = list(self.added_names) if self.together else self.added
        out.update(
            {
                "motion": self.motion,
                "wrench": None if self.wrench is None else [float(x) for x in self.wrench],
                "margin": self.margin_N,
                "friction_robustness": self.friction_robustness,
                "time_s": self.time_s,
                "path_length_m": self.path_length_m,
                "max_constraint_violation_m": self.max_constraint_violation_m,
                "solve_time_s": self.solve_time_s,
                "poses": [p.to_json() for p in self.poses],
            }
        )
        if self.peak_force_fraction is not None:
            out["peak_force_fraction"] = self.peak_force_fraction
            out["peak_torque_fraction"] = self.peak_torque_fraction
        return {**out, **self.extras}

    @classmethod
    def from_json(cls, obj: Any, *, dimension: int | None = None, where: str = "transition") -> PlannedTransition:
        if not isinstance(obj, dict):
            raise InputError(f"{where}: expected an object, got {_short(obj)}")
        before = tuple(_names(obj.get("from", []), f"{where}.from"))
        raw = obj.get("added")
        together: tuple[str, ...] = ()
        if isinstance(raw, list):
            # a group closing together: ["E1", "E2"]
            group = _names(raw, f"{where}.added")
            if not group:
                raise InputError(f"{where}.added: expected a locator name or a non-empty list of them, got []")
            added: str | None = group[0]
            together = tuple(group[1:])
        else:
            added = raw
            if added is not None and not isinstance(added, str):
                _names([added], f"{where}.added")
        if "to" in obj:
            after = tuple(_names(obj["to"], f"{where}.to"))
        else:
            after = tuple(sorted([*before, added, *together])) if added else before
        # a hand-written plan without durations replays at 1 s per transition
        duration = obj.get("time_s", 1.0)
        if not _is_number(duration) or duration < 0:
            raise InputError(f"{where}.time_s: expected a non-negative number [s], got {_short(duration)}")
        knots = obj.get("poses") or []
        if not isinstance(knots, list):
            raise InputError(f"{where}.poses: expected the planned knot poses, got {_short(knots)}")
        d = dimension if dimension is not None else (_dimension_of(knots[0]) if knots else None)
        poses = _poses(knots, d, f"{where}.poses") if d is not None else ()
        wrench = obj.get("wrench")
        w = None
        if wrench is not None:
            w = _vector(wrench, f"{where}.wrench")
            ndof = 6 if d == 3 else 3 if d == 2 else w.shape[0]
            if w.shape[0] != ndof:
                raise InputError(f"{where}.wrench: expected {ndof} numbers, got {w.shape[0]}")

        def num(key: str) -> float | None:
            return _number(obj.get(key, ...), f"{where}.{key}", optional=True)

        known = {"from", "to", "added", "motion", "wrench", "margin", "friction_robustness", "time_s"}
        known |= {"path_length_m", "max_constraint_violation_m", "solve_time_s", "poses"}
        known |= {"peak_force_fraction", "peak_torque_fraction"}
        return cls(
            from_state=before,
            to_state=after,
            added=added,
            motion=str(obj.get("motion", "slide")),
            wrench=w,
            margin_N=num("margin"),
            friction_robustness=num("friction_robustness"),
            time_s=float(duration),
            path_length_m=num("path_length_m"),
            max_constraint_violation_m=num("max_constraint_violation_m"),
            solve_time_s=num("solve_time_s"),
            poses=poses,
            extras={k: v for k, v in obj.items() if k not in known},
            together=together,
            peak_force_fraction=num("peak_force_fraction"),
            peak_torque_fraction=num("peak_torque_fraction"),
        )


@dataclass(frozen=True)
class TriedTransition:
    """A transition the coarse search priced: ``from_state + added``, whether it worked, and why not."""

    from_state: tuple[str, ...]
    added: str
    ok: bool
    reason: str
    # "fine": its fine plan ran; "precheck": only the cheap cone check before it, which failed (the
    # search then tried the transition after the others); "path": its path was found, its pushes
    # not searched (its sequence was not the one chosen)
    stage: str = "fine"
    together: tuple[str, ...] = ()  # locators closing at the same instant (then "add" is a list)

    def to_json(self) -> dict[str, Any]:
        add: str | list[str] = [self.added, *self.together] if self.together else self.added
        return {"from": list(self.from_state), "add": add, "ok": self.ok, "reason": self.reason,
                "stage": self.stage}  # fmt: skip

    @classmethod
    def from_json(cls, obj: Any, where: str = "tried") -> TriedTransition:
        if not isinstance(obj, dict):
            raise InputError(f"{where}: expected an object, got {_short(obj)}")
        add = obj.get("add", "")
        group = _names(add, f"{where}.add") if isinstance(add, list) else [str(add)]
        return cls(
            tuple(_names(obj.get("from", []), f"{where}.from")),
            group[0] if group else "",
            bool(obj.get("ok", False)),
            str(obj.get("reason", "")),
            str(obj.get("stage", "fine")),
            tuple(group[1:]),
        )


# top-level keys of a plan file, in the order solve writes them
_PLAN_KEYS = (
    "status", "reason", "sequence", "transitions", "tried", "proven", "certificate", "verification", "policy", "coverage",
)  # fmt: skip


@dataclass(frozen=True, eq=False)
class Plan:
    """A loading plan: status, sequence of contact states, transitions with their policy, verification.

    Attributes
    ----------
    status : {"planned", "unverified", "infeasible"} or a recorded session's outcome
        ``planned``: found and confirmed in the haptic loop.
    reason : str
        Why not planned, or a note.
    sequence : tuple of tuple of str
        The contact states, from the start state to every locator.
    transitions : tuple of PlannedTransition
    tried : tuple of TriedTransition
        Every transition the search priced.
    proven : bool or None
        For ``infeasible``: whether every blocking transition is certified by its wrench search.
    certificate : tuple of TriedTransition
        For ``infeasible``: the certified failed transitions.
    verification : Verification or None
        None when not run.
    timings : dict
        Wall-clock times [s] by phase.
    policy : Policy or None
        The next transition from every contact state the part can be observed in
        (:mod:`fixplan.planner.policy`); None when not built (no plan, or a recorded session).
    extras : dict
        Other keys of the file (``perturbation``; a recorded session's ``source``, ``fixture``,
        ``where``, ``session``), written after the others.
    """

    status: str
    reason: str
    sequence: tuple[tuple[str, ...], ...]
    transitions: tuple[PlannedTransition, ...]
    tried: tuple[TriedTransition, ...] = ()
    proven: bool | None = None
    certificate: tuple[TriedTransition, ...] = ()
    verification: Verification | None = None
    timings: dict[str, float] = field(default_factory=dict)
    extras: dict[str, Any] = field(default_factory=dict)
    present: tuple[str, ...] | None = field(default=None, repr=False)  # the top-level keys a file had
    policy: Policy | None = None

    @property
    def ok(self) -> bool:
        return self.status == "planned"

    @property
    def durations_s(self) -> list[float]:
        """Planned duration of each transition [s]."""
        return [tr.time_s for tr in self.transitions]

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Plan):
            return NotImplemented
        return self.to_json() == other.to_json()

    __hash__ = None  # type: ignore[assignment]

    def with_extras(self, **extras: Any) -> Plan:
        """The plan with more top-level keys (``perturbation``)."""
        from dataclasses import replace

        return replace(self, extras={**self.extras, **extras})

    def to_json(self) -> dict[str, Any]:
        values: dict[str, Any] = {
            "status": self.status,
            "reason": self.reason,
            "sequence": [list(s) for s in self.sequence],
            "transitions": [tr.to_json() for tr in self.transitions],
            "tried": [a.to_json() for a in self.tried],
            "proven": self.proven,
            "certificate": [
                {k: v for k, v in a.to_json().items() if k in ("from", "add", "reason")} for a in self.certificate
            ],
            "verification": None if self.verification is None else self.verification.to_json(),
            "policy": None if self.policy is None else self.policy.to_json(),
            "coverage": None if self.policy is None else self.policy.coverage,
        }
        out = {k: v for k, v in values.items() if self.present is None or k in self.present}
        if self.present is None or "timings" in self.present:
            out["timings"] = dict(self.timings)
        leading = {k: v for k, v in self.extras.items() if k in _LEADING}
        return {**leading, **out, **{k: v for k, v in self.extras.items() if k not in _LEADING}}

    @classmethod
    def from_json(
        cls, data: Any, *, source: str = "plan", dimension: int | None = None, validated: bool = False
    ) -> Plan:
        """Read a plan file's object (``fixplan solve --out`` or ``fixplan haptic --record``).

        The object is first checked against the format (:func:`check_plan_document`; skipped when
        ``validated``): ``dimension`` (of the fixture the plan is read for) checks the kind of
        every pose and the width of every wrench. Raises :class:`InputError` (every problem with
        its key path: :class:`~fixplan.errors.InputFileError`).
        """
        if not validated:
            check_plan_document(data, source, dimension)
        if not isinstance(data, dict) or not isinstance(data.get("transitions"), list) or "status" not in data:
            raise InputError(f"{source}: {NOT_A_PLAN}")
        sequence = data.get("sequence") or []
        if not isinstance(sequence, list):
            raise InputError(f"{source}: sequence: expected lists of locator names, got {_short(sequence)}")
        verification = data.get("verification")
        v = None
        if verification is not None:
            v = Verification.from_json(verification, dimension=dimension, where=f"{source}: verification")
            if dimension is None and v.trace is not None:
                dimension = v.trace.poses[0].dimension
        transitions = tuple(
            PlannedTransition.from_json(tr, dimension=dimension, where=f"{source}: transitions[{i}]")
            for i, tr in enumerate(data["transitions"])
        )
        tried = data.get("tried") or []
        certificate = data.get("certificate") or []
        if not isinstance(tried, list) or not isinstance(certificate, list):
            raise InputError(f"{source}: tried and certificate: expected lists of transitions")
        proven = data.get("proven")
        policy = (
            None
            if data.get("policy") is None
            else Policy.from_json(data["policy"], f"{source}: policy", coverage=data.get("coverage"))
        )
        timings = data.get("timings") or {}
        if not isinstance(timings, dict):
            raise InputError(f"{source}: timings: expected {{phase: seconds}}, got {_short(timings)}")
        certified = tuple(
            TriedTransition.from_json({**c, "ok": False} if isinstance(c, dict) else c, f"{source}: certificate[{i}]")
            for i, c in enumerate(certificate)
        )
        return cls(
            status=str(data["status"]),
            reason=str(data.get("reason") or ""),
            sequence=tuple(tuple(_names(s, f"{source}: sequence[{i}]")) for i, s in enumerate(sequence)),
            transitions=transitions,
            tried=tuple(TriedTransition.from_json(a, f"{source}: tried[{i}]") for i, a in enumerate(tried)),
            proven=None if proven is None else bool(proven),
            certificate=certified,
            verification=v,
            timings={str(k): x for k, x in timings.items()},
            extras={k: x for k, x in data.items() if k not in (*_PLAN_KEYS, "timings")},
            present=tuple(k for k in data if k in (*_PLAN_KEYS, "timings")),
            policy=policy,
        )


# the keys that come first in a file: what made it (a recorded session), for which fixture
_LEADING = ("source", "fixture", "fixture_sha256")


# -- the format --------------------------------------------------------------------------------------
MAX_ISSUES_SHOWN = 10  # problems of one plan file listed (then how many more)


def check_plan_document(data: Any, source: str, dimension: int | None = None) -> None:
    """Refuse a plan file's or recording's object that does not follow the format (:mod:`fixplan.plan_schema`).

    Raises :class:`~fixplan.errors.InputFileError` with one line per problem
    (``plan.json: transitions[2].wrench[0]: got 1e+308 (expected a force component [N] in ...)``).
    """
    from fixplan.errors import InputFileError, Issue
    from fixplan.plan_schema import validate_plan_document

    if not isinstance(data, dict) or "transitions" not in data and "status" not in data:
        raise InputError(f"{source}: {NOT_A_PLAN}")
    issues = validate_plan_document(data, dimension)
    if issues:
        more = len(issues) - MAX_ISSUES_SHOWN
        shown = issues[:MAX_ISSUES_SHOWN]
        if more > 0:
            shown.append(Issue("...", f"{more} more problems not shown"))
        raise InputFileError(source, shown)
