"""Haptic devices: the abstraction (after CHAI3D's ``cGenericHapticDevice``) and a simulated one.

A device has a handle with a pose and a twist in its workspace, and accepts a force and a torque
to display. :class:`SimulatedDevice` models the handle as a rigid body with mass, inertia and
viscous damping ``b`` (the physical damping that makes a virtual coupling passive, see
:mod:`.coupling`), saturates the displayed wrench at the device's limits, and can quantize its
position readings like an encoder.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fixplan.errors import InputError
from fixplan.settings import HAPTIC, HapticRigSettings

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class DeviceSpecs:
    """What a device can do (CHAI3D's ``cHapticDeviceInfo``)."""

    max_force_N: float
    max_torque_Nm: float
    max_stiffness_N_per_m: float
    max_damping_Ns_per_m: float
    workspace_radius_m: float
    physical_damping_Ns_per_m: float  # b: the handle's own viscous damping
    physical_damping_rot_Nms_per_rad: float | None = None  # rotation; None: HAPTIC.haptic.rot_damping_fraction of b

    @property
    def rotational_damping_Nms_per_rad(self) -> float:
        """The handle's own rotational damping [N·m·s/rad] (1 % of ``b`` unless given)."""
        if self.physical_damping_rot_Nms_per_rad is None:
            return HAPTIC.haptic.rot_damping_fraction * self.physical_damping_Ns_per_m
        return self.physical_damping_rot_Nms_per_rad


def saturate(w: FloatArray, d: int, F_max: float, T_max: float) -> tuple[FloatArray, bool]:
    """``w`` with its force and moment scaled down to ``F_max`` [N] and ``T_max`` [N·m], and whether it was.

    The force is the first ``d`` components; ``w`` itself is returned when within both limits.
    """
    F = math.sqrt(float(w[:d] @ w[:d]))
    T = math.sqrt(float(w[d:] @ w[d:]))
    if F <= F_max and T <= T_max:
        return w, False
    out = np.array(w, dtype=float)
    if F > F_max:
        out[:d] *= F_max / F
    if T > T_max:
        out[d:] *= T_max / T
    return out, True


class HapticDevice(ABC):
    """The calls a loop makes on a device, real or simulated."""

    @abstractmethod
    def open(self) -> None: ...

    @abstractmethod
    def close(self) -> None: ...

    @property
    @abstractmethod
    def specs(self) -> DeviceSpecs: ...

    @abstractmethod
    def position(self) -> FloatArray:
        """Handle position [m] (and, in 3D, orientation as a rotation vector [rad]) — the device's pose coordinates."""

    @abstractmethod
    def velocity(self) -> FloatArray:
        """Handle twist in the same coordinates [m/s, rad/s]."""

    @abstractmethod
    def set_force_and_torque(self, wrench: ArrayLike) -> FloatArray:
        """Display a wrench (saturated at the device's limits); returns what is displayed."""

    def advance(self, dt: float, operator_wrench: ArrayLike) -> None:  # noqa: B027 - a real handle: nothing to do
        """The handle over one tick under the operator's hand: a real one moves by itself."""


class ReadDevice(HapticDevice):
    """A real device's handle as a loop sees it for a tick: the pose and twist it reported.

    :meth:`read` gives the tick's reading; :meth:`set_force_and_torque` saturates the wrench
    at the device's limits and keeps it for the caller to send (with its answer) to the device.
    """

    def __init__(self, ndof: int, specs: DeviceSpecs):
        self.ndof = ndof
        self._specs = specs
        self._x = np.zeros(ndof)
        self._v = np.zeros(ndof)
        self.displayed = np.zeros(ndof)

    def read(self, x: FloatArray, v: FloatArray) -> None:
        """The handle's pose and twist this tick, in device coordinates."""
        self._x, self._v = x, v

    def open(self) -> None:
        pass

    def close(self) -> None:
        self.displayed = np.zeros(self.ndof)

    @property
    def specs(self) -> DeviceSpecs:
        return self._specs

    def position(self) -> FloatArray:
        return self._x

    def velocity(self) -> FloatArray:
        return self._v

    def set_force_and_torque(self, wrench: ArrayLike) -> FloatArray:
        w = np.asarray(wrench, dtype=float)
        self.displayed, _ = saturate(w, 2 if self.ndof == 3 else 3, self._specs.max_force_N, self._specs.max_torque_Nm)
        return self.displayed


class SimulatedDevice(HapticDevice):
    """A handle of mass ``m`` (and rotational inertia) with viscous damping, driven by the operator.

    Coordinates: ``ndof`` generalised coordinates, 6 in 3D (position, small-angle rotation
    vector) or 3 in 2D (x, y, θ). Each tick :meth:`advance` integrates
    ``M ẍ = f_operator + f_displayed − b ẋ`` with semi-implicit Euler.
    """

    def __init__(
        self,
        ndof: int,
        *,
        mass_kg: float | None = None,
        inertia_kgm2: float | None = None,
        specs: DeviceSpecs | None = None,
        quantization_m: float = 0.0,
        x0: ArrayLike | None = None,
        rig: HapticRigSettings = HAPTIC.haptic,
    ):
        if ndof not in (3, 6):
            raise InputError(f"a device has 3 (2D) or 6 (3D) coordinates, got {ndof}")
        self.ndof = ndof
        d = 2 if ndof == 3 else 3
        mass_kg = rig.handle_mass_kg if mass_kg is None else mass_kg
        inertia_kgm2 = rig.handle_inertia_kgm2 if inertia_kgm2 is None else inertia_kgm2
        self._M = np.concatenate([np.full(d, mass_kg), np.full(ndof - d, inertia_kgm2)])
        self._specs = specs or DeviceSpecs(
            max_force_N=rig.max_force_N,
            max_torque_Nm=rig.max_torque_Nm,
            max_stiffness_N_per_m=rig.max_stiffness_N_per_m,
            max_damping_Ns_per_m=rig.max_damping_Ns_per_m,
            workspace_radius_m=rig.workspace_radius_m,
            physical_damping_Ns_per_m=rig.min_device_damping_Ns_per_m,
        )
        self.quantization_m = float(quantization_m)
        self._x = np.zeros(ndof) if x0 is None else np.array(x0, dtype=float)
        self._v = np.zeros(ndof)
        self._displayed = np.zeros(ndof)
        self._open = False

    def open(self) -> None:
        self._open = True

    def close(self) -> None:
        self._displayed[:] = 0.0
        self._open = False

    @property
    def specs(self) -> DeviceSpecs:
        return self._specs

    def position(self) -> FloatArray:
        if self.quantization_m > 0:
            return np.round(self._x / self.quantization_m) * self.quantization_m
        return self._x.copy()

    def velocity(self) -> FloatArray:
        return self._v.copy()

    def set_force_and_torque(self, wrench: ArrayLike) -> FloatArray:
        d = 2 if self.ndof == 3 else 3
        w, _ = saturate(np.array(wrench, dtype=float), d, self._specs.max_force_N, self._specs.max_torque_Nm)
        self._displayed = w
        return w.copy()

    def advance(self, dt: float, operator_wrench: ArrayLike) -> None:
        """Integrate the handle for one tick under the operator's hand and the displayed wrench."""
        b = self._specs.physical_damping_Ns_per_m
        d = 2 if self.ndof == 3 else 3
        damping = np.concatenate([np.full(d, b), np.full(self.ndof - d, self._specs.rotational_damping_Nms_per_rad)])
        f = np.asarray(operator_wrench, dtype=float) + self._displayed
        # semi-implicit: damping implicit for unconditional stability
        self._v = (self._v + dt * f / self._M) / (1.0 + dt * damping / self._M)
        self._x = self._x + dt * self._v
