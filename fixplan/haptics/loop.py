"""The haptic loop: operator → device → virtual coupling → engine, one tick per sample period.

Per tick (period ``T``, 1 ms by default):

1. the operator model pushes the device handle (``operator(t, device) -> wrench``);
2. the coupling wrench ``w_c = K (x_d − x_w) + B (ẋ_d − ẋ_w)`` is computed from the device and
   workpiece coordinates (position of the body origin; in 3D the rotation vector of
   ``R_w R_0ᵀ`` relative to the start orientation ``R_0``);
3. the engine advances the workpiece one step under ``w_c`` (plus gravity);
4. the device displays ``−w_c`` (saturated at its limits): what the user feels;
5. the device handle is integrated under the operator's push and the displayed wrench.

Each tick's compute time (steps 1–4, the part a real-time loop must finish within ``T``: the
command the operator model computes — in a verification the plan's executor, with any re-plan
it runs — the coupling, the engine step and the display) is measured with ``time.perf_counter``;
a tick longer than ``T`` is a deadline miss. The command's share is kept apart
(``LoopRecord.command_s``), so a report can say how much of the loop's time was the controller's.
"""

from __future__ import annotations

import gc
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fixplan.aot import kernel
from fixplan.engine.simulator import ContactReport, Simulator
from fixplan.errors import InputError
from fixplan.haptics.coordinates import workpiece_coordinates
from fixplan.haptics.coupling import VirtualCoupling
from fixplan.haptics.device import HapticDevice, SimulatedDevice, saturate
from fixplan.spatial import Pose

FloatArray = NDArray[np.float64]
Operator = Callable[[float, SimulatedDevice], ArrayLike]

_coupling3 = kernel("fixplan.haptics._kernels", "coupling3")  # 3D only: imported on first call


@dataclass
class LoopRecord:
    """What happened in a run of the loop, per tick."""

    time_s: list[float] = field(default_factory=list)
    compute_s: list[float] = field(default_factory=list)  # whole tick: command + coupling + step + display
    command_s: list[float] = field(default_factory=list)  # the operator's command alone (part of compute_s)
    coupling_wrench: list[FloatArray] = field(default_factory=list)  # on the workpiece
    felt_wrench: list[FloatArray] = field(default_factory=list)  # displayed on the device (saturated)
    device_position: list[FloatArray] = field(default_factory=list)
    workpiece_position: list[FloatArray] = field(default_factory=list)
    active_contacts: list[tuple[str, ...]] = field(default_factory=list)  # locators pressing on the part
    unconverged_steps: int = 0  # engine steps that stopped at the sweep cap
    max_solver_error: float | None = None  # worst FCLib residual the engine reached over the ticks (None: no tick)
    period_s: float = 1e-3
    # every ``trace_every`` ticks (and the last): (tick index, time [s], pose, per-locator contact reports)
    trace: list[tuple[int, float, Pose, list[ContactReport]]] = field(default_factory=list)

    @property
    def deadline_misses(self) -> int:
        return int(sum(c > self.period_s for c in self.compute_s))

    @property
    def mean_compute_s(self) -> float | None:
        """Mean compute time of a tick [s]; None when no tick ran."""
        return float(np.mean(self.compute_s)) if self.compute_s else None

    @property
    def max_compute_s(self) -> float | None:
        """Longest compute time of a tick [s]; None when no tick ran."""
        return float(np.max(self.compute_s)) if self.compute_s else None


class HapticLoop:
    """Runs the engine behind a virtual coupling and a (simulated) device."""

    def __init__(
        self,
        sim: Simulator,
        device: SimulatedDevice,
        coupling: VirtualCoupling,
        *,
        push_limits: tuple[float, float] | None = None,
    ):
        if abs(coupling.period_s - sim.dt) > 1e-12:
            raise InputError(f"coupling period {coupling.period_s:g} s must equal the engine step {sim.dt:g} s")
        if device.ndof != (6 if sim.dimension == 3 else 3):
            raise InputError(
                f"a {sim.dimension}D scene needs a device with {6 if sim.dimension == 3 else 3} coordinates"
            )
        specs = device.specs
        if coupling.K_lin > specs.max_stiffness_N_per_m or coupling.B_lin > specs.max_damping_Ns_per_m:
            raise InputError(
                f"coupling gains exceed the device: K = {coupling.K_lin:g} > {specs.max_stiffness_N_per_m:g} N/m "
                f"or B = {coupling.B_lin:g} > {specs.max_damping_Ns_per_m:g} N·s/m"
            )
        # the coupling's passivity was checked against the damping it was told the handle has;
        # the handle must really have at least that much
        b_dev, b_rot = specs.physical_damping_Ns_per_m, specs.rotational_damping_Nms_per_rad
        if coupling.device_damping > b_dev * (1 + 1e-12) or coupling.device_damping_rot > b_rot * (1 + 1e-12):
            raise InputError(
                f"the coupling was checked for passivity with device damping b = {coupling.device_damping:g} N·s/m "
                f"(rotation {coupling.device_damping_rot:g}), but the device has {b_dev:g} N·s/m "
                f"(rotation {b_rot:g}): expected at most the device's own damping"
            )
        self.sim = sim
        self.device = device
        self.coupling = coupling
        # the hand's limits on the push the part receives (force [N], moment about the body origin
        # [N·m]): a hand cannot push harder, so the coupling wrench is saturated there
        self.push_limits = push_limits
        self.saturated_ticks = 0
        self._R0 = sim.pose.R_world_body.copy()
        self._com_b = sim.com_body
        d = sim.dimension
        n = 6 if d == 3 else 3
        self._K = np.concatenate([np.full(d, coupling.K_lin), np.full(n - d, coupling.K_rot)])
        self._B = np.concatenate([np.full(d, coupling.B_lin), np.full(n - d, coupling.B_rot)])

    def workpiece_coordinates(self, *, compiled: bool = False) -> tuple[FloatArray, FloatArray]:
        """Workpiece coordinates matching the device's: body origin (+ rotation vector), and their rates.

        (:func:`fixplan.haptics.coordinates.workpiece_coordinates` relative to the start orientation.)
        """
        return workpiece_coordinates(self.sim, self._R0, compiled=compiled)

    def tick(
        self,
        operator_wrench: ArrayLike | Callable[[], ArrayLike],
        *,
        external: FloatArray | None = None,
        hand: bool = True,
        device: HapticDevice | None = None,
        stiffness_scale: float = 1.0,
    ) -> tuple[FloatArray, FloatArray, float]:
        """One sample period; returns (coupling wrench on the workpiece, felt wrench, compute time [s]).

        The compute time is steps 2–4's; :meth:`run` adds the time the operator's command took.
        ``operator_wrench``: the operator's push on the handle over the tick, or a callable that
        gives it once the part has moved and the device displays (a hand that reacts to this
        tick: the interactive session's). ``external``: a wrench about the body origin (world
        axes) the engine applies besides the coupling's (the clamps of a clamping stage);
        ``hand`` False: the hand has let go of the part (or the device gave no reading), the
        coupling's wrench is 0 and so is what the device shows. ``device``: the device of this
        tick in place of :attr:`device` (the session switches between a person's and the
        simulated one); ``stiffness_scale`` scales the coupling's stiffness (within its passivity
        bound, the caller's check).
        """
        t0 = time.perf_counter()
        d = self.sim.dimension
        dev = self.device if device is None else device
        if not hand:
            w_c = np.zeros(6 if d == 3 else 3)
        else:
            x_d, v_d = dev.position(), dev.velocity()
            K = self._K if stiffness_scale == 1.0 else self._K * stiffness_scale
            if d == 3:
                R, p, v, w = self.sim.body_state
                w_c = _coupling3(R, p, self._com_b, v, w, self._R0, x_d, v_d, K, self._B)
            else:
                x_w, v_w = self.workpiece_coordinates()
                w_c = K * (x_d - x_w) + self._B * (v_d - v_w)
            if self.push_limits is not None:
                w_c = self._saturate(w_c, *self.push_limits)
        self.sim.step(w_c if external is None else w_c + external)
        felt = dev.set_force_and_torque(-w_c)
        compute = time.perf_counter() - t0
        dev.advance(self.coupling.period_s, operator_wrench() if callable(operator_wrench) else operator_wrench)
        return w_c, felt, compute

    def _saturate(self, w: FloatArray, F_max: float, T_max: float) -> FloatArray:
        """``w`` with its force and moment scaled down to the hand's limits (counted when it was)."""
        out, saturated = saturate(w, self.sim.dimension, F_max, T_max)
        self.saturated_ticks += saturated
        return out

    def warm_up(self) -> Simulator:
        """Load every compiled kernel once on a scratch copy, so no tick pays for compilation.

        Returns the scratch copy (stepped once), for a caller to load its own kernels on.
        """
        import copy

        scratch = copy.deepcopy(self.sim)
        x_d, v_d = self.device.position(), self.device.velocity()
        if scratch.dimension == 3:
            R, p, v, w = scratch.body_state
            _coupling3(R, p, self._com_b, v, w, self._R0, x_d, v_d, self._K, self._B)
        scratch.step(np.zeros(6 if scratch.dimension == 3 else 3))
        return scratch

    def run(
        self,
        duration_s: float,
        operator: Operator,
        *,
        trace_every: int = 0,
        until: Callable[[], bool] | None = None,
    ) -> LoopRecord:
        """Run ticks for ``duration_s`` with ``operator(t, device)`` pushing the handle.

        ``trace_every > 0`` also samples the pose and the contact reports every that many ticks
        and at the last one (outside the timed part of the tick) into ``LoopRecord.trace``.
        ``until()``, checked after every tick, ends the run early when it returns True.
        """
        rec = LoopRecord(period_s=self.coupling.period_s)
        n = int(round(duration_s / self.coupling.period_s))
        self.warm_up()
        self.device.open()
        # like any real-time loop, no garbage collection pauses inside the ticks (a collection of
        # the young generation costs 0.1–1 ms); the loop allocates little, collected afterwards
        gc_was_enabled = gc.isenabled()
        gc.disable()
        try:
            for i in range(n):
                t = self.sim.time_s
                t0 = time.perf_counter()
                command = operator(t, self.device)  # the controller's work is the tick's too
                command_s = time.perf_counter() - t0
                w_c, felt, compute = self.tick(command)
                rec.time_s.append(self.sim.time_s)
                rec.compute_s.append(command_s + compute)
                rec.command_s.append(command_s)
                rec.coupling_wrench.append(w_c)
                rec.felt_wrench.append(felt)
                rec.device_position.append(self.device.position())
                rec.workpiece_position.append(self.sim.pose.p_world.copy())
                rec.active_contacts.append(self.sim.pressed())
                last = self.sim.last
                if last is not None:
                    worst = rec.max_solver_error
                    rec.max_solver_error = last.error if worst is None else max(worst, last.error)
                    if not last.converged:
                        rec.unconverged_steps += 1
                stop = until is not None and until()
                if trace_every > 0 and (i % trace_every == 0 or i == n - 1 or stop):
                    rec.trace.append((i, self.sim.time_s, self.sim.pose, self.sim.contacts()))
                if stop:
                    break
        finally:
            self.device.close()
            if gc_was_enabled:
                gc.enable()
        return rec
