"""The simulated haptic rig: a device, a virtual coupling and an operator's gains, scaled to the part.

:func:`haptic_rig` builds the :class:`HapticRig` a verification, an insertion run, a recording's
re-run and the interactive session drive: a :class:`~fixplan.haptics.device.SimulatedDevice`
whose damping keeps the :class:`~fixplan.haptics.coupling.VirtualCoupling` passive, the
:class:`~fixplan.haptics.loop.HapticLoop` around the engine, and the operator's PD on the handle
(:meth:`HapticRig.operator_wrench`: the hand that makes the coupling transmit a wanted push).
The numbers are the ``haptic`` profile's :class:`~fixplan.settings.HapticRigSettings`. The rig
imports nothing of the planner; the planner drives it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fixplan.engine.simulator import Simulator
from fixplan.haptics.coupling import VirtualCoupling
from fixplan.haptics.device import DeviceSpecs, SimulatedDevice
from fixplan.haptics.loop import HapticLoop
from fixplan.model import Fixture
from fixplan.settings import HAPTIC, HapticRigSettings

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class HapticRig:
    """The simulated load's hardware: device, virtual coupling, loop, and the operator's gains."""

    loop: HapticLoop
    K: FloatArray  # coupling stiffness per coordinate
    kp: FloatArray  # operator PD on the handle, per coordinate
    kd: FloatArray
    damping: FloatArray  # the handle's own damping, per coordinate (the operator compensates it)

    def operator_wrench(self, w: FloatArray, device: SimulatedDevice) -> FloatArray:
        """The operator's hand on the handle so that the coupling transmits ``w`` to the part.

        Feedforward ``w`` plus the handle's damping at the part's speed, and a PD that holds the
        handle ``w / K`` ahead of the part.
        """
        x_w, v_w = self.loop.workpiece_coordinates()
        return (
            w
            + self.damping * v_w
            + self.kp * (x_w + w / self.K - device.position())
            + self.kd * (v_w - device.velocity())
        )


def haptic_rig(
    fixture: Fixture,
    sim: Simulator,
    x0: FloatArray,
    F_max: float,
    T_max: float,
    rig: HapticRigSettings = HAPTIC.haptic,
) -> HapticRig:
    """Device, coupling and operator gains scaled to the part (see the comments for each choice).

    The numbers are ``rig``'s (:class:`fixplan.settings.HapticRigSettings`, the ``haptic`` profile's).
    """
    ndof = fixture.ndof
    # The coupling is scaled to the part: 1000 N/m per kg and 4800 N·m/rad per kg·m² of its
    # largest principal inertia (2000 N/m and 40 N·m/rad for the 2 kg default box), so the
    # part-on-coupling frequency is about 32 rad/s in translation and 69 rad/s in rotation for
    # every part. Fixed gains made a 22 g plate's sampled spring unstable (ω·T > 2: it rocked
    # between its base locators for ever) and a 30 kg box's coupling need a lead beyond the
    # workspace. The simulated device gets the damping that keeps the coupling passive
    # (b > K T/2 + B with a 1.5 margin; at least 8 N·s/m).
    #
    # The rig is the same in every coordinate once divided by the handle's inertia: the handle's
    # rotational inertia, its own damping and the coupling's damping are the translational ones
    # scaled by K_rot/K_lin. The push then reaches the part as one wrench, every component with the
    # same time course. With a fixed 2e-4 kg·m² handle and 1 % of b in rotation the moment arrived
    # about ten times faster than the force: a tall box got the counter-moment of a sideways push
    # before the push itself and tipped off a base locator as every push began.
    wp = fixture.workpiece
    I_max = float(np.max(np.linalg.eigvalsh(np.atleast_2d(wp.inertia_body))))
    K_lin, K_rot = rig.stiffness_per_kg * wp.mass_kg, rig.rot_stiffness_per_kgm2 * I_max
    ratio = K_rot / K_lin  # [m²]: rotation's share of each translational quantity
    B_lin = rig.damping_time_s * K_lin
    B_rot = B_lin * ratio
    b = max(rig.min_device_damping_Ns_per_m, rig.passivity_safety * (K_lin * sim.dt / 2 + B_lin))
    b_rot = b * ratio  # passive too: b_rot ≥ 1.5 (K_rot T/2 + B_rot)
    m_dev = rig.handle_mass_kg
    i_dev = m_dev * ratio
    # the device can display a little more than the hand may push (the coupling's transients)
    specs = DeviceSpecs(
        max_force_N=rig.display_headroom * F_max,
        max_torque_Nm=rig.display_headroom * T_max,
        max_stiffness_N_per_m=max(rig.max_stiffness_N_per_m, rig.stiffness_headroom * K_lin),
        max_damping_Ns_per_m=max(rig.max_damping_Ns_per_m, rig.stiffness_headroom * B_lin),
        workspace_radius_m=rig.workspace_radius_m,
        physical_damping_Ns_per_m=b,
        physical_damping_rot_Nms_per_rad=b_rot,
    )
    dev = SimulatedDevice(ndof, mass_kg=m_dev, inertia_kgm2=i_dev, specs=specs, x0=x0)
    coupling = VirtualCoupling(K_lin, B_lin, K_rot, B_rot, sim.dt, device_damping=b, device_damping_rot=b_rot)
    loop = HapticLoop(sim, dev, coupling, push_limits=(F_max, T_max))
    d = fixture.dimension
    K = np.concatenate([np.full(d, coupling.K_lin), np.full(ndof - d, coupling.K_rot)])
    # The operator (a person's arm, or a robot's force loop) holds the handle w/K ahead of the
    # part with a stiff PD: natural frequency 120 rad/s (about 20 Hz, a robot force loop's
    # bandwidth), damping ratio 0.9, gains scaled by the handle's mass and inertia. At 45 rad/s the
    # lag of the transmitted push let 4 of 12 generated 3-2-1 boxes tip off a base locator when
    # the push changed (10 of 12 verified at 120).
    w_op, zeta = rig.operator_omega_radps, rig.operator_damping_ratio
    kp = np.concatenate([np.full(d, m_dev * w_op**2), np.full(ndof - d, i_dev * w_op**2)])
    kd = np.concatenate([np.full(d, 2 * zeta * w_op * m_dev), np.full(ndof - d, 2 * zeta * w_op * i_dev)])
    damping = np.concatenate([np.full(d, b), np.full(ndof - d, b_rot)])
    return HapticRig(loop, K, kp, kd, damping)


__all__ = ["HapticRig", "haptic_rig"]
