"""The contact-dynamics simulator: one rigid workpiece among fixed locators.

``Simulator(fixture)`` integrates the workpiece with the compiled Moreau–Jean step of
:mod:`fixplan.engine.step` (detection, Delassus blocks, NSGS sweeps with exact local solvers,
angular-momentum update, position post-stabilisation). Wrenches are given as everywhere in
fixplan: force and moment about the body-frame origin, world axes, applied in addition to
gravity.

State conventions: the pose is ``T_world_body`` (:class:`~fixplan.pose.Pose`); the twist is
``(v, ω)`` of the centre of mass in world axes (3D: 6 numbers, 2D: ``(vx, vy, ω)``).
"""

from __future__ import annotations

import csv
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fixplan.engine import step as kernels
from fixplan.engine.detect import encode
from fixplan.errors import InputError, SolverError
from fixplan.fixture import Fixture
from fixplan.pose import Pose, quaternion_wxyz_from_matrix, rot2

FloatArray = NDArray[np.float64]
WrenchInput = ArrayLike | Callable[[float, "Simulator"], ArrayLike] | None


class State(NamedTuple):
    """The workpiece's state: a ``(pose, twist)`` tuple with named fields."""

    pose: Pose  # T_world_body
    twist: FloatArray  # (v, ω) of the centre of mass, world axes


@dataclass(frozen=True)
class ContactReport:
    """One locator after the last step."""

    name: str
    gap_m: float  # at the start of the step [m]
    normal_force_N: float
    force_world: FloatArray  # average contact force over the step, on the workpiece [N]
    spin_moment_Nm: float  # soft fingers only
    mode: str  # "open" | "sticking" | "sliding" | "rolling"

    def to_json(self) -> dict[str, Any]:
        return {"name": self.name, "gap": self.gap_m, "normal_force": self.normal_force_N, "mode": self.mode}


@dataclass(frozen=True)
class StepInfo:
    """How the last step's contact problem was solved."""

    error: float  # FCLib residual reached
    iterations: int
    converged: bool
    failed_local_solves: int
    penetration_m: float  # deepest penetration after the step (0: none)
    names: tuple[str, ...]
    active_mask: NDArray[np.bool_]

    @property
    def active(self) -> tuple[str, ...]:
        """Names of the contacts the step solved for (within the detection margin)."""
        return tuple(n for n, a in zip(self.names, self.active_mask, strict=True) if a)


@dataclass
class Trajectory:
    """Recorded samples of a run (one row per recorded step)."""

    names: list[str]
    dimension: int
    time_s: list[float] = field(default_factory=list)
    position: list[FloatArray] = field(default_factory=list)  # body origin, world [m]
    orientation: list[FloatArray] = field(default_factory=list)  # quaternion wxyz (3D) or [angle_rad] (2D)
    velocity: list[FloatArray] = field(default_factory=list)  # (v, ω) of the centre of mass
    normal_force: list[FloatArray] = field(default_factory=list)  # per locator [N]
    gap: list[FloatArray] = field(default_factory=list)  # per locator [m]
    error: list[float] = field(default_factory=list)
    iterations: list[int] = field(default_factory=list)
    max_penetration_m: float = 0.0
    wall_time_s: float = 0.0
    steps: int = 0

    def arrays(self) -> dict[str, FloatArray]:
        return {
            "time": np.array(self.time_s),
            "position": np.array(self.position),
            "orientation": np.array(self.orientation),
            "velocity": np.array(self.velocity),
            "normal_force": np.array(self.normal_force),
            "gap": np.array(self.gap),
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
        with open(path, "w", newline="") as fh:
            out = csv.writer(fh)
            out.writerow(header)
            for i, t in enumerate(self.time_s):
                row = [t, *self.position[i], *self.orientation[i], *self.velocity[i]]
                for k in range(len(self.names)):
                    row += [self.gap[i][k], self.normal_force[i][k]]
                out.writerow([f"{x:.12g}" for x in row])


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
    max_iterations : int
        Cap on NSGS sweeps per step (the stop is the residual).
    """

    def __init__(
        self,
        fixture: Fixture,
        dt: float | None = None,
        tolerance: float | None = None,
        *,
        restitution: float | None = None,
        max_iterations: int = 2000,
        margin_m: float = 1e-4,
        strict: bool = False,
    ):
        if not fixture.locators:
            raise InputError(
                f"{fixture.source} has only explicit [[contact]] entries: there is no geometry to simulate "
                "(add [[locator]] entries)"
            )
        self.fixture = fixture
        self.dt = float(dt if dt is not None else fixture.simulation.timestep_s)
        self.tolerance = float(tolerance if tolerance is not None else fixture.simulation.tolerance)
        self.restitution = float(restitution if restitution is not None else fixture.simulation.restitution)
        if not (self.dt > 0 and math.isfinite(self.dt)):
            raise InputError(f"dt must be a positive number of seconds, got {dt}")
        if not (self.tolerance > 0):
            raise InputError(f"tolerance must be positive, got {tolerance}")
        self.max_iterations = int(max_iterations)
        self.margin_m = float(margin_m)
        self.strict = strict
        wp = fixture.workpiece
        self.dimension = fixture.dimension
        self._kind, self._params, self._verts, self._enorm = encode(wp.shape)
        locs = fixture.locators
        self.names = [loc.name for loc in locs]
        self._names_t = tuple(self.names)
        self._loc_p = np.ascontiguousarray([loc.p_world for loc in locs], dtype=float)
        self._loc_r = np.array([loc.radius_m for loc in locs])
        self._mu = np.array([loc.friction for loc in locs])
        self._tors = np.array([loc.torsion_m for loc in locs])
        self._mass = wp.mass_kg
        self._Ib = np.ascontiguousarray(wp.inertia_body, dtype=float)
        self._Ib_inv = np.linalg.inv(self._Ib)
        self._com_b = np.asarray(wp.com_body, dtype=float)
        self._bound = wp.shape.bounding_radius + float(np.abs(self._com_b).max(initial=0.0))
        self.time_s = 0.0
        self.steps = 0
        k = len(locs)
        self._P = np.zeros((k, 4))
        self._active = np.zeros(k, dtype=np.bool_)
        self._u = np.zeros((k, 4))
        self._gap = np.zeros(k)
        self._nw = np.zeros((k, self.dimension))
        self.last: StepInfo | None = None
        self._state3 = np.zeros((4, 3, 3))
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
        self._P = np.zeros((len(self.names), 4))
        self._active = np.zeros(len(self.names), dtype=np.bool_)
        if pose is not None:
            # gaps at the new pose (until a step measures them): a report before any step is true
            from fixplan.locating import locator_contact

            wp = self.fixture.workpiece
            self._gap = np.array([locator_contact(wp, self.pose, loc).gap_m for loc in self.fixture.locators])

    @property
    def pose(self) -> Pose:
        return Pose(self._R, self._p)

    @property
    def twist(self) -> FloatArray:
        """``(v, ω)`` of the centre of mass, world axes."""
        w = np.atleast_1d(np.asarray(self._w, dtype=float))
        return np.concatenate([self._v, w])

    @property
    def state(self) -> State:
        """``(pose, twist)``, also readable as ``.pose`` and ``.twist``."""
        return State(self.pose, self.twist)

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
        o = -(self._R @ self._com_b)  # body origin relative to the centre of mass
        if d == 3:
            F = w[:3]
            cross = np.array([o[1] * F[2] - o[2] * F[1], o[2] * F[0] - o[0] * F[2], o[0] * F[1] - o[1] * F[0]])
            return g + F, w[3:] + cross
        return g + w[:2], float(w[2] + o[0] * w[1] - o[1] * w[0])

    def step(self, wrench: ArrayLike | None = None) -> StepInfo:
        """Advance one step under ``wrench`` (about the body origin) plus gravity."""
        f, tau = self._external(wrench)
        h = self.dt
        v = self._v
        w_norm = float(np.sqrt(np.dot(self._w, self._w))) if self.dimension == 3 else abs(float(self._w))
        speed = math.sqrt(float(v @ v)) + w_norm * self._bound
        margin = self.margin_m + 2.0 * h * speed
        if self.dimension == 3:
            st = self._state3
            st[0] = self._R
            st[1, 0], st[1, 1], st[1, 2] = self._p, self._v, self._w
            err, iters, status, failures, pen = kernels.step3_into(
                st, self._mass, self._Ib, self._Ib_inv, self._com_b, self._kind, self._params, self._verts,
                self._enorm, self._loc_p, self._loc_r, self._mu, self._tors, h, f, tau, self.restitution, margin,
                self.tolerance, self.max_iterations, self._P, self._active, self._gap, self._u, self._nw, self._bound,
            )  # fmt: skip
            if status != kernels.STATUS_NONFINITE:
                self._R, self._p, self._v, self._w = st[0].copy(), st[1, 0].copy(), st[1, 1].copy(), st[1, 2].copy()
        else:
            theta = math.atan2(self._R[1, 0], self._R[0, 0])
            out = kernels.step2(
                theta, self._p, self._v, self._w, self._mass, float(self._Ib[0, 0]), self._com_b,
                self._kind, self._params, self._verts, self._enorm, self._loc_p, self._loc_r, self._mu,
                h, f, tau, self.restitution, margin, self.tolerance, self.max_iterations, self._P, self._active,
                self._bound,
            )  # fmt: skip
            rot, p, v2, w2, P, active, gap, u, n_w, _pt, err, iters, status, failures, pen = out
            self._gap = gap
            if status != kernels.STATUS_NONFINITE:
                self._R, self._p, self._v, self._w = rot2(rot), p, v2, w2
                self._P, self._active, self._u, self._nw = P, active, u, n_w
        if status == kernels.STATUS_NONFINITE:
            raise SolverError(
                f"step {self.steps} at t = {self.time_s:.6g} s produced a non-finite state; the state was kept",
                extras={"error": err, "iterations": iters},
            )
        if status == kernels.STATUS_NOT_CONVERGED and self.strict:
            raise SolverError(f"NSGS did not reach {self.tolerance:g} at t = {self.time_s:.6g} s (error {err:.3g})")
        self.time_s += h
        self.steps += 1
        if pen > self.max_penetration_m:
            self.max_penetration_m = pen
        self.last = StepInfo(
            float(err),
            int(iters),
            status == kernels.STATUS_OK,
            int(failures),
            float(pen),
            self._names_t,
            self._active.copy(),
        )
        return self.last

    def pressed(self, min_force_N: float = 1e-9) -> tuple[str, ...]:
        """Names of the locators that pushed on the workpiece in the last step (normal force > min)."""
        f = self._P[:, 0] / self.dt
        return tuple(n for n, a, fn in zip(self.names, self._active, f, strict=True) if a and fn > min_force_N)

    def in_contact(self, min_force_N: float, max_gap_m: float) -> tuple[str, ...]:
        """Locators in contact after the last step.

        In contact: pressing (normal force > ``min_force_N``) or touching (gap at the start of the
        step ≤ ``max_gap_m``, e.g. a contact that friction leaves unloaded).
        """
        f = self._P[:, 0] / self.dt
        return tuple(
            n
            for n, a, fn, g in zip(self.names, self._active, f, self._gap, strict=True)
            if a and (fn > min_force_N or g <= max_gap_m)
        )

    def contacts(self) -> list[ContactReport]:
        """Per-locator gap, force and mode after the last step."""
        h = self.dt
        reports = []
        omega = float(np.linalg.norm(np.atleast_1d(self._w)))
        for i, name in enumerate(self.names):
            Pn = float(self._P[i, 0])
            n = self._nw[i]
            d = self.dimension
            if not self._active[i] or Pn <= 0.0:
                reports.append(ContactReport(name, float(self._gap[i]), 0.0, np.zeros(d), 0.0, "open"))
                continue
            if d == 3:
                from fixplan.kinematics import tangent_basis

                t1, t2 = tangent_basis(n)
                force = (Pn * n + self._P[i, 1] * t1 + self._P[i, 2] * t2) / h
                slip = float(np.hypot(self._u[i, 1], self._u[i, 2]))
                spin = float(self._P[i, 3] * self._tors[i] / h) if self._tors[i] > 0 else 0.0
            else:
                t = np.array([-n[1], n[0]])
                force = (Pn * n + self._P[i, 1] * t) / h
                slip = abs(float(self._u[i, 1]))
                spin = 0.0
            slip_tol = 1e-7
            mode = "sliding" if slip > slip_tol else ("rolling" if omega > 1e-6 else "sticking")
            reports.append(ContactReport(name, float(self._gap[i]), Pn / h, force, spin, mode))
        return reports

    def run(
        self,
        duration_s: float,
        wrench: WrenchInput = None,
        *,
        record_every: int = 1,
        progress: Callable[[int], None] | None = None,
    ) -> Trajectory:
        """Step for ``duration_s`` under a constant wrench or ``wrench(t, sim)``; record samples."""
        if not (duration_s >= 0 and math.isfinite(duration_s)):
            raise InputError(f"duration must be a non-negative number of seconds, got {duration_s}")
        n_steps = int(round(duration_s / self.dt))
        if self.dimension == 3 and not callable(wrench):
            return self._run_compiled(n_steps, wrench, record_every, progress)
        traj = Trajectory(list(self.names), self.dimension)
        t0 = time.perf_counter()
        self._record(traj)
        for s in range(1, n_steps + 1):
            w = wrench(self.time_s, self) if callable(wrench) else wrench
            self.step(w)
            if s % record_every == 0 or s == n_steps:
                self._record(traj)
            if progress is not None and s % 1000 == 0:
                progress(1000)
        traj.wall_time_s = time.perf_counter() - t0
        traj.steps = n_steps
        traj.max_penetration_m = self.max_penetration_m
        return traj

    def _run_compiled(
        self, n_steps: int, wrench: ArrayLike | None, record_every: int, progress: Callable[[int], None] | None
    ) -> Trajectory:
        """A constant-wrench 3D run as compiled loops of up to 5000 steps (no Python per step)."""
        every = max(1, record_every)
        f, _ = self._external(wrench)
        tau_origin = np.zeros(3) if wrench is None else np.asarray(wrench, dtype=float)[3:6]
        traj = Trajectory(list(self.names), self.dimension)
        self._record(traj)
        traj.error.clear()
        traj.iterations.clear()
        chunk = max(every, (5000 // every) * every)
        done = 0
        wall = 0.0
        status = kernels.STATUS_OK
        last_err, last_it = 0.0, 0  # a run of 0 steps solved nothing
        while done < n_steps:
            n = min(chunk, n_steps - done)
            t0 = time.perf_counter()
            out = kernels.run3(
                n, every, self._R, self._p, self._v, self._w, self._mass, self._Ib, self._Ib_inv,
                self._com_b, self._kind, self._params, self._verts, self._enorm, self._loc_p, self._loc_r, self._mu,
                self._tors, self.dt, f, tau_origin, self.restitution, self.margin_m, self._bound, self.tolerance,
                self.max_iterations, self._P, self._active,
            )  # fmt: skip
            wall += time.perf_counter() - t0
            (
                R,
                p,
                v,
                w,
                P,
                active,
                gap,
                n_w,
                u,
                rp,
                rR,
                rnu,
                rfn,
                rgap,
                rerr,
                rit,
                pen,
                worst_k,
                status_k,
                last_err,
                last_it,
            ) = out
            if status_k == kernels.STATUS_NONFINITE:
                raise SolverError(
                    f"a step produced a non-finite state between t = {self.time_s:.6g} s and {self.time_s + n * self.dt:.6g} s; the state before it was kept"
                )
            if status_k == kernels.STATUS_NOT_CONVERGED:
                status = status_k
                if self.strict:
                    raise SolverError(f"NSGS did not reach {self.tolerance:g} in some step (worst error {worst_k:.3g})")
            self._R, self._p, self._v, self._w, self._P, self._active, self._gap = R, p, v, w, P, active, gap
            self._nw, self._u = n_w, u
            times = self.time_s + self.dt * np.minimum(every * np.arange(1, len(rp)), n)
            traj.time_s += [float(t) for t in times]
            traj.position += list(rp[1:])
            traj.orientation += [quaternion_wxyz_from_matrix(Rk) for Rk in rR[1:]]
            traj.velocity += list(rnu[1:])
            traj.normal_force += list(rfn[1:])
            traj.gap += list(rgap[1:])
            traj.error += [float(e) for e in rerr[1:]]
            traj.iterations += [int(i) for i in rit[1:]]
            self.time_s += n * self.dt
            self.steps += n
            done += n
            self.max_penetration_m = max(self.max_penetration_m, float(pen))
            if progress is not None:
                progress(n)
        traj.max_penetration_m = self.max_penetration_m
        traj.wall_time_s = wall
        traj.steps = n_steps
        self.last = StepInfo(
            float(last_err), int(last_it), status == kernels.STATUS_OK, 0, float(self.max_penetration_m),
            self._names_t, self._active.copy(),
        )  # fmt: skip
        return traj

    def _record(self, traj: Trajectory) -> None:
        traj.time_s.append(self.time_s)
        traj.position.append(self._p.copy())
        if self.dimension == 3:
            traj.orientation.append(quaternion_wxyz_from_matrix(self._R))
        else:
            traj.orientation.append(np.array([math.atan2(self._R[1, 0], self._R[0, 0])]))
        traj.velocity.append(self.twist)
        traj.normal_force.append(np.where(self._active, self._P[:, 0] / self.dt, 0.0))
        traj.gap.append(self._gap.copy())
        if self.last is not None:
            traj.error.append(self.last.error)
            traj.iterations.append(self.last.iterations)
