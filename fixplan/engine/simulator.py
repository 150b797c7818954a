"""The contact-dynamics simulator: one rigid workpiece among fixed locators.

``Simulator(fixture)`` integrates the workpiece with the compiled Moreau–Jean step of
:mod:`fixplan.engine.step` (detection, Delassus blocks, NSGS sweeps with exact local solvers,
angular-momentum update, position post-stabilisation). Wrenches are given as everywhere in
fixplan: force and moment about the body-frame origin, world axes, applied in addition to
gravity.

State conventions: the pose is ``T_world_body`` (:class:`~fixplan.spatial.Pose`); the twist is
``(v, ω)`` of the centre of mass in world axes (3D: 6 numbers, 2D: ``(vx, vy, ω)``).
"""

from __future__ import annotations

import csv
import math
import time
from collections.abc import Callable, Collection
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fixplan.aot import kernel
from fixplan.engine.encode import OBSTACLE_PLANE, encode, encode_obstacles
from fixplan.engine.mesh_slots import MeshSlots, MeshStepper, mesh_slots
from fixplan.engine.pin_slots import PinGeometry, PinSlots
from fixplan.engine.status import STATUS_CONVERGED, STATUS_MAX_ITER, STATUS_NONFINITE
from fixplan.errors import InputError, SolverError
from fixplan.geometry.mesh import Mesh
from fixplan.model import Fixture
from fixplan.settings import DEFAULT, EngineSettings
from fixplan.spatial import Pose, quaternion_wxyz_from_matrix, rot2, shift_wrench_by, tangent_basis

FloatArray = NDArray[np.float64]
_STEP = "fixplan.engine.step"  # the compiled step and loops (fixplan.aot: ahead of time when built)
_step2, _step3_into = kernel(_STEP, "step2"), kernel(_STEP, "step3_into")
_run2, _run3 = kernel(_STEP, "run2"), kernel(_STEP, "run3")
_LOADED: set[int] = set()  # dimensions whose compiled loop this process has already called
WrenchInput = ArrayLike | Callable[[float, "Simulator"], ArrayLike] | None


class PoseTwist(NamedTuple):
    """The workpiece's pose and twist: a ``(pose, twist)`` tuple with named fields.

    (Not a contact state: that is :data:`fixplan.contact_state.State`, the pressed contacts.)
    """

    pose: Pose  # T_world_body
    twist: FloatArray  # (v, ω) of the centre of mass, world axes


class BodyState(NamedTuple):
    """The body's state after the last step as plain copies: what a controller reads every tick.

    Writable float64 copies (the simulator's own arrays stay private and are never handed out),
    so a compiled controller sees the same array types as the engine's.
    """

    R_world_body: FloatArray  # (3, 3), or (2, 2) in 2D
    p_world: FloatArray  # body origin, world [m]
    v_com_world: FloatArray  # velocity of the centre of mass, world [m/s]
    omega_world: FloatArray  # angular velocity, world [rad/s]: (3,), or (1,) in 2D


ContactMode = Literal["open", "sticking", "sliding", "rolling"]  # a contact after a step


@dataclass(frozen=True)
class ContactReport:
    """One locator after the last step.

    The gap is the locator's at the body's current pose (the pose a trace samples beside it);
    the forces and the mode are the step's, which solved for the gaps at its start.
    """

    name: str
    gap_m: float  # at the pose after the step (the pose reported beside it) [m]
    normal_force_N: float
    force_world: FloatArray  # average contact force over the step, on the workpiece [N]
    spin_moment_Nm: float  # soft fingers only
    mode: ContactMode
    # a locator touching a mesh part at several places (a concave corner): each contact (the
    # fields above are their sum, the least gap); empty for a locator with one contact
    contacts: tuple[ContactTouch, ...] = ()

    def to_json(self) -> dict[str, Any]:
        out = {"name": self.name, "gap": self.gap_m, "normal_force": self.normal_force_N, "mode": self.mode}
        if self.contacts:
            out["contacts"] = [c.to_json() for c in self.contacts]
        return out


@dataclass(frozen=True)
class ContactTouch:
    """One of a locator's several contacts with a mesh part, after the last step."""

    gap_m: float  # at the start of the step [m]
    normal_force_N: float
    force_world: FloatArray  # on the workpiece [N]
    normal_world: FloatArray  # from the locator into the workpiece

    def to_json(self) -> dict[str, Any]:
        return {
            "gap": self.gap_m,
            "normal_force": self.normal_force_N,
            "normal": [float(x) for x in self.normal_world],
            "force": [float(x) for x in self.force_world],
        }


@dataclass(frozen=True)
class ObstacleReport:
    """One collision-only body (``[[obstacle]]``) after the last step: not a locator, never in contact states."""

    name: str
    gap_m: float  # the part's least gap to it at the current pose [m]
    force_world: FloatArray  # its average force on the workpiece over the last step [N]

    def to_json(self) -> dict[str, Any]:
        return {"name": self.name, "gap": self.gap_m, "force": [float(x) for x in self.force_world]}


@dataclass(frozen=True)
class StepInfo:
    """How the last step's contact problem was solved."""

    error: float  # FCLib residual reached
    iterations: int
    converged: bool
    failed_local_solves: int | None  # None after a compiled run(): its loop does not count them
    penetration_m: float  # deepest penetration after the step (0: none)
    names: tuple[str, ...]
    active_mask: NDArray[np.bool_]

    @property
    def active(self) -> tuple[str, ...]:
        """Names of the contacts the step solved for (within the detection margin)."""
        return tuple(n for n, a in zip(self.names, self.active_mask, strict=True) if a)


def _empty(*shape: int) -> FloatArray:
    return np.zeros(shape)


@dataclass
class Trajectory:
    """Recorded samples of a run: arrays with one row per sample.

    The first sample is the state the run started from, then one every ``record_every`` steps
    and the last. ``error`` and ``iterations`` describe the steps that produced the samples after
    the first (one entry fewer than ``time_s``).
    """

    names: list[str]
    dimension: int
    time_s: FloatArray = field(default_factory=lambda: _empty(0))
    position: FloatArray = field(default_factory=lambda: _empty(0, 3))  # body origin, world [m]
    orientation: FloatArray = field(default_factory=lambda: _empty(0, 4))  # quaternion wxyz (3D) or [angle_rad] (2D)
    velocity: FloatArray = field(default_factory=lambda: _empty(0, 6))  # (v, ω) of the centre of mass
    normal_force: FloatArray = field(default_factory=lambda: _empty(0, 0))  # per locator [N]
    # per locator [m], measured by the step that produced the sample at its start (before its
    # position update; the first sample's: at its pose). Exact gaps at a sample's pose:
    # fixplan.locating.locator_gaps, or Simulator.gaps_m() after the run.
    gap: FloatArray = field(default_factory=lambda: _empty(0, 0))
    error: FloatArray = field(default_factory=lambda: _empty(0))
    iterations: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    max_penetration_m: float = 0.0
    wall_time_s: float = 0.0
    steps: int = 0

    def arrays(self) -> dict[str, FloatArray]:
        return {
            "time": self.time_s,
            "position": self.position,
            "orientation": self.orientation,
            "velocity": self.velocity,
            "normal_force": self.normal_force,
            "gap": self.gap,
        }

    def to_csv(self, path: Path) -> None:
        """One row per sample: time, pose, twist, and per locator gap and normal force."""
        d = self.dimension
        pos = ["x", "y", "z"][:d]
        ori = ["qw", "qx", "qy", "qz"] if d == 3 else ["angle_rad"]
        vel = ["vx", "vy", "vz", "wx", "wy", "wz"] if d == 3 else ["vx", "vy", "w"]
        header = ["time", *pos, *ori, *vel]
        for n in self.names:
            header += [f"{n}_gap", f"{n}_normal_force"]
        k = len(self.names)
        per_locator = np.empty((len(self.time_s), 2 * k))
        per_locator[:, 0::2] = self.gap
        per_locator[:, 1::2] = self.normal_force
        table = np.column_stack([self.time_s, self.position, self.orientation, self.velocity, per_locator])

        def write(tmp: Path) -> None:
            with open(tmp, "w", newline="") as fh:
                out = csv.writer(fh)
                out.writerow(header)
                for row in table.tolist():
                    out.writerow([f"{x:.12g}" for x in row])

        from fixplan.files import write_output

        write_output(path, write)  # a temporary file renamed into place: never half a file


class _Samples:
    """Chunks of samples collected during a run, joined into a :class:`Trajectory` at the end."""

    def __init__(self) -> None:
        self.parts: dict[str, list[Any]] = {
            k: [] for k in ("time", "position", "orientation", "velocity", "normal_force", "gap", "error", "iterations")
        }

    def add(self, **chunks: Any) -> None:
        for k, v in chunks.items():
            self.parts[k].append(v)

    def trajectory(self, names: list[str], dimension: int, k: int) -> Trajectory:
        n_ori = 4 if dimension == 3 else 1
        n_nu = 6 if dimension == 3 else 3
        shapes = {"position": (0, dimension), "orientation": (0, n_ori), "velocity": (0, n_nu),
                  "normal_force": (0, k), "gap": (0, k), "time": (0,), "error": (0,), "iterations": (0,)}  # fmt: skip

        def join(key: str) -> Any:
            parts = self.parts[key]
            dtype = np.int64 if key == "iterations" else float
            if not parts:
                return np.zeros(shapes[key], dtype=dtype)
            if len(parts) == 1:  # one compiled chunk: its arrays as they are
                return np.asarray(parts[0], dtype=dtype).reshape((-1, *shapes[key][1:]))
            return np.concatenate([np.asarray(x, dtype=dtype).reshape((-1, *shapes[key][1:])) for x in parts])

        return Trajectory(
            names, dimension, join("time"), join("position"), join("orientation"), join("velocity"),
            join("normal_force"), join("gap"), join("error"), join("iterations"),
        )  # fmt: skip


@dataclass(frozen=True)
class WrenchSchedule:
    """A piecewise-constant applied wrench: ``wrenches[k]`` from ``times_s[k]`` to ``times_s[k + 1]``.

    The last row holds to the end of the run, the first also before ``times_s[0]``. Wrenches are
    about the body origin, world axes (3D: 6 numbers, 2D: 3), added to gravity. A run under a
    schedule is compiled end to end (:meth:`Simulator.run`); it is also a ``wrench(t, sim)``
    callable, evaluated at each step's start time.
    """

    times_s: FloatArray
    wrenches: FloatArray

    def __post_init__(self) -> None:
        t = np.array(self.times_s, dtype=float).reshape(-1)
        w = np.array(self.wrenches, dtype=float)
        if w.ndim == 1:
            w = w[None, :]
        if t.size == 0 or w.ndim != 2 or w.shape[0] != t.size or w.shape[1] not in (3, 6):
            raise InputError(
                f"a wrench schedule expects n times and n wrenches of 3 or 6 numbers, got {t.size} times and "
                f"wrenches of shape {w.shape}"
            )
        if not (np.isfinite(t).all() and np.isfinite(w).all()):
            raise InputError("a wrench schedule expects finite times and wrenches")
        if np.any(np.diff(t) <= 0):
            raise InputError(f"a wrench schedule expects increasing times, got {t.tolist()}")
        t.setflags(write=False)
        w.setflags(write=False)
        object.__setattr__(self, "times_s", t)
        object.__setattr__(self, "wrenches", w)

    def __call__(self, t: float, sim: Simulator | None = None) -> FloatArray:
        k = max(0, int(np.searchsorted(self.times_s, t, side="right")) - 1)
        return self.wrenches[k]


class Simulator:
    """Moreau–Jean simulation of a fixture's workpiece among its locators.

    Parameters
    ----------
    fixture : Fixture
        Must have ``[[locator]]`` entries (explicit contacts have no geometry to simulate).
    dt : float, optional
        Time step [s]; default ``[simulation] timestep``.
    tolerance : float, optional
        NSGS stopping residual; default ``[simulation] tolerance``.
    restitution : float, optional
        Newton restitution coefficient; default ``[simulation] restitution``.
    max_iterations : int, optional
        Cap on NSGS sweeps per step (the stop is the residual); default ``settings.max_iterations``.
    polish_after : int, optional
        NSGS sweeps before the Newton polish takes over (0: only after ``max_iterations``);
        default ``settings.polish_after``.
    polish_steps : int, optional
        Cap on the Newton steps of each polish (:mod:`fixplan.engine.polish`; 0: none); default
        ``settings.polish_steps``.
    margin_m : float, optional
        Contact detection margin [m]; default ``settings.margin_m``.
    settings : EngineSettings
        The engine's settings (:mod:`fixplan.settings`); the haptic loop passes the ``haptic``
        profile's. Explicit ``tolerance``, ``max_iterations`` and ``margin_m`` override it.
    """

    def __init__(
        self,
        fixture: Fixture,
        dt: float | None = None,
        tolerance: float | None = None,
        *,
        restitution: float | None = None,
        max_iterations: int | None = None,
        polish_after: int | None = None,
        polish_steps: int | None = None,
        margin_m: float | None = None,
        strict: bool = False,
        settings: EngineSettings = DEFAULT.engine,
    ):
        if not fixture.locators and not fixture.has_pins:
            raise InputError(
                f"{fixture.source} has only explicit [[contact]] entries: there is no geometry to simulate "
                "(add [[locator]] entries)"
            )
        self.fixture = fixture
        self.dt = float(dt if dt is not None else fixture.simulation.timestep_s)
        if tolerance is None:
            tolerance = settings.tolerance if settings.tolerance is not None else fixture.simulation.tolerance
        self.tolerance = float(tolerance)
        self.restitution = float(restitution if restitution is not None else fixture.simulation.restitution)
        if not (self.dt > 0 and math.isfinite(self.dt)):
            raise InputError(f"dt must be a positive number of seconds, got {dt}")
        if not (self.tolerance > 0):
            raise InputError(f"tolerance must be positive, got {tolerance}")
        self.settings = settings
        self.max_iterations = int(max_iterations if max_iterations is not None else settings.max_iterations)
        self.polish_after = int(settings.polish_after if polish_after is None else polish_after)
        self.polish_steps = int(settings.polish_steps if polish_steps is None else polish_steps)
        self.margin_m = float(margin_m if margin_m is not None else settings.margin_m)
        self.strict = strict
        wp = fixture.workpiece
        self.dimension = fixture.dimension
        self._kind, self._params, self._verts, self._enorm = encode(wp.shape)
        # a mesh part: the locators' contacts are detected before each step (several per locator in
        # a concave corner) and handed to the step as slots, in one compiled call (module mesh_slots)
        self._mesh = wp.shape if isinstance(wp.shape, Mesh) else None
        self._mesh_last: MeshSlots | None = None  # the last step's slots (the Python reference's)
        self._mesh_reference = False  # True: the Python reference of the mesh step (tests)
        self._mesh_state: dict[tuple[int, int], FloatArray] = {}  # (locator, rank) -> its warm start
        locs = fixture.locators
        # pins and bores: their contacts are detected before each step by the compiled closed forms and
        # handed to the step as slots (module pin_slots); one named row each after the locators'. A mesh
        # part's holes are analytic too: its step adds them to its locators' slots (module mesh_slots)
        self._pins = PinGeometry(fixture) if fixture.has_pins else None
        self._pin_last: PinSlots | None = None
        self._pin_state: dict[tuple[int, int, int], FloatArray] = {}  # (owner, kind, ordinal) -> its warm start
        pin_names = self._pins.names if self._pins is not None else []
        pin_mu = self._pins.friction if self._pins is not None else np.zeros(0)
        self._n_tips = len(locs)  # the locator tips the compiled step detects itself
        self.names = [loc.name for loc in locs] + pin_names
        self._names_t = tuple(self.names)
        self._loc_p = np.ascontiguousarray(np.reshape([loc.p_world for loc in locs], (-1, self.dimension)), dtype=float)
        self._loc_r = np.array([loc.radius_m for loc in locs], dtype=float)
        # collision-only bodies: the part's collision points against each, contacts after the
        # locators in the kernels' arrays (mu, tors, P, gaps ...), never in names or reports
        self._obs, self._slots, slot_mu = encode_obstacles(fixture, settings.rim_points)
        self._k_loc = len(self.names)  # the named rows: locators, then pins and bores
        self._mu = np.concatenate([[loc.friction for loc in locs], pin_mu, slot_mu])
        self._tors = np.concatenate([[loc.torsion_m for loc in locs], np.zeros(len(pin_mu) + len(slot_mu))])
        self._mesh_stepper = (
            MeshStepper(self._mesh, locs, self._obs, self._slots, slot_mu, self._pins)
            if self._mesh is not None
            else None
        )
        self._mass = wp.mass_kg
        self._Ib = np.ascontiguousarray(wp.inertia_body, dtype=float)
        self._Ib_inv = np.linalg.inv(self._Ib)
        self._com_b = np.asarray(wp.com_body, dtype=float)
        self._bound = wp.shape.bounding_radius + float(np.abs(self._com_b).max(initial=0.0))
        self.time_s = 0.0
        self.steps = 0
        k = self._k = len(self._mu)
        self._P = np.zeros((k, 4))
        self._active = np.zeros(k, dtype=np.bool_)
        self._u = np.zeros((k, 4))
        self._gap = np.zeros(k)
        self._nw = np.zeros((k, self.dimension))
        self.last: StepInfo | None = None
        self.max_penetration_m = 0.0
        self.set_state(fixture.start)

    # -- state ---------------------------------------------------------------------------------
    def set_state(self, pose: Pose | None = None, twist: ArrayLike | None = None) -> None:
        """Place the body (default: keep the pose) with a twist (default: at rest)."""
        d = self.dimension
        if pose is not None:
            self._R = np.array(pose.R_world_body, dtype=float)
            self._p = np.array(pose.p_world, dtype=float)
        if twist is None:
            twist = np.zeros(6 if d == 3 else 3)
        nu = np.asarray(twist, dtype=float)
        if nu.shape != ((6,) if d == 3 else (3,)):
            raise InputError(f"twist expects {6 if d == 3 else 3} numbers, got {nu.shape}")
        self._v = nu[:d].copy()
        self._w = nu[d:].copy() if d == 3 else float(nu[2])
        # a new state makes the previous step's impulses meaningless as a warm start
        self._P = np.zeros((self._k, 4))
        self._active = np.zeros(self._k, dtype=np.bool_)
        self._P_prev = np.zeros((self._k, 4))  # the step before (3D: extrapolated warm start)
        self._active_prev = np.zeros(self._k, dtype=np.bool_)
        self._mesh_state = {}
        self._mesh_last = None
        if self._mesh_stepper is not None:
            self._mesh_stepper.reset()
        self._pin_state = {}
        self._pin_last = None
        if pose is not None:
            # gaps at the new pose (until a step measures them): a report before any step is true
            from fixplan.locating import locator_contact

            wp = self.fixture.workpiece
            self._gap = np.concatenate(
                [[locator_contact(wp, self.pose, loc).gap_m for loc in self.fixture.locators], self._pin_gaps(),
                 self._obstacle_gaps()]
            )  # fmt: skip
        self._gaps_now: tuple[int, FloatArray] | None = None  # (steps, gaps at the current pose)

    @property
    def pose(self) -> Pose:
        return Pose(self._R, self._p)

    @property
    def n_tips(self) -> int:
        """How many of :attr:`names` are locator tips (the rest: pins, then bores)."""
        return self._n_tips

    @property
    def twist(self) -> FloatArray:
        """``(v, ω)`` of the centre of mass, world axes."""
        w = np.atleast_1d(np.asarray(self._w, dtype=float))
        return np.concatenate([self._v, w])

    @property
    def state(self) -> PoseTwist:
        """``(pose, twist)``, also readable as ``.pose`` and ``.twist``."""
        return PoseTwist(self.pose, self.twist)

    @property
    def body_state(self) -> BodyState:
        """Rotation, origin, centre-of-mass velocity and angular velocity, as copies."""
        return BodyState(self._R.copy(), self._p.copy(), self._v.copy(), np.atleast_1d(np.array(self._w, dtype=float)))

    @property
    def com_body(self) -> FloatArray:
        """Centre of mass in body coordinates [m] (a copy)."""
        return self._com_b.copy()

    @property
    def com_world(self) -> FloatArray:
        return self._p + self._R @ self._com_b

    # -- stepping ------------------------------------------------------------------------------
    def _external(self, wrench: ArrayLike | None) -> tuple[FloatArray, Any]:
        d = self.dimension
        g = self._mass * self.fixture.gravity
        if wrench is None:
            return g, (np.zeros(3) if d == 3 else 0.0)
        w = np.asarray(wrench, dtype=float)
        if w.shape != ((6,) if d == 3 else (3,)) or not np.isfinite(w).all():
            raise InputError(f"wrench expects {6 if d == 3 else 3} finite numbers, got {np.asarray(wrench).tolist()}")
        w_com = shift_wrench_by(w, self._R @ self._com_b)  # from the body origin to the centre of mass
        if d == 3:
            return g + w_com[:3], w_com[3:]
        return g + w_com[:2], float(w_com[2])

    def step(self, wrench: ArrayLike | None = None) -> StepInfo:
        """Advance one step under ``wrench`` (about the body origin) plus gravity."""
        f, tau = self._external(wrench)
        h = self.dt
        v = self._v
        w_norm = float(np.sqrt(np.dot(self._w, self._w))) if self.dimension == 3 else abs(float(self._w))
        speed = math.sqrt(float(v @ v)) + w_norm * self._bound
        margin = self.margin_m + 2.0 * h * speed
        if self._mesh is not None:
            err, iters, status, failures, pen = self._step_mesh(f, tau, margin)
        elif self._pins is not None:
            err, iters, status, failures, pen = self._step_pins(f, tau, margin)
        elif self.dimension == 3:
            err, iters, status, failures, pen = _step3_into(
                self._R, self._p, self._v, self._w, self._mass, self._Ib, self._Ib_inv, self._com_b, self._kind,
                self._params, self._verts, self._enorm, self._loc_p, self._loc_r, self._mu, self._tors, self._obs,
                self._slots, h, f, tau,
                self.restitution, margin, self.tolerance, self.max_iterations, self.polish_after, self.polish_steps, self._P, self._active, self._P_prev,
                self._active_prev, self._gap, self._u, self._nw, self._bound,
            )  # fmt: skip
        else:
            theta = math.atan2(self._R[1, 0], self._R[0, 0])
            out = _step2(
                theta, self._p, self._v, self._w, self._mass, float(self._Ib[0, 0]), self._com_b,
                self._kind, self._params, self._verts, self._enorm, self._loc_p, self._loc_r, self._mu, self._obs,
                self._slots, h, f, tau, self.restitution, margin, self.tolerance, self.max_iterations, self.polish_after, self.polish_steps, self._P, self._active,
                self._bound,
            )  # fmt: skip
            rot, p, v2, w2, P, active, gap, u, n_w, _pt, err, iters, status, failures, pen = out
            self._gap = gap
            if status != STATUS_NONFINITE:
                self._R, self._p, self._v, self._w = rot2(rot), p, v2, w2
                self._P, self._active, self._u, self._nw = P, active, u, n_w
        if status == STATUS_NONFINITE:
            raise SolverError(
                f"step {self.steps} at t = {self.time_s:.6g} s produced a non-finite state; the state was kept",
                extras={"error": err, "iterations": iters},
            )
        if status == STATUS_MAX_ITER and self.strict:
            raise SolverError(f"NSGS did not reach {self.tolerance:g} at t = {self.time_s:.6g} s (error {err:.3g})")
        self.time_s += h
        self.steps += 1
        if pen > self.max_penetration_m:
            self.max_penetration_m = pen
        self.last = StepInfo(
            float(err),
            int(iters),
            status == STATUS_CONVERGED,
            int(failures),
            float(pen),
            self._names_t,
            self._active[: self._k_loc].copy(),
        )
        return self.last

    def _step_mesh(self, f: FloatArray, tau: FloatArray, margin: float) -> tuple[float, int, int, int, float]:
        """One 3D step of a mesh part: one compiled call (:class:`.mesh_slots.MeshStepper`), detection included."""
        if self._mesh_reference or self._mesh_stepper is None:
            return self._step_mesh_reference(f, tau, margin)
        return self._mesh_stepper.step(self, f, tau, margin)

    def _step_mesh_reference(self, f: FloatArray, tau: FloatArray, margin: float) -> tuple[float, int, int, int, float]:
        """:meth:`_step_mesh` in Python: contacts as slots (:func:`.mesh_slots.mesh_slots`), then the compiled step.

        The slots of the locators come first, then the pins' (their closed forms, as
        :meth:`_step_pins` hands them over for a primitive part), then the fixture's own
        collision-only bodies' (as for a convex part). Each locator slot's warm start is carried by
        its ``(locator, rank)``, each pin slot's by its ``(pin, kind, ordinal)``. Afterwards the
        locator rows of the simulator's arrays hold each locator's contacts together: the least
        gap, any active, the summed normal impulse, the nearest's normal; the pins' rows as
        :meth:`_step_pins` writes them.
        """
        if self._mesh is None:  # pragma: no cover - step() calls it only for a mesh part
            raise SolverError("a mesh step was asked of a part that is not a mesh")
        ms = mesh_slots(self._mesh, self.fixture.locators, self._R, self._p, margin)
        ps = self._pins.slots(self._R, self._p, margin) if self._pins is not None else None
        n, kl, nt = len(ms), self._k_loc, self._n_tips
        m = len(ps) if ps is not None else 0
        # a mesh part's collision points are its vertices (5·10⁴ triangles: 2.5·10⁴ of them against
        # each obstacle, and the step's arrays grow with the square of the slots it is handed). Only
        # the points whose gap can be within the margin are handed over: the step treats the others
        # as open anyway, so the answer is the same (a lower bound of each gap decides)
        near = self._obstacle_points_near(margin)
        fix_mu = self._mu[kl:][near]
        shifted = self._slots[near].copy()
        shifted[:, 4] += n + m  # the fixture's obstacles follow the mesh's planes and the pins'
        pin_obs, pin_slots = (ps.obs, ps.slots.copy()) if ps is not None else (np.zeros((0, 16)), np.zeros((0, 5)))
        pin_slots[:, 4] += n
        pin_mu = self._pins.friction[ps.owner] if self._pins is not None and ps is not None else np.zeros(0)
        obs = np.ascontiguousarray(np.vstack([ms.obs, pin_obs, self._obs]).reshape(-1, 16))
        slots = np.ascontiguousarray(np.vstack([ms.slots, pin_slots, shifted]).reshape(-1, 5))
        mu = np.concatenate([[self.fixture.locators[i].friction for i in ms.locator], pin_mu, fix_mu])
        k = mu.shape[0]
        tors = np.zeros(k)  # a soft finger's torsion arm on each of its slots (a pin's contacts have none)
        tors[:n] = [self.fixture.locators[i].torsion_m for i in ms.locator]
        # warm start: per slot (P, active, P_prev, active_prev, u) from the slot of the same key
        P, P_prev, u = np.zeros((k, 4)), np.zeros((k, 4)), np.zeros((k, 4))
        act, act_prev = np.zeros(k, dtype=np.bool_), np.zeros(k, dtype=np.bool_)
        keys: list[Any] = [*ms.keys, *(ps.keys if ps is not None else [])]
        for j, key in enumerate(keys):
            old = (self._mesh_state if j < n else self._pin_state).get(key)
            if old is not None:
                P[j], P_prev[j], u[j] = old[0:4], old[4:8], old[8:12]
                act[j], act_prev[j] = bool(old[12]), bool(old[13])
        nm = n + m
        P[nm:], P_prev[nm:], u[nm:] = self._P[kl:][near], self._P_prev[kl:][near], self._u[kl:][near]
        act[nm:], act_prev[nm:] = self._active[kl:][near], self._active_prev[kl:][near]
        gap, n_w = np.zeros(k), np.zeros((k, 3))
        err, iters, status, failures, pen = _step3_into(
            self._R, self._p, self._v, self._w, self._mass, self._Ib, self._Ib_inv, self._com_b, self._kind,
            self._params, self._verts, self._enorm, np.zeros((0, 3)), np.zeros(0), mu, tors, obs,
            slots, self.dt, f, tau,
            self.restitution, margin, self.tolerance, self.max_iterations, self.polish_after, self.polish_steps, P, act, P_prev,
            act_prev, gap, u, n_w, self._bound,
        )  # fmt: skip
        self._mesh_last = ms
        self._mesh_slot_P, self._mesh_slot_active, self._mesh_slot_u = P[:n].copy(), act[:n].copy(), u[:n].copy()
        self._mesh_slot_n, self._mesh_slot_gap = n_w[:n].copy(), gap[:n].copy()
        state = {
            key: np.concatenate([P[j], P_prev[j], u[j], [float(act[j]), float(act_prev[j])]])
            for j, key in enumerate(keys)
        }
        self._mesh_state = {key: state[key] for key in ms.keys}
        # the obstacles' rows: the points handed over, the others open (their gap: beyond the margin)
        rows = kl + near
        for arr in (self._P, self._P_prev, self._u):
            arr[kl:] = 0.0
        self._active[kl:], self._active_prev[kl:] = False, False
        self._gap[kl:] = np.inf
        self._P[rows], self._P_prev[rows], self._u[rows] = P[nm:], P_prev[nm:], u[nm:]
        self._active[rows], self._active_prev[rows] = act[nm:], act_prev[nm:]
        self._gap[rows], self._nw[rows] = gap[nm:], n_w[nm:]
        # the locator rows: each locator's contacts together
        for i in range(nt):
            rows = np.flatnonzero(ms.locator == i)
            if rows.size == 0:  # pragma: no cover - every locator has a nearest contact
                continue
            on = rows[act[rows]]
            self._active[i] = on.size > 0
            self._gap[i] = float(gap[rows].min())
            self._P[i] = 0.0
            self._P[i, 0] = float(P[on, 0].sum()) if on.size else 0.0
            self._nw[i] = n_w[rows[0]]
            self._u[i] = u[rows[0]]
        if ps is not None:
            self._pin_rows(ps, slice(n, nm), P, act, u, n_w, gap)
            self._pin_state = {key: state[key] for key in ps.keys}
        return err, iters, status, failures, pen

    def _pin_rows(
        self, ps: PinSlots, rows: slice, P: FloatArray, act: NDArray[np.bool_], u: FloatArray, n_w: FloatArray,
        gap: FloatArray,
    ) -> None:  # fmt: skip
        """After a step with the pins' slots at ``rows`` of its arrays: the slots kept for the reports, each pin's named row.

        A pin's row holds its contacts together: its least gap over all of them (the closed forms'),
        any active, the summed normal impulse, the normal and velocity of its slot at that gap.
        """
        nt, kl = self._n_tips, self._k_loc
        self._pin_last = ps
        self._pin_slot_P, self._pin_slot_active, self._pin_slot_u = P[rows].copy(), act[rows].copy(), u[rows].copy()
        self._pin_slot_n, self._pin_slot_gap = n_w[rows].copy(), gap[rows].copy()
        named = slice(nt, kl)
        self._active[named], self._gap[named] = False, ps.least_gap_m
        self._P[named], self._P_prev[named], self._u[named] = 0.0, 0.0, 0.0
        slot_gap, slot_P, slot_act = gap[rows], P[rows, 0], act[rows]
        first = rows.start
        for j, i in enumerate(ps.owner.tolist()):  # few contacts: a loop is cheaper than grouping
            r = nt + i
            if slot_act[j]:
                self._active[r] = True
                self._P[r, 0] += slot_P[j]
            if slot_gap[j] <= self._gap[r]:
                self._gap[r] = slot_gap[j]
                self._nw[r], self._u[r] = n_w[first + j], u[first + j]

    def _pin_gaps(self) -> FloatArray:
        """Each pin's and bore's least gap at the current pose [m] (inf: none possible; empty without pins)."""
        if self._pins is None:
            return np.zeros(0)
        return self._pins.least_gaps_m(self._R, self._p)

    def _step_pins(self, f: FloatArray, tau: FloatArray, margin: float) -> tuple[float, int, int, int, float]:
        """One 3D step with pins or bores: their contacts as slots (:mod:`.pin_slots`), then the compiled step.

        The compiled step's rows: the locator tips (detected by the step itself), the pins' and
        bores' slots, the fixture's collision-only bodies. Each pin slot's warm start is carried by
        its ``(owner, kind, ordinal)``. Afterwards each pin's named row holds its contacts together:
        the least gap, any active, the summed normal impulse, the nearest's normal.
        """
        pins = self._pins
        if pins is None:  # pragma: no cover - step() calls it only with pins
            raise SolverError("a pin step was asked of a fixture without pins")
        ps = pins.slots(self._R, self._p, margin)
        nt, kl, n = self._n_tips, self._k_loc, len(ps)
        shifted = self._slots.copy()
        shifted[:, 4] += n  # the fixture's obstacles follow the pins' planes
        obs = np.ascontiguousarray(np.vstack([ps.obs, self._obs]).reshape(-1, 16))
        slots = np.ascontiguousarray(np.vstack([ps.slots, shifted]).reshape(-1, 5))
        mu = np.concatenate([self._mu[:nt], pins.friction[ps.owner], self._mu[kl:]])
        k = mu.shape[0]
        tors = np.concatenate([self._tors[:nt], np.zeros(k - nt)])
        # the locator tips' and the obstacles' rows are carried as they are (slices: no index arrays)
        tip, ob, own_ob = slice(0, nt), slice(nt + n, k), slice(kl, self._k)
        P, P_prev, u = np.zeros((k, 4)), np.zeros((k, 4)), np.zeros((k, 4))
        act, act_prev = np.zeros(k, dtype=np.bool_), np.zeros(k, dtype=np.bool_)
        gap, n_w = np.zeros(k), np.zeros((k, 3))
        for mine, theirs in ((tip, tip), (ob, own_ob)):
            P[mine], P_prev[mine], u[mine] = self._P[theirs], self._P_prev[theirs], self._u[theirs]
            act[mine], act_prev[mine] = self._active[theirs], self._active_prev[theirs]
            gap[mine], n_w[mine] = self._gap[theirs], self._nw[theirs]
        for j, key in enumerate(ps.keys):
            old = self._pin_state.get(key)
            if old is not None:
                P[nt + j], P_prev[nt + j], u[nt + j] = old[0:4], old[4:8], old[8:12]
                act[nt + j], act_prev[nt + j] = bool(old[12]), bool(old[13])
        err, iters, status, failures, pen = _step3_into(
            self._R, self._p, self._v, self._w, self._mass, self._Ib, self._Ib_inv, self._com_b, self._kind,
            self._params, self._verts, self._enorm, self._loc_p, self._loc_r, mu, tors, obs,
            slots, self.dt, f, tau,
            self.restitution, margin, self.tolerance, self.max_iterations, self.polish_after, self.polish_steps, P, act, P_prev,
            act_prev, gap, u, n_w, self._bound,
        )  # fmt: skip
        self._pin_state = {
            key: np.concatenate([P[nt + j], P_prev[nt + j], u[nt + j], [float(act[nt + j]), float(act_prev[nt + j])]])
            for j, key in enumerate(ps.keys)
        }
        for mine, theirs in ((tip, tip), (ob, own_ob)):
            self._P[theirs], self._P_prev[theirs], self._u[theirs] = P[mine], P_prev[mine], u[mine]
            self._active[theirs], self._active_prev[theirs] = act[mine], act_prev[mine]
            self._gap[theirs], self._nw[theirs] = gap[mine], n_w[mine]
        self._pin_rows(ps, slice(nt, nt + n), P, act, u, n_w, gap)  # each pin's named row: its contacts together
        return err, iters, status, failures, pen

    def _pin_contacts(self, i: int) -> list[tuple[FloatArray, float, FloatArray, float, float, float]]:
        """Pin or bore ``i``'s contacts in the last step: ``(force_world, normal force, normal, slip, gap, spin moment)`` each."""
        if self._mesh is not None and not self._mesh_reference and self._mesh_stepper is not None:
            out = []
            for row in self._mesh_stepper.pin_slots_of(i):  # the compiled mesh step's pin slots
                P, n = row[0:4], row[12:15].copy()
                on = bool(row[16]) and P[0] > 0.0
                t1, t2 = tangent_basis(n)
                force = (P[0] * n + P[1] * t1 + P[2] * t2) / self.dt if on else np.zeros(3)
                slip = float(np.hypot(row[9], row[10]))
                out.append((force, float(P[0]) / self.dt if on else 0.0, n, slip, float(row[15]), 0.0))
            return out
        ps = self._pin_last
        if ps is None:
            return []
        out = []
        for j in np.flatnonzero(ps.owner == i):
            n = self._pin_slot_n[j]
            P = self._pin_slot_P[j]
            on = bool(self._pin_slot_active[j]) and P[0] > 0.0
            t1, t2 = tangent_basis(n)
            force = (P[0] * n + P[1] * t1 + P[2] * t2) / self.dt if on else np.zeros(3)
            slip = float(np.hypot(self._pin_slot_u[j, 1], self._pin_slot_u[j, 2]))
            # (a pin's contacts have no spin row: their spin moment is 0, the last entry as a mesh contact's)
            out.append((force, float(P[0]) / self.dt if on else 0.0, n.copy(), slip, float(self._pin_slot_gap[j]), 0.0))
        return out

    def _obstacle_points_near(self, margin: float) -> NDArray[np.intp]:
        """Indices of the obstacle slots whose gap may be within ``margin`` at the current pose.

        A lower bound of each gap, vectorized: a plane's is exact (the point's height over it, less
        its radius), a box's the distance to its centre less its half-diagonal and the radius.
        """
        slots = self._slots
        if slots.shape[0] == 0:
            return np.zeros(0, dtype=np.intp)
        lower = np.empty(slots.shape[0])
        which = slots[:, 4]
        for j, ob in enumerate(self._obs):
            rows = which == j
            R_ob = ob[4:13].reshape(3, 3)
            # Rᵀ (R_part p_body + p − o), as one small matrix product per obstacle
            local = slots[rows, :3] @ (R_ob.T @ self._R).T + R_ob.T @ (self._p - ob[1:4])
            if ob[0] == OBSTACLE_PLANE:
                lower[rows] = local[:, 2]
            else:
                lower[rows] = np.sqrt(np.einsum("ki,ki->k", local, local)) - float(np.sqrt(ob[13:16] @ ob[13:16]))
        lower -= slots[:, 3]
        return np.flatnonzero(lower <= margin)

    def _mesh_contacts(self, i: int) -> list[tuple[FloatArray, float, FloatArray, float, float, float]]:
        """Locator ``i``'s contacts in the last step: ``(force_world, normal force, normal, slip, gap, spin moment)`` each."""
        tors = float(self._tors[i])
        if not self._mesh_reference and self._mesh_stepper is not None:
            out = []
            for row in self._mesh_stepper.slots_of(i):
                P, n = row[0:4], row[12:15].copy()
                on = bool(row[16]) and P[0] > 0.0
                t1, t2 = tangent_basis(n)
                force = (P[0] * n + P[1] * t1 + P[2] * t2) / self.dt if on else np.zeros(3)
                slip = float(np.hypot(row[9], row[10]))
                spin = float(P[3] * tors / self.dt) if on and tors > 0.0 else 0.0
                out.append((force, float(P[0]) / self.dt if on else 0.0, n, slip, float(row[15]), spin))
            return out
        ms = self._mesh_last
        if ms is None:
            return []
        out = []
        for j in np.flatnonzero(ms.locator == i):
            n = self._mesh_slot_n[j]
            P = self._mesh_slot_P[j]
            on = bool(self._mesh_slot_active[j]) and P[0] > 0.0
            t1, t2 = tangent_basis(n)
            force = (P[0] * n + P[1] * t1 + P[2] * t2) / self.dt if on else np.zeros(3)
            slip = float(np.hypot(self._mesh_slot_u[j, 1], self._mesh_slot_u[j, 2]))
            spin = float(P[3] * tors / self.dt) if on and tors > 0.0 else 0.0
            out.append(
                (force, float(P[0]) / self.dt if on else 0.0, n.copy(), slip, float(self._mesh_slot_gap[j]), spin)
            )
        return out

    def pressed(self, min_force_N: float = 1e-9) -> tuple[str, ...]:
        """Names of the locators that pushed on the workpiece in the last step (normal force > min)."""
        kl = self._k_loc
        f = self._P[:kl, 0] / self.dt
        return tuple(n for n, a, fn in zip(self.names, self._active[:kl], f, strict=True) if a and fn > min_force_N)

    def in_contact(
        self, min_force_N: float, max_gap_m: float, held: Collection[str] = (), hold_gap_m: float = 0.0
    ) -> tuple[str, ...]:
        """Locators in contact after the last step.

        In contact: pressing (normal force > ``min_force_N``) or touching (gap at the start of the
        step ≤ ``max_gap_m``, e.g. a contact that friction leaves unloaded). A locator in ``held``
        (the last observation's) stays in contact until its gap exceeds ``hold_gap_m``: a
        hysteresis, so that a contact friction holds a few micrometres open is not lost and found
        again, while a locator the part only passes near is not found.
        """
        kl = self._k_loc
        f = self._P[:kl, 0] / self.dt
        return tuple(
            n
            for n, a, fn, g in zip(self.names, self._active[:kl], f, self._gap[:kl], strict=True)
            if a and (fn > min_force_N or g <= max_gap_m or (n in held and g <= hold_gap_m))
        )

    def gaps_m(self) -> FloatArray:
        """Every locator's signed gap at the current pose [m] (negative: penetration).

        The step's own gaps (:meth:`in_contact` uses them) are measured at its start, before the
        position update; these are the current pose's, computed exactly
        (:func:`fixplan.locating.locator_gaps`, once per step when asked).
        """
        cached = self._gaps_now
        if cached is None or cached[0] != self.steps:
            from fixplan.locating import locator_gaps

            gaps = locator_gaps(self.fixture.workpiece, self.pose, self.fixture.locators)
            cached = (self.steps, np.concatenate([gaps, self._pin_gaps()]))
            self._gaps_now = cached
        return cached[1].copy()

    def contacts(self) -> list[ContactReport]:
        """Per-locator gap (at the current pose), force and mode (the last step's)."""
        h = self.dt
        reports = []
        gaps = self.gaps_m()
        omega = float(np.linalg.norm(np.atleast_1d(self._w)))
        for i, name in enumerate(self.names):
            Pn = float(self._P[i, 0])
            n = self._nw[i]
            d = self.dimension
            if i >= self._n_tips:  # a pin or a bore
                reports.append(self._mesh_report(i, name, float(gaps[i]), omega, self._pin_contacts(i - self._n_tips)))
                continue
            if self._mesh is not None:
                reports.append(self._mesh_report(i, name, float(gaps[i]), omega))
                continue
            if not self._active[i] or Pn <= 0.0:
                reports.append(ContactReport(name, float(gaps[i]), 0.0, np.zeros(d), 0.0, "open"))
                continue
            if d == 3:
                t1, t2 = tangent_basis(n)
                force = (Pn * n + self._P[i, 1] * t1 + self._P[i, 2] * t2) / h
                slip = float(np.hypot(self._u[i, 1], self._u[i, 2]))
                spin = float(self._P[i, 3] * self._tors[i] / h) if self._tors[i] > 0 else 0.0
            else:
                t = np.array([-n[1], n[0]])
                force = (Pn * n + self._P[i, 1] * t) / h
                slip = abs(float(self._u[i, 1]))
                spin = 0.0
            slip_tol, spin_tol = self.settings.slip_mps, self.settings.spin_radps
            mode: ContactMode = "sliding" if slip > slip_tol else ("rolling" if omega > spin_tol else "sticking")
            reports.append(ContactReport(name, float(gaps[i]), Pn / h, force, spin, mode))
        return reports

    def _mesh_report(
        self, i: int, name: str, gap_m: float, omega: float,
        touches: list[tuple[FloatArray, float, FloatArray, float, float, float]] | None = None,
    ) -> ContactReport:  # fmt: skip
        """A mesh part's locator (or a pin, ``touches`` given): its contacts' forces summed, one :class:`ContactTouch` per contact."""
        touches = self._mesh_contacts(i) if touches is None else touches
        force = sum((t[0] for t in touches), np.zeros(3))
        fn = sum(t[1] for t in touches)
        each = tuple(ContactTouch(g, f_n, fw, nn) for fw, f_n, nn, _s, g, _m in touches) if len(touches) > 1 else ()
        if fn <= 0.0:
            return ContactReport(name, gap_m, 0.0, np.zeros(3), 0.0, "open", each)
        slip = max(t[3] for t in touches if t[1] > 0.0)
        slip_tol, spin_tol = self.settings.slip_mps, self.settings.spin_radps
        mode: ContactMode = "sliding" if slip > slip_tol else ("rolling" if omega > spin_tol else "sticking")
        spin = sum(t[5] for t in touches)  # a soft finger's spin moments about its contacts' normals
        return ContactReport(name, gap_m, fn, force, spin, mode, each)

    # -- collision-only bodies ---------------------------------------------------------------------
    def _obstacle_gaps(self) -> FloatArray:
        """Gap of every collision point to its obstacle at the current pose [m] (NumPy reference)."""
        from fixplan.geometry.collision import obstacle_gap

        d, pose = self.dimension, self.pose
        out = np.empty(self._slots.shape[0])
        for j, row in enumerate(self._slots):
            ob = self._obs[int(row[d + 1])]
            R = ob[1 + d : 1 + d + d * d].reshape(d, d)
            x = pose.point_world_from_body(row[:d])
            out[j] = obstacle_gap(int(ob[0]), R, ob[1 : 1 + d], ob[1 + d + d * d :], x, float(row[d]))[0]
        return out

    def obstacle_gap_m(self) -> float:
        """The least gap of the part to any collision-only body at the current pose [m] (inf: none)."""
        return float(self._obstacle_gaps().min(initial=np.inf))

    def obstacle_force_world(self) -> FloatArray:
        """The total force the collision-only bodies exerted on the part in the last step [N], world axes."""
        return sum((r.force_world for r in self.obstacles()), np.zeros(self.dimension))

    def obstacles(self) -> list[ObstacleReport]:
        """Per collision-only body: the part's least gap to it (current pose) and its force (the last step's)."""
        d, h, kl = self.dimension, self.dt, self._k_loc
        gaps = self._obstacle_gaps()
        out = []
        for j, ob in enumerate(self.fixture.obstacles):
            rows = np.flatnonzero(self._slots[:, d + 1] == j)
            force = np.zeros(d)
            for i in rows + kl:
                if self._active[i] and self._P[i, 0] > 0.0:
                    n = self._nw[i]
                    force += (self._P[i, 0] * n + self._P[i, 1:d] @ tangent_basis(n)) / h
            out.append(ObstacleReport(ob.name, float(gaps[rows].min(initial=np.inf)), force))
        return out

    def run(
        self,
        duration_s: float,
        wrench: WrenchInput = None,
        *,
        record_every: int = 1,
        progress: Callable[[int], None] | None = None,
    ) -> Trajectory:
        """Step for ``duration_s`` under a wrench; record samples every ``record_every`` steps.

        ``wrench``: ``None`` (gravity only), a constant wrench, a :class:`WrenchSchedule` (both
        compiled end to end: no Python per step, 2D and 3D) or a callable ``wrench(t, sim)``,
        which is evaluated from Python before every step.
        """
        if not (duration_s >= 0 and math.isfinite(duration_s)):
            raise InputError(f"duration must be a non-negative number of seconds, got {duration_s}")
        n_steps = int(round(duration_s / self.dt))
        every = max(1, int(record_every))
        if callable(wrench) and not isinstance(wrench, WrenchSchedule):
            return self._run_python(n_steps, wrench, every, progress)
        if self._mesh is not None or self._pins is not None:  # per-step detection outside run_compiled: Python's loop
            times, table = self._schedule(wrench)
            schedule = WrenchSchedule(times, table)
            return self._run_python(n_steps, lambda t, _sim: schedule(t), every, progress)
        return self._run_compiled(n_steps, self._schedule(wrench), every, progress)

    def _schedule(self, wrench: ArrayLike | WrenchSchedule | None) -> tuple[FloatArray, FloatArray]:
        """``(times, wrenches)`` for the compiled loops, checked against the dimension."""
        n = 6 if self.dimension == 3 else 3
        if wrench is None:
            return np.zeros(1), np.zeros((1, n))
        if isinstance(wrench, WrenchSchedule):
            if wrench.wrenches.shape[1] != n:
                raise InputError(f"wrench schedule expects {n} numbers per wrench, got {wrench.wrenches.shape[1]}")
            return np.ascontiguousarray(wrench.times_s), np.ascontiguousarray(wrench.wrenches)
        w = np.asarray(wrench, dtype=float)
        if w.shape != (n,) or not np.isfinite(w).all():
            raise InputError(f"wrench expects {n} finite numbers, got {np.asarray(wrench).tolist()}")
        return np.zeros(1), w.reshape(1, n).copy()

    def _run_python(
        self, n_steps: int, wrench: Callable[[float, Simulator], ArrayLike], every: int,
        progress: Callable[[int], None] | None,
    ) -> Trajectory:  # fmt: skip
        """A run under a Python callable: one :meth:`step` per step."""
        samples = _Samples()
        self._record(samples)
        t0 = time.perf_counter()
        for s in range(1, n_steps + 1):
            info = self.step(wrench(self.time_s, self))
            if s % every == 0 or s == n_steps:
                self._record(samples)
                samples.add(error=[info.error], iterations=[info.iterations])
            if progress is not None and s % 1000 == 0:
                progress(1000)
        traj = samples.trajectory(list(self.names), self.dimension, len(self.names))
        traj.wall_time_s = time.perf_counter() - t0
        traj.steps = n_steps
        traj.max_penetration_m = self.max_penetration_m
        return traj

    def _run_compiled(
        self, n_steps: int, schedule: tuple[FloatArray, FloatArray], every: int,
        progress: Callable[[int], None] | None,
    ) -> Trajectory:  # fmt: skip
        """A run as compiled loops of about 5000 steps (no Python per step)."""
        times, table = schedule
        gravity_f = self._mass * np.asarray(self.fixture.gravity, dtype=float)
        samples = _Samples()  # the kernels also record the initial state (first chunk)
        chunk = max(every, (5000 // every) * every)
        done = 0
        wall = 0.0
        status = STATUS_CONVERGED
        last_err, last_it = 0.0, 0  # a run of 0 steps solved nothing
        d = self.dimension
        if n_steps == 0:
            self._record(samples)
        elif d not in _LOADED:
            # load the compiled loop (numba's cache: ~0.5 s, once per process) outside the timing
            self._call_kernel(0, every, True, times, table, gravity_f)
            _LOADED.add(d)
        while done < n_steps:
            n = min(chunk, n_steps - done)
            t0 = time.perf_counter()
            out = self._call_kernel(n, every, done == 0, times, table, gravity_f)
            rt, rp, rori, rnu, rfn, rgap, rerr, rit, t_end, k_done, status_k, pen, worst_k, l_err, l_it = out
            wall += time.perf_counter() - t0
            kl = self._k_loc  # the locators' columns (obstacle contacts follow them)
            samples.add(time=rt, position=rp, orientation=rori, velocity=rnu, normal_force=rfn[:, :kl],
                        gap=rgap[:, :kl], error=rerr, iterations=rit)  # fmt: skip
            self.time_s = float(t_end)
            self.steps += int(k_done)
            done += int(k_done)
            self.max_penetration_m = max(self.max_penetration_m, float(pen))
            if k_done > 0:
                last_err, last_it = l_err, l_it
            if status_k == STATUS_NONFINITE:
                raise SolverError(
                    f"step {self.steps} at t = {self.time_s:.6g} s produced a non-finite state; the state before it was kept"
                )
            if status_k == STATUS_MAX_ITER:
                status = status_k
                if self.strict:
                    raise SolverError(f"NSGS did not reach {self.tolerance:g} in some step (worst error {worst_k:.3g})")
            if progress is not None:
                progress(n)
        traj = samples.trajectory(list(self.names), d, len(self.names))
        traj.max_penetration_m = self.max_penetration_m
        traj.wall_time_s = wall
        traj.steps = n_steps
        if n_steps > 0:
            self.last = StepInfo(
                float(last_err), int(last_it), status == STATUS_CONVERGED, None, float(self.max_penetration_m),
                self._names_t, self._active[: self._k_loc].copy(),
            )  # fmt: skip
        return traj

    def _call_kernel(
        self, n: int, every: int, first: bool, times: FloatArray, table: FloatArray, gravity_f: FloatArray
    ) -> tuple[Any, ...]:
        """``n`` compiled steps (3D: state updated in place; 2D: stored back here); the samples and figures."""
        if self.dimension == 3:
            return _run3(  # type: ignore[no-any-return]
                n, every, first, self.time_s, self._R, self._p, self._v, self._w, self._mass, self._Ib,
                self._Ib_inv, self._com_b, self._kind, self._params, self._verts, self._enorm, self._loc_p,
                self._loc_r, self._mu, self._tors, self._obs, self._slots, self.dt, gravity_f, times, table, self.restitution,
                self.margin_m, self._bound, self.tolerance, self.max_iterations, self.polish_after, self.polish_steps, self._P, self._active,
                self._P_prev, self._active_prev, self._gap, self._u, self._nw,
            )  # fmt: skip
        theta = math.atan2(self._R[1, 0], self._R[0, 0])
        out = _run2(
            n, every, first, self.time_s, theta, self._p, self._v, float(self._w), self._mass,
            float(self._Ib[0, 0]), self._com_b, self._kind, self._params, self._verts, self._enorm,
            self._loc_p, self._loc_r, self._mu, self._obs, self._slots, self.dt, gravity_f, times, table, self.restitution,
            self.margin_m, self._bound, self.tolerance, self.max_iterations, self.polish_after, self.polish_steps, self._P, self._active, self._gap,
        )  # fmt: skip
        (rt, rp, rori, rnu, rfn, rgap, rerr, rit, th, p2, v2, w2, P2, act2, gap2, u2, nw2,
         t_end, k_done, status_k, pen, worst_k, l_err, l_it) = out  # fmt: skip
        if k_done > 0 or status_k == STATUS_NONFINITE:
            self._gap = gap2
        if k_done > 0:
            self._R, self._p, self._v, self._w = rot2(th), p2, v2, float(w2)
            self._P, self._active, self._u, self._nw = P2, act2, u2, nw2
        return rt, rp, rori, rnu, rfn, rgap, rerr, rit, t_end, k_done, status_k, pen, worst_k, l_err, l_it

    def _record(self, samples: _Samples) -> None:
        """The current state as one sample (the residual and sweeps are added by the caller)."""
        if self.dimension == 3:
            ori = quaternion_wxyz_from_matrix(self._R)
        else:
            ori = np.array([math.atan2(self._R[1, 0], self._R[0, 0])])
        samples.add(
            time=[self.time_s], position=self._p.copy(), orientation=ori, velocity=self.twist,
            normal_force=np.where(self._active, self._P[:, 0] / self.dt, 0.0)[: self._k_loc],
            gap=self._gap[: self._k_loc].copy(),
        )  # fmt: skip
