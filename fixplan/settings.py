"""Settings in one place: small frozen dataclasses, bundled in named profiles.

Every tunable number fixplan uses — a threshold, a solver option, a gain, a rate, a search limit
— lives here, so a reader can see what "touching", "balanced" or "passive" means without hunting
for literals. Constants of nature and mathematics (``g``, ``π``, a division guard far below any
physical quantity) are not settings and stay where they are used. ``tests/test_settings.py``
scans the package for threshold-looking literals so this stays true.

Groups
------
:class:`Tolerances`
    What "touching", "balanced" and "slipping" mean (carried by every :class:`~fixplan.fixture.Fixture`).
:class:`EngineSettings`
    The contact engine: NSGS sweep cap and stopping residual, the detection margin.
:class:`HapticRigSettings`
    The haptic rig — ONE copy: coupling gains per unit of mass and inertia, the passivity safety
    factor, the simulated handle, the device's limits, the operator's PD hand.
:class:`VerificationSettings`
    The thresholds a simulated load must meet to verify a plan.

A :class:`Settings` bundles one of each. The named profiles in :data:`PROFILES`:

``default``
    What every function uses when not told otherwise (the planner, ``classify``, ``simulate``).
``haptic``
    Selected by everything that runs the 1 kHz haptic loop: :func:`fixplan.planner.verify.verify`,
    :class:`fixplan.interactive.session.Session` and
    :func:`fixplan.interactive.record.verify_recording`. Its engine bounds the work per tick
    (a haptic-grade residual of 10⁻⁶ and at most 40 NSGS sweeps); its tolerances are the default
    ones, so the executor's verdicts are the planner's.
``strict``
    Tighter residuals and solver accuracy, for tests and benchmarks that compare against closed
    forms to many digits (``tests/test_settings.py``; the engine's in
    ``tests/engine/test_validation.py``).

Pass settings explicitly (``settings=profile("strict").tolerances``); there is no global state.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

from fixplan.errors import InputError


@dataclass(frozen=True)
class Tolerances:
    """Numerical thresholds.

    Attributes
    ----------
    touch_m : float
        A locator touches the workpiece when its gap is at most this [m].
    penetration_m : float
        Largest start-pose penetration of a locator tip accepted by the loader [m].
    goal_gap_m : float
        Largest gap accepted at a given or computed goal pose [m].
    balance_rel : float
        Static balance holds when the least M⁻¹-weighted residual is at most this fraction of
        the wrench's own M⁻¹-norm (scale-free, so a wrench of 1e-6 N and of 1e6 N get the same
        verdict).
    cone_eps : float
        Solver accuracy requested from the cone-program backends (relative).
    slip_rel : float
        A contact's tangential acceleration counts as slipping above this fraction of the body
        acceleration.
    wedge_force : float
        Contacts wedge when they can hold self-equilibrated forces whose normal components sum to
        more than this, out of 1 (:func:`fixplan.jamming.can_wedge`).
    """

    touch_m: float = 1e-6
    penetration_m: float = 1e-6
    goal_gap_m: float = 1e-6
    balance_rel: float = 1e-6
    cone_eps: float = 1e-9
    slip_rel: float = 1e-6
    wedge_force: float = 1e-7

    def with_(self, **changes: float) -> Tolerances:
        """A copy with some fields changed."""
        return replace(self, **changes)


@dataclass(frozen=True)
class EngineSettings:
    """The contact engine (:class:`~fixplan.engine.simulator.Simulator`).

    Attributes
    ----------
    tolerance : float or None
        NSGS stopping residual; None: the fixture's ``[simulation] tolerance``.
    max_iterations : int
        Cap on NSGS sweeps per step (the stop is the residual).
    margin_m : float
        Contact detection margin [m]: a locator this far from the surface enters the step's
        contact problem.
    slip_mps : float
        A contact report calls a contact sliding above this tangential speed [m/s].
    spin_radps : float
        ... and rolling (not sticking) above this body angular speed [rad/s].
    """

    tolerance: float | None = None
    max_iterations: int = 2000
    margin_m: float = 1e-4
    slip_mps: float = 1e-7
    spin_radps: float = 1e-6


@dataclass(frozen=True)
class HapticRigSettings:
    """The haptic rig: device, virtual coupling and operator, scaled to the part.

    The coupling is scaled to the part: ``stiffness_per_kg`` N/m per kg of mass and
    ``rot_stiffness_per_kgm2`` N·m/rad per kg·m² of its largest principal inertia (2000 N/m and
    40 N·m/rad for the 2 kg default box), so the part-on-coupling frequency is about 32 rad/s in
    translation and 69 rad/s in rotation for every part (see :func:`fixplan.planner.verify.haptic_rig`).

    Attributes
    ----------
    stiffness_per_kg : float
        Coupling stiffness per kg of the part [N/m/kg].
    rot_stiffness_per_kgm2 : float
        Rotational coupling stiffness per kg·m² of the part's largest principal inertia [N·m/rad/(kg·m²)].
    damping_time_s : float
        Coupling damping over stiffness, ``B = damping_time_s · K`` [s].
    passivity_safety : float
        The handle's damping is this factor over the passivity bound ``K T/2 + B``.
    min_device_damping_Ns_per_m : float
        ... and at least this [N·s/m]; also the default device's own damping.
    handle_mass_kg : float
        Mass of the simulated handle [kg].
    handle_inertia_kgm2 : float
        Rotational inertia of a stand-alone simulated handle [kg·m²] (the rig scales it instead).
    rot_damping_fraction : float
        A device's rotational damping, when not given, is this fraction of ``b`` [m²].
    display_headroom : float
        The device can display this factor over what the hand may push (the coupling's transients).
    stiffness_headroom : float
        The device's stiffness and damping limits are at least this factor over the coupling's.
    max_force_N, max_torque_Nm, max_stiffness_N_per_m, max_damping_Ns_per_m, workspace_radius_m : float
        The default simulated device's limits (the rig raises stiffness and damping when needed).
    operator_omega_radps : float
        Natural frequency of the operator's PD hand [rad/s] (about 20 Hz, a robot force loop).
    operator_damping_ratio : float
        Its damping ratio.
    """

    stiffness_per_kg: float = 1000.0
    rot_stiffness_per_kgm2: float = 4800.0
    damping_time_s: float = 1e-3
    passivity_safety: float = 1.5
    min_device_damping_Ns_per_m: float = 8.0
    handle_mass_kg: float = 0.2
    handle_inertia_kgm2: float = 2e-4
    rot_damping_fraction: float = 1e-2
    display_headroom: float = 1.5
    stiffness_headroom: float = 2.0
    max_force_N: float = 40.0
    max_torque_Nm: float = 2.0
    max_stiffness_N_per_m: float = 5000.0
    max_damping_Ns_per_m: float = 50.0
    workspace_radius_m: float = 0.5
    operator_omega_radps: float = 120.0
    operator_damping_ratio: float = 0.9


@dataclass(frozen=True)
class VerificationSettings:
    """What a simulated load must meet to verify a plan (:func:`fixplan.planner.verify.verify`).

    Attributes
    ----------
    final_gap_m : float
        Every goal locator ends within this gap [m].
    max_penetration_m : float
        The deepest penetration over the load stays below this [m].
    limit_slack : float
        The push may exceed the hand's limits by this fraction (the coupling's transients) ...
    limit_window_s : float
        ... averaged over this window [s].
    trace_every_s : float
        The contact trace is sampled this often [s] (0: no trace).
    time_factor : float
        Time limit: this factor times the nominal duration at cruise speed ...
    time_base_s : float
        ... plus this [s] ...
    time_per_step_s : float
        ... plus this per transition [s] ...
    time_max_s : float
        ... and at most this [s].
    """

    final_gap_m: float = 1e-4
    max_penetration_m: float = 1e-5
    limit_slack: float = 0.05
    limit_window_s: float = 0.01
    trace_every_s: float = 0.01
    time_factor: float = 3.0
    time_base_s: float = 2.0
    time_per_step_s: float = 0.5
    time_max_s: float = 60.0


@dataclass(frozen=True)
class Settings:
    """One of each group: what a profile selects."""

    name: str = "default"
    tolerances: Tolerances = field(default_factory=Tolerances)
    engine: EngineSettings = field(default_factory=EngineSettings)
    haptic: HapticRigSettings = field(default_factory=HapticRigSettings)
    verification: VerificationSettings = field(default_factory=VerificationSettings)

    def with_(self, **changes: Any) -> Settings:
        """A copy with some groups replaced."""
        return replace(self, **changes)


_STRICT_TOLERANCES = Tolerances(balance_rel=1e-8, cone_eps=1e-10, slip_rel=1e-8)

PROFILES: dict[str, Settings] = {
    "default": Settings(),
    # the loop's engine bounds its work per tick: a haptic-grade residual and at most 40 NSGS sweeps
    # (≈ 7 µs a sweep with five or six sliding contacts: 40 sweeps stay within 0.3 ms of the 1 ms
    # period); the thresholds stay the planner's so the executor's verdicts agree with the plan's
    "haptic": Settings(name="haptic", engine=EngineSettings(tolerance=1e-6, max_iterations=40)),
    "strict": Settings(name="strict", tolerances=_STRICT_TOLERANCES, engine=EngineSettings(tolerance=1e-10)),
}

DEFAULT = PROFILES["default"]
HAPTIC = PROFILES["haptic"]
STRICT = PROFILES["strict"]
DEFAULT_TOLERANCES = DEFAULT.tolerances


def profile(name: str) -> Settings:
    """The settings profile called ``name``; :class:`InputError` listing the known ones otherwise."""
    try:
        return PROFILES[name]
    except KeyError:
        raise InputError(f"unknown settings profile {name!r}: expected one of {', '.join(sorted(PROFILES))}") from None
