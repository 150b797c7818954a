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
:class:`PlannerSettings`
    The planner: clearances, the friction-margin grid, IPOPT's options.
:class:`SearchSettings`
    The wrench search: margins, the slip threshold, when a limit binds.
:class:`ExecutionSettings`
    How the executor pushes (:mod:`fixplan.planner.execute`).
:class:`RobustSettings`
    The uncertainty a robustness study samples (:mod:`fixplan.robust`, ``fixplan robust``'s options).
:class:`WitnessSettings`
    When a candidate motion counts as a sliding witness.
:class:`GoalSettings`
    Finding the located pose: Gauss–Newton's stop, when a pose touches, the wider search's starts.
:class:`Numerics`
    Rank and pseudo-inverse cut-offs of the numerical linear algebra, Clarabel's options.
:class:`ClusterSettings`
    How long ``robust`` and batch solves wait for a Dask scheduler given by its address.

A :class:`Settings` bundles one of each. The named profiles in :data:`PROFILES`:

``default``
    What every function uses when not told otherwise (the planner, ``classify``, ``simulate``).
``haptic``
    Selected by everything that runs the 1 kHz haptic loop: :func:`fixplan.planner.verify.verify`,
    :func:`fixplan.planner.solve.solve` (which verifies its plan there),
    :class:`fixplan.interactive.session.Session` and
    :func:`fixplan.interactive.record.verify_recording`. Its engine bounds the work per tick
    (a haptic-grade residual of 10⁻⁶ and at most 1000 NSGS sweeps); its tolerances are the default
    ones, so the executor's verdicts are the planner's.
``strict``
    Tighter residuals and solver accuracy, for tests and benchmarks that compare against closed
    forms to many digits (``tests/test_settings.py``; the engine's in
    ``tests/engine/test_validation.py``).

Pass settings explicitly: a function that uses a threshold takes ``settings=`` (a profile,
``settings=profile("strict")``, or the group it needs) from its caller, and only the public entry
points default to a profile; no module keeps a threshold of its own, and there is no global state.
"""

from __future__ import annotations

import math
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
    polish_after : int
        NSGS sweeps of a step before the nonsmooth Newton polish takes over (0: only after
        ``max_iterations``). A polish that does not converge hands back to the sweeps, which go
        on up to ``max_iterations`` in all (:func:`fixplan.engine.step.solve_staged`). Gauss–Seidel
        converges linearly, slowly on a hyperstatic seat; 40 sweeps first halved the verification's
        contact solves on free-start boxes (80 sweeps a step on six point locators before).
    polish_steps : int
        Cap on the nonsmooth Newton steps (and proximal rounds) of each polish
        (:mod:`fixplan.engine.polish`; 0: none).
    margin_m : float
        Contact detection margin [m]: a locator this far from the surface enters the step's
        contact problem.
    slip_mps : float
        A contact report calls a contact sliding above this tangential speed [m/s].
    spin_radps : float
        ... and rolling (not sticking) above this body angular speed [rad/s].
    fclib_tolerance : float
        Target FCLib residual of ``fixplan fclib`` (natural map, relative).
    fclib_time_factor, fclib_time_slack_s : float
        Promise of every FCLib solver: it answers within ``fclib_time_factor × time_limit +
        fclib_time_slack_s`` [s] of reading and solving. Work that cannot be interrupted (a
        chunk of sweeps, a factorization, an interior-point iteration) is started only when the
        last one of its kind fits in the time left; the slack covers the first one and the
        clock's granularity.
    rim_points : int
        Points on each rim of a cylinder that meet collision-only bodies (``[[obstacle]]``,
        :mod:`fixplan.geometry.collision`): the rims' inscribed polygons.
    """

    tolerance: float | None = None
    max_iterations: int = 2000
    polish_after: int = 40
    polish_steps: int = 30
    margin_m: float = 1e-4
    slip_mps: float = 1e-7
    spin_radps: float = 1e-6
    fclib_tolerance: float = 1e-8
    fclib_time_factor: float = 1.1
    fclib_time_slack_s: float = 0.05
    rim_points: int = 16


@dataclass(frozen=True)
class HapticRigSettings:
    """The haptic rig: device, virtual coupling and operator, scaled to the part.

    The coupling is scaled to the part: ``stiffness_per_kg`` N/m per kg of mass and
    ``rot_stiffness_per_kgm2`` N·m/rad per kg·m² of its largest principal inertia (2000 N/m and
    40 N·m/rad for the 2 kg default box), so the part-on-coupling frequency is about 32 rad/s in
    translation and 69 rad/s in rotation for every part (see :func:`fixplan.haptics.rig.haptic_rig`).

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
    operator_reaction_s : float
        How late a device's operator follows the guidance in a haptic session [s] (``fixplan
        device-sim``'s default reaction; a person is slower): the guidance's servo is held to it
        (``InsertionSettings.delay_bandwidth``). A session without a device (its simulated hand) has none.
    switch_interval_s : float
        Real-time session: the interpreter's thread switch interval at most this [s] (the display
        thread gives the GIL back quickly).
    spin_s : float
        The loop sleeps only when the next tick is more than this away [s] ...
    wake_early_s : float
        ... and wakes this long before it, spinning the rest [s].
    coupling_force_weights : float
        A haptic session on a fixture without ``[manipulator]`` limits caps the coupling force at
        this many times the part's weight ``m |g|`` [N] (the planner's guidance is planned within
        the same cap) ...
    coupling_torque_weights : float
        ... and its torque at this many times ``m |g|`` × the part's bounding radius [N·m].
    guide_ready_s : float
        The wall-clock session waits at most this long [s] for the guidance processes' first
        answers (start-up, imports, the first plan) before its clock starts; then it starts
        without them, saying so.
    guide_nice : int
        The guidance (planner) process asks for this nice value: a busy core shares with it
        about 10:1 (refused without permission: it keeps its niceness).
    peer_timeout_s : float
        ``fixplan device-sim`` ends (exit 1, one line) when fixplan has not answered for this long [s].
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
    operator_reaction_s: float = 0.05
    switch_interval_s: float = 2e-4
    spin_s: float = 2e-4
    wake_early_s: float = 1.5e-4
    coupling_force_weights: float = 4.0
    coupling_torque_weights: float = 4.0
    guide_ready_s: float = 300.0
    guide_nice: int = -10
    peer_timeout_s: float = 2.0


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
    time_per_replan_s : float
        Each new plan the executor takes on the way (a re-plan, the policy's transitions from an
        unexpected state, a lift off a dead end) adds this to the time limit [s], within
        ``time_max_s``: a tall box that rocked into other states and re-planned 3-8 times timed
        out at 10.9 s while still closing its last gap.
    max_solver_error : float
        The contact solver's largest FCLib residual (relative) over the ticks: above it the
        verification fails ("solver"). The real-time engine stops at its sweep cap (the haptic
        profile's ``max_iterations``): with 200 sweeps the loads of problems/ stay within 1.1e-4;
        with 40, point tips 1-2 mm from a face's edge reached 2e-3 (1.4e-2 reported).
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
    time_per_replan_s: float = 2.0
    max_solver_error: float = 1e-3


@dataclass(frozen=True)
class PlanFileSettings:
    """What a plan file or a haptic recording must meet before ``fixplan verify`` replays it.

    The files are written with six significant digits (a recording) or in full (a plan); these
    tolerances absorb that rounding and nothing more.

    Attributes
    ----------
    quaternion_norm_tol : float
        A pose's quaternion has norm 1 within this.
    limit_rel : float
        A push in the file may exceed the hand's limits (``manipulator.max_force``,
        ``max_torque``) by this fraction: the coupling saturates at them, and the file rounds.
    push_match_rel : float
        A recorded push (``transitions[].pushes``) and the trace's coupling wrench at the same
        sample agree within this fraction of the hand's limit ...
    push_match_abs : float
        ... plus this [N or N·m]; beyond, the recording contradicts its own evidence.
    """

    quaternion_norm_tol: float = 1e-3
    limit_rel: float = 1e-3
    push_match_rel: float = 1e-4
    push_match_abs: float = 1e-3


@dataclass(frozen=True)
class PlannerSettings:
    """The loading planner (:mod:`fixplan.planner`).

    Attributes
    ----------
    clearances_m : tuple of float
        Gaps kept at the other locators along a fine path [m], tried in turn when IPOPT finds no
        path (a fixed 1 mm is an angle on a part whose locators sit close together).
    robust_grid : tuple of float
        Friction margins δ tried per transition (pushes robust to μ(1 ± δ)).
    smooth_max_m : float
        Length scale of the smooth maximum of two face planes' gaps [m].
    mesh_planes_band_m : float
        A mesh part's locator is written, in the fine planner, as the least of the planes of every
        face (or tangent plane at an edge or vertex) that is a local minimum of its distance within
        this of the nearest [m]: in a concave region those planes bound the free space the tip
        moves in (a tip 4 mm from the L's wall, on its base, keeps clear of the wall).
    ipopt_tol : float
        IPOPT's ``tol`` for a transition's NLP.
    ipopt_max_iter : int
        IPOPT's ``max_iter``.
    ipopt_constr_viol_tol : float
        IPOPT's ``constr_viol_tol``.
    settle_tol_m : float
        A re-plan first settles the observed contacts to touch within this [m].
    same_pose_m : float
        A warm start is reused when it starts within this of the start pose [m, rad].
    cost_slack : float
        The coarse search re-ranks when a transition costs more than this factor over its guess.
    lazy_slack : float
        The lazy search accepts a sequence whose fine-planned cost is within this factor of the
        best estimate of any other (1: the cheapest, as far as the learned estimates tell).
    spare_core_idle_cpus : float
        The planner runs likely next fine plans ahead on a second core (a forked child) only when
        at least this many CPUs are idle (CPU count minus the one-minute load average): on a busy
        machine the child would only compete with the parent.
    precheck_penalty : float
        A transition that fails its cheap cone check before the fine plan is made this many times
        dearer (tried after the others, never dropped).
    precheck_floor : float
        ... and at least this much dearer, so that a transition guessed free is postponed too.
    carry_cost : float
        A transition's mass-weighted length is priced ``1 + carry_cost × f``, with ``f`` the share
        of the weight its kept contacts' normals cannot carry at its start (1 in free space or on
        walls, 0 resting on base locators): the search seats the part on what holds its weight first
        where paths are otherwise alike. 0 prices length alone.
    compliant_step_rel : float
        A compliant initial guess (:mod:`fixplan.planner.fine`'s ladder) moves at most this
        fraction of the part's bounding radius per step (mass-weighted) before settling its
        kept contacts again.
    compliant_max_steps : int
        ... and takes at most this many steps.
    ladder_max_iter : int
        IPOPT's ``max_iter`` for the ladder's later formulations and the elastic diagnosis (the
        first formulation keeps ``ipopt_max_iter``): a failing transition stays cheap.
    elastic_regularisation : float
        Weight of the path energy beside the slacks' sum in the elastic diagnosis of a transition
        with no path (keeps the relaxed program well posed).
    blocking_slack_m : float
        A constraint group whose slack in that diagnosis exceeds this blocks the transition [m].
    span_rel : float
        A locator's normal row lies in the span of other rows when the least-squares residual is
        below this fraction of its norm (locators that close together, rank at the goal).
    """

    clearances_m: tuple[float, ...] = (1e-3, 1e-4)
    robust_grid: tuple[float, ...] = (0.05, 0.1, 0.2, 0.3, 0.5)
    smooth_max_m: float = 1e-4
    mesh_planes_band_m: float = 0.01
    ipopt_tol: float = 1e-9
    # successful transition programs take 14 iterations (median; p99 22, 2 of 561 over 100 on 34
    # generated free starts); the failing ones ran to 500 and were two thirds of the fine-plan time
    ipopt_max_iter: int = 150
    ipopt_constr_viol_tol: float = 1e-10
    settle_tol_m: float = 1e-10
    same_pose_m: float = 1e-9
    cost_slack: float = 1.5
    lazy_slack: float = 1.0
    spare_core_idle_cpus: float = 0.75
    precheck_penalty: float = 100.0
    carry_cost: float = 1.0
    precheck_floor: float = 1e-6
    compliant_step_rel: float = 0.05
    compliant_max_steps: int = 200
    ladder_max_iter: int = 150
    elastic_regularisation: float = 1e-4
    blocking_slack_m: float = 1e-6
    span_rel: float = 1e-6

    def ipopt_options(self, tol: float | None = None, max_iter: int | None = None) -> dict[str, Any]:
        """IPOPT's options for a transition (quiet), with ``tol`` and ``max_iter`` overridable."""
        return {
            "print_level": 0,
            "sb": "yes",
            "tol": self.ipopt_tol if tol is None else tol,
            "max_iter": int(self.ipopt_max_iter if max_iter is None else max_iter),
            "constr_viol_tol": self.ipopt_constr_viol_tol,
        }


@dataclass(frozen=True)
class SearchSettings:
    """The wrench search (:func:`fixplan.jamming.search_wrench`).

    Attributes
    ----------
    jam_margin_rel : float
        Default least relative distance of the wrench found from static balance.
    target_rel : float
        A margin target counts as met within this relative shortfall (solver accuracy).
    slip_rel : float
        A kept contact slipping at this fraction of the part's speed slides against its slip.
    role_rel : float
        A contact's normal velocity under the motion counts as zero below this (relative).
    found_rel : float
        A push whose least normal force is at most this fraction of ``F_max`` is no push.
    binding_rel : float
        A limit binds when the push reaches it within this fraction.
    limit_rel : float
        A wrench exceeds a limit beyond this fraction (round-off).
    along_rel : float
        The check's acceleration may fall short of the requested one by this fraction ...
    off_axis_rel : float
        ... and point off its axis by this (mass-weighted) fraction.
    unbounded_factor : float
        When no push within the hand's limits exists, a limit is lifted to this many times its
        value to ask whether the other alone binds (and what force or torque is needed).
    limit_fraction : float
        Headroom: the push is sought within this fraction of the hand's force and torque limits
        first (the coupling's transients, tracking errors and noise then stay within the hand);
        only where no non-jamming push exists inside it does the search use the whole limits, and
        it says so. 1 disables the headroom.
    headroom_margin_gain : float
        Where the margin found within ``limit_fraction`` stays below the weight m|g| (or the
        margin asked for), the whole limits are tried as well; their push is kept when it presses
        the kept contacts this many times harder (or reaches the weight).
    """

    jam_margin_rel: float = 1e-3
    target_rel: float = 1e-6
    slip_rel: float = 0.05
    role_rel: float = 1e-9
    found_rel: float = 1e-9
    binding_rel: float = 1e-6
    limit_rel: float = 1e-9
    along_rel: float = 1e-6
    off_axis_rel: float = 1e-4
    unbounded_factor: float = 1e3
    limit_fraction: float = 0.8
    headroom_margin_gain: float = 1.5


@dataclass(frozen=True)
class ExecutionNoise:
    """Operator imperfections: relative force noise per control period and a reaction delay.

    Used by :mod:`fixplan.planner.execute` (also importable from there) and ``fixplan robust``.
    """

    force_noise: float = 0.0  # standard deviation, relative to each wrench component's size
    latency_s: float = 0.0
    seed: int = 0


@dataclass(frozen=True)
class ExecutionSettings:
    """How the executor pushes. Speeds and accelerations are of the mass-weighted twist.

    The mass-weighted speed of a twist ``ν`` of the centre of mass is ``√(νᵀ M ν / m)`` [m/s]:
    the speed of the centre of mass for a translation, the radius-of-gyration speed for a spin.
    """

    control_rate_hz: float = 200.0  # wrench re-solves per second (held between solves)
    speed_mps: float = 0.04  # cruise speed
    # cruise speed in free flight (no contact kept): free starts 5-80 mm and up to 23 cm of path away
    # spent 1-2.5 s of their simulated load cruising at 0.1 m/s; the contact speed is the braking's
    free_speed_mps: float = 0.25
    min_speed_mps: float = 0.004  # speed kept up to the very end of a transition
    accel_mps2: float = 1.0  # largest commanded acceleration
    brake_mps2: float = 0.1  # deceleration of the speed profile toward the target
    # free flight brakes harder, down to the speed the gentle profile has soft_approach_m before the
    # target, then as gently as any transition: the same impact, a shorter approach
    free_brake_mps2: float = 0.5
    soft_approach_m: float = 0.002
    speed_time_s: float = 0.05  # the speed error is closed in about this long
    min_accel_fraction: float = 0.05  # least |acceleration| asked (of accel_mps2): never a jamming push
    max_accel_factor: float = 1.5  # the push may accelerate at most this × the acceleration asked
    friction_margin: float = 0.1  # δ: pushes robust to friction μ(1 ± δ)
    margin_N: float | None = None  # least normal force on kept contacts (default: the part's weight)
    press_fraction: float = 0.02  # force-sensor threshold as a fraction of the weight
    contact_gap_m: float = 2e-6  # a locator this close counts as in contact even when friction leaves it unloaded
    # a locator seen in contact stays in contact until its gap exceeds this: the located tolerance
    # (VerificationSettings.final_gap_m). A part is located to within it, so a contact that opens
    # by less is not lost. A tall slab on point tips rocks between its side locators by 10-90 µm
    # whenever one of them closes; at 20 µm every rock was a lost contact, the recoveries and
    # re-plans rocked it further, and 9 of 100 perturbed worlds gave up after 16 re-plans (5 of
    # 100 at 100 µm; mean re-plans per world 5.3 → 3.3). 20 µm for finding contacts too found a
    # locator a plate only passed near on its way in (an unplanned contact): hence the
    # hysteresis, on the debounced state only (a graze shorter than the dwell is not held)
    contact_hold_gap_m: float = 1e-4
    dwell_s: float = 0.01  # a pressed set counts once held this long
    stall_speed_mps: float = 1e-4
    stall_s: float = 0.12
    progress_s: float = 1.5  # a transition whose target's gap has not shrunk by progress_m for this long stalls
    progress_m: float = 5e-4
    max_retries: int = 3  # stall recoveries per transition before giving up
    # 8 verified 64 of 72 development fixtures, 4 verified 62; with time of its own per new plan
    # (VerificationSettings.time_per_replan_s) 16 took a tall held-out box from 25 to 29 of 30 worlds
    max_replans: int = 16
    settle_s: float = 0.2  # at rest with every locator pressed this long: done
    recover_s: float = 0.15  # after a lost contact, press the part back this long before re-planning
    smoothing_s: float = 0.02  # first-order lag on the applied push (0: none)
    hold_fraction: float = 0.25  # at the goal, each locator is pressed by this fraction of the weight
    # with a [robot]: a push found within the arm's joint-torque box that loads a joint beyond this
    # share of the headroom (limit_fraction of its effort) keeps the next searches within the box at
    # once; below it the next push is first sought without the box's rows (the box does not bind)
    box_binds_fraction: float = 0.9
    speed_limit_factor: float = 25.0  # speed beyond this × the cruise speed (and ≥ 1 m/s) is divergence
    # a pressed locator whose contact normal (in the part's frame) makes less than this cosine with
    # its normal at the goal presses another face of the part (a side tip under the base)
    wrong_face_cos: float = 0.5
    release_gap_m: float = 2e-3  # a part lifted off a wrong-face contact is free once every gap is this
    release_s: float = 1.5  # the lift may take at most this long
    # a state no plan leads on from (a re-plan fails there even after pressing back): lift the part
    # off and approach again, with the transition that led there set aside, at most this often
    dead_end_releases: int = 1
    # a transition that loses a contact this often in one load is a loop (pressing back and the
    # policy lead into it again): it is set aside and the part re-planned around it
    max_losses: int = 3
    carry_torque_fraction: float = 0.5  # a carried part's spin is stopped with up to this fraction of the hand's torque
    reach_factor: float = 3.0  # the part this × (farthest locator + bounding radius) from its start has diverged


@dataclass(frozen=True)
class RobustSettings:
    """The uncertainty sampled, and the planner/executor options (as ``fixplan solve``'s)."""

    samples: int = 20
    seed: int = 0
    mu_spread: float = 0.2  # friction μ_i (1 + u), u uniform in ±mu_spread
    pose_sigma_m: float = 1e-3  # start translation, per axis in the resting plane [m]
    pose_sigma_deg: float = 1.0  # start rotation about the gravity axis [deg]
    locator_sigma_m: float = 1e-4  # locator tip offset, per axis [m]
    force_noise: float = 0.05  # operator: relative force noise per control period
    latency_s: float = 0.002  # operator: reaction delay [s]
    acceleration_mps2: float = 1.0
    margin_N: float | None = None
    friction_margin: float = 0.1
    knots: int = 10
    rest_gap_m: float = 1e-9  # the nominally touching locators touch the perturbed start within this [m]
    max_penetration_m: float = 1e-6  # no locator penetrates the perturbed start by more [m]

    def check(self) -> None:
        """Raise :class:`InputError` naming the setting that is out of range (``RobustSettings.mu_spread``)."""
        n = "RobustSettings."
        checks = [
            (n + "samples", self.samples, self.samples >= 0 and self.samples == int(self.samples), "an integer ≥ 0"),
            (n + "seed", self.seed, self.seed >= 0 and self.seed == int(self.seed), "an integer ≥ 0"),
            (n + "mu_spread", self.mu_spread, 0.0 <= self.mu_spread <= 1.0, "a fraction in [0, 1]"),
            (n + "pose_sigma_m", self.pose_sigma_m, 0.0 <= self.pose_sigma_m <= 0.1, "0 .. 0.1 m"),
            (n + "pose_sigma_deg", self.pose_sigma_deg, 0.0 <= self.pose_sigma_deg <= 30.0, "0 .. 30 deg"),
            (n + "locator_sigma_m", self.locator_sigma_m, 0.0 <= self.locator_sigma_m <= 0.01, "0 .. 0.01 m"),
            (n + "force_noise", self.force_noise, 0.0 <= self.force_noise <= 1.0, "a fraction in [0, 1]"),
            (n + "latency_s [ms]", self.latency_s * 1e3, 0.0 <= self.latency_s <= 0.1, "0 .. 100 ms"),
        ]
        for name, value, ok, expected in checks:
            if not (isinstance(value, int | float) and math.isfinite(value) and ok):
                raise InputError(f"{name} must be {expected}, got {value}")

    @property
    def perturbs(self) -> bool:
        """Whether the world is perturbed at all (else every sample is the nominal world)."""
        return any(x > 0 for x in (self.mu_spread, self.pose_sigma_m, self.pose_sigma_deg, self.locator_sigma_m))

    def execution_settings(self) -> ExecutionSettings:
        """The executor's settings: the pushes' acceleration and margins, the others' defaults."""
        return ExecutionSettings(
            accel_mps2=self.acceleration_mps2, friction_margin=self.friction_margin, margin_N=self.margin_N
        )

    def profile(self) -> Settings:
        """The settings the plans and loads of a study use: the ``haptic`` profile with :meth:`execution_settings`."""
        return HAPTIC.with_(execution=self.execution_settings())

    def noise(self, seed: int) -> ExecutionNoise:
        return ExecutionNoise(force_noise=self.force_noise, latency_s=self.latency_s, seed=seed)

    def to_json(self) -> dict[str, Any]:
        return {
            "seed": self.seed,
            "mu_spread": self.mu_spread,
            "pose_sigma_m": self.pose_sigma_m,
            "pose_sigma_deg": self.pose_sigma_deg,
            "locator_sigma_m": self.locator_sigma_m,
            "force_noise": self.force_noise,
            "latency_s": self.latency_s,
            "acceleration_mps2": self.acceleration_mps2,
            "margin_N": self.margin_N,
            "friction_margin": self.friction_margin,
        }


@dataclass(frozen=True)
class WitnessSettings:
    """When a candidate motion is accepted as a sliding witness (:mod:`fixplan.jamming.sliding`).

    Attributes
    ----------
    residual_fraction : float
        The witness's dynamics residual must be below this fraction of ``Tolerances.balance_rel``.
    normal_rel : float
        A kept contact's normal acceleration counts as zero below this fraction of the motion's.
    force_rel : float
        Contact forces may leave their cones by this fraction of the force scale (round-off).
    root_rel : float
        A Newton root's residual is at most this fraction of the wrench.
    solve_rel : float
        A linear solve's residual is at most this fraction of its right-hand side.
    seed_force : float
        Newton starts with at least this normal force on a kept contact (relative).
    seed_force_open : float
        ... and on every contact when it starts from a perturbed guess.
    """

    residual_fraction: float = 1e-3
    normal_rel: float = 1e-8
    force_rel: float = 1e-9
    root_rel: float = 1e-9
    solve_rel: float = 1e-9
    seed_force: float = 1e-6
    seed_force_open: float = 1e-3


@dataclass(frozen=True)
class Numerics:
    """Cut-offs of numerical linear algebra (not physics): one value each, named for its use.

    Attributes
    ----------
    rank_tol : float
        Singular values below this count as zero in the rank of a contact Jacobian.
    rcond : float
        Relative cut-off of pseudo-inverses, least-squares steps and null spaces.
    zero_rel : float
        A length or norm counts as zero below this fraction of its reference (or of 1).
    same_time_s : float
        Two instants within this are the same [s].
    line_search_min_step : float
        A backtracking line search gives up below this step.
    stall_rel : float
        Gauss–Newton stalls when an iteration decreases its objective by less than this fraction.
    taylor_switch_rad2 : float
        Below this squared angle [rad²] series expansions replace sin/cos ratios.
    format_nudge_rel : float
        Numbers printed with a few digits are nudged by this fraction before truncation.
    clarabel_ktratio, clarabel_max_iter : float, int
        Clarabel's ``tol_ktratio`` and ``max_iter`` for the jamming programs (its gap and
        feasibility tolerances are ``Tolerances.cone_eps``).
    """

    rank_tol: float = 1e-9
    rcond: float = 1e-10
    zero_rel: float = 1e-9
    same_time_s: float = 1e-9
    line_search_min_step: float = 1e-6
    stall_rel: float = 1e-6
    taylor_switch_rad2: float = 1e-10
    format_nudge_rel: float = 1e-7
    clarabel_ktratio: float = 1e-7
    clarabel_max_iter: int = 100


@dataclass(frozen=True)
class PolicySettings:
    """The contact-state policy (:mod:`fixplan.planner.policy`): a next transition for every state.

    Attributes
    ----------
    backoff_m : float
        A state's representative pose is the located pose backed off so that every locator not in
        the state opens by this gap [m] while the state's locators keep touching (the pre-image of
        the goal, to first order).
    min_open_fraction : float
        ... and the state counts as realisable when every such locator's exact gap there is at
        least this fraction of ``backoff_m`` (no other contact closes with the state's).
    checks_per_state : int
        Candidate transitions out of a state whose first push is checked (one cone program each),
        cheapest cost-to-go first; the first that has a non-jamming push is kept.
    margin_candidates : int
        Of the checked candidates within the planner's cost slack of the cheapest, at most this many
        are compared, and the one with the most margin (least normal force on the kept contacts
        under its push) is kept.
    max_locators : int
        Above this many locators the policy covers the plan's states and the states one contact
        away from them only (2ⁿ states otherwise).
    max_verifications : int
        ``solve`` verifies at most this many plans: when the simulated load of the best sequence
        fails, the transition where it failed is set aside and the next-best sequence is tried.
    approach_samples : int
        Poses per leg of the free approach path at which every locator's exact gap is checked.
    approach_waypoint_scales : tuple of float
        The approach's detour waypoint lies this many back-offs out from the goal, tried in turn
        (:mod:`fixplan.planner.approach`).
    approach_clearance_m, approach_clearance_deg : float
        Far from the staging pose the approach keeps every locator at least
        ``approach_clearance_m + bounding radius × approach_clearance_deg`` away (at most half the
        start's least gap): the start's pose error and the tracking error are of this order.
    approach_funnel_share : float
        ... except in this last share of the way (of the part's farthest point), where the clearance
        asked shrinks linearly to half the staging pose's gap: the part closes in on the locators
        only as it comes to the staging pose.
    approach_lift_steps : int
        Detours lifted against gravity first, by that clearance × 1, 2, 4, ... (this many heights).
    """

    backoff_m: float = 2e-3
    min_open_fraction: float = 0.5
    checks_per_state: int = 4
    margin_candidates: int = 2
    max_locators: int = 8
    max_verifications: int = 3
    approach_samples: int = 40
    approach_waypoint_scales: tuple[float, ...] = (3.0, 6.0, 12.0, 25.0, 50.0, 100.0)
    approach_clearance_m: float = 2e-3
    approach_clearance_deg: float = 1.0
    approach_funnel_share: float = 0.5
    approach_lift_steps: int = 6


@dataclass(frozen=True)
class GoalSettings:
    """Finding the located (goal) pose, where every locator touches (:func:`fixplan.locating.find_goal`).

    Attributes
    ----------
    stop_gap_m : float
        Gauss–Newton stops when every |gap| is at most this [m].
    touch_gap_m : float
        A pose touches every locator when every |gap| is at most this [m] (a solved goal is exact:
        much tighter than :attr:`Tolerances.goal_gap_m`, which a given goal must meet).
    max_iterations : int
        Gauss–Newton iterations from the start pose ...
    search_iterations : int
        ... and per run of the wider search (a run that converges takes fewer than 30).
    max_turn_rad : float
        Largest rotation of one Gauss–Newton step [rad] ...
    max_shift_rel : float
        ... and largest translation, as a fraction of the part's bounding radius.
    face_normal_cos : float
        A locator touches its named face when its contact normal is within ``acos`` of this of the
        face's normal (a tip touching the face's edge or the wrong face is not on it).
    turns_deg : tuple of float
        The wider search's starts: the start turned by each of these angles [deg] (both ways)
        about each body axis (3D) or in the plane (2D), nearest first, then the part's symmetry
        turns (90°, 120°, 180°: 23 in 3D, 3 in 2D) composed with the start.
    """

    stop_gap_m: float = 1e-12
    touch_gap_m: float = 1e-10
    max_iterations: int = 100
    search_iterations: int = 40
    max_turn_rad: float = 0.2
    max_shift_rel: float = 0.5
    face_normal_cos: float = 1.0 - 1e-9
    turns_deg: tuple[float, ...] = (15.0, 30.0, 45.0, 60.0)


@dataclass(frozen=True)
class ClusterSettings:
    """Reaching a Dask scheduler (:mod:`fixplan.cluster`).

    Attributes
    ----------
    connect_timeout_s : float
        The whole connection — TCP connect (retried while refused), Dask's handshake and the
        scheduler's answer to an ``identity`` request, then the client's registration — must
        finish within this [s]; else exit 2. The documentation promises exit 2 within 10 s of
        the command's start (README, ``fixplan robust``): this plus starting Python and reading
        the fixture (about 2 s) must stay below that.
    """

    connect_timeout_s: float = 5.0


@dataclass(frozen=True)
class MeshSettings:
    """Triangle-mesh parts (:mod:`fixplan.geometry.mesh`): checks at load and point queries.

    Attributes
    ----------
    degenerate_rel : float
        A triangle is degenerate when twice its area is at most this fraction of its longest
        edge squared (the sine of its largest angle, near 0 or 180°): removed at load.
    same_point_rel : float
        Two closest points within this fraction of the part's bounding radius are one (a tip
        over an edge is closest to both faces there at one point: one contact).
    coplanar_rel : float
        Two triangles are coplanar when the volumes of the tetrahedra their vertices span are at
        most this fraction of the part's bounding radius cubed (self-intersection test).
    wedge_rel : float
        A direction lies on a triangle's wedge (self-intersection test of two triangles with one
        shared vertex) when its coordinates along the wedge's edges are at least ``-wedge_rel``.
    contact_band_m : float
        :meth:`Mesh.contacts` returns every local minimum of the distance within this of the
        nearest [m]: a spherical tip in a concave corner touches two faces.
    grid_cell_min_rel : float
        The self-intersection check's grid cell is at least this fraction of the largest
        triangle's extent (a mesh of slivers does not make a grid of billions of cells).
    step_tolerance_m : float
        A STEP part is tessellated to this chordal tolerance [m] (the largest distance between a
        triangle and the surface) unless ``workpiece.tolerance`` says otherwise.
    step_angular_rad : float
        ...and to at most this angle between neighbouring triangles on a curved face
        (OpenCASCADE's angular deflection; its default).
    tree_leaf_triangles : int
        At most this many triangles in a leaf of the point queries' AABB tree (measured on a
        5·10⁴-triangle part: 8 about as fast as 4, 2 and 16 slower).
    query_cache_radius_m : float
        The engine's step remembers, at each locator's full query, the triangles near enough to
        answer exactly for a tip within this distance of that point [m]; farther, it queries the
        tree again (:func:`fixplan.geometry._mesh_kernels.contacts_near`). The answer does not
        depend on it, only the speed: larger remembers more triangles and queries less often.
    query_cache_triangles : int
        At most this many triangles remembered per locator (more: no memory, a full query each step).
    hole_probe_m : float
        A ``[[workpiece.hole]]`` of a mesh part whose bottom lies on the surface is blind when the
        point this far past its bottom (along its axis, deeper) is inside the part [m]: the mesh
        models the hole's bore, and its bottom is the bore's floor. Outside, the hole is through
        (a primitive part never models its holes: its rule is the bottom on or outside the surface).
    """

    degenerate_rel: float = 1e-12
    same_point_rel: float = 1e-9
    coplanar_rel: float = 1e-12
    wedge_rel: float = 1e-12
    contact_band_m: float = 1e-6
    grid_cell_min_rel: float = 1e-6
    tree_leaf_triangles: int = 8
    query_cache_radius_m: float = 1e-4
    query_cache_triangles: int = 256
    hole_probe_m: float = 1e-5
    step_tolerance_m: float = 1e-4
    step_angular_rad: float = 0.5


@dataclass(frozen=True)
class PinSettings:
    """Pins in holes and pegs in bores (:mod:`fixplan.geometry.pins`): the closed-form contacts.

    Attributes
    ----------
    rim_samples : int
        Angles at which a rim circle's distance is sampled before Newton refines the extreme
        (the distance along a circle of an ellipse's projection has at most 4 extremes).
    newton_steps : int
        Newton steps on the extreme's angle; quadratic convergence reaches machine precision in 4-5.
    golden_steps : int
        Golden-section steps on a tip contact's angle (between the samples around the least):
        0.618⁶⁰ of 2·2π/rim_samples is below 1e-13 rad.
    coaxial_rel : float
        A rim whose tilt from the other axis, or an offset, is below this fraction of its radius
        is coaxial (a face lying flat: its contact is put at the face's centre).
    axis_angle_rad : float
        A pin enters its hole at the located pose when their axes are antiparallel within this.
    face_points : int
        The engine's points of a tip face on a blind hole's bottom (the face's rim at that many
        angles from its deepest point, :mod:`fixplan.engine.pin_slots`): a face resting flat is
        held by its disk, not by the deepest point alone (one point lets it wobble like a coin).
        The same for a pin's tip on the part's face around its hole (a pin that misses its hole:
        :func:`fixplan.geometry.pins.tip_face_contacts`). The closed forms (:mod:`fixplan.geometry.pins`,
        the cone programs) keep the deepest point.
    face_arc_inset : float
        A tip partly over the mouth rests on the face along a crescent: its edge's arc over the
        face adds a point this fraction of the arc in from each of its ends (with ``face_points``
        above 1), so the tip cannot tip about one point of it.
    """

    rim_samples: int = 64
    newton_steps: int = 8
    golden_steps: int = 60
    coaxial_rel: float = 1e-9
    axis_angle_rad: float = 0.01
    face_points: int = 4
    face_arc_inset: float = 0.1


@dataclass(frozen=True)
class InsertionSettings:
    """Planning and verifying a part's insertion onto pins or into a bore (:mod:`fixplan.planner.insertion`).

    Heights are along the insertion axis (the pins' axis, or the bore's), above the located pose.

    Attributes
    ----------
    lead_m : float
        The staging pose lifts the holes' mouths this far above the first tip to engage.
    engage_margin_m : float
        An insertion step ends this far past both chamfers of the pin it engages (the pin is then
        in the hole's bore, not on its chamfer).
    approach_speed_mps, insert_speed_mps : float
        The reference's speed in free flight and along the pins' axis.
    axial_omega_radps, lateral_omega_radps, rot_omega_radps : float
        The hand's servo toward the guide per coordinate (natural frequency, critically damped;
        the gains scale with the part's mass and inertia). Laterally soft, as a remote-centre
        compliance: a chamfer's push moves the part sideways by its pose error with a force far
        below the insertion push. Below the coupling's 32 rad/s.
    push_accel_mps2 : float
        The acceleration along the axis each insertion step's non-jamming push is searched for.
    seat_press : float
        The seating push along the axis, in the part's weights (beyond carrying it).
    seat_side : float
        The seating push toward the round pin's (or bore's) contact, in the part's weights; as much
        into each stop (a locator facing across the axis).
    stop_clearance_m : float
        With stops and one round pin, the part goes down turned about the pin's axis away from them
        by the least turn that opens every stop's gap this much (a face sliding down along a stop
        catches its tip on the face's edge), then turns into them on the rests.
    stop_turn_max_rad : float
        That turn at most.
    seat_turn_speed_mps : float
        The turn into the stops runs at this speed at the farthest stop (a velocity loop up to the
        stops' part of the seating push): a stop met faster knocks the part's hole around its pin.
    seat_turn_gain : float
        That loop's gain at most this × the part's inertia about the pin's axis per control tick
        (higher gains on the part's speed ring through the haptic coupling).
    dwell_s : float
        A state (engaged pins, pressed rests) counts once held this long.
    stall_s, stall_progress_m : float
        An insertion step that does not move ``stall_progress_m`` along the axis in ``stall_s`` has
        stalled: the run fails and says which pin did not enter and by how much it missed.
    settle_s : float
        At the goal state this long with the seating push: located.
    time_factor, time_base_s : float
        The run's time limit: ``time_factor`` × the guide's duration + ``time_base_s``.
    align_tol_m, align_tol_rad : float
        The approach ends (and the insertion begins) once the part is this close to the staging
        pose, in position and in angle: a part still turning as it meets its pins tilts in them.
    delay_bandwidth : float
        In a haptic session whose operator follows the guidance late (``HapticRigSettings.
        operator_reaction_s``, plus the guidance's own update period, ``τ`` in all), each servo
        frequency is held to this over ``τ`` [rad]: ``ω τ = 0.3`` keeps about 40° of the
        critically damped servo's 76° phase margin (:class:`fixplan.planner.insertion.InsertionRun`).
    align_capture_share : float
        ... and every pin's hole (a shaft's leading end) is within this share of its capture
        (play + chamfers) of where the staging pose puts it, across the axis: the tip is aimed
        into the mouth, which a sharp bore's capture (its play alone, 10 µm) makes the binding
        condition (the part's origin may be far from its tip, and a turn within ``align_tol_rad``
        moves the tip by its lever).
    axis_play_rel : float
        Slack on the radial play in the final check (relative): the hole's axis within
        ``(D − d)/2 · (1 + axis_play_rel)`` of the pin's, at the mouth and at the pin's tip.
    retries : int
        The recovery's budget (:mod:`fixplan.planner.insertion_policy`): a run that stalls, or
        loses a pin it had engaged, backs off and tries again at most this many times, then fails.
    recovery_time_s : float
        The recovery's time budget: the run's time limit grows by at most this much, and a
        recovery that has spent it fails.
    backoff_min_m : float
        A back-off rises at least this far along the axis: to the end of the latest stage at least
        this far above the part (the staging pose when none is).
    """

    lead_m: float = 0.002
    engage_margin_m: float = 0.0005
    approach_speed_mps: float = 0.05
    insert_speed_mps: float = 0.02
    axial_omega_radps: float = 12.0
    lateral_omega_radps: float = 4.0
    rot_omega_radps: float = 12.0
    push_accel_mps2: float = 0.2
    seat_press: float = 1.0
    seat_side: float = 0.3
    stop_clearance_m: float = 0.001
    stop_turn_max_rad: float = 0.1
    seat_turn_speed_mps: float = 0.01
    seat_turn_gain: float = 0.25
    dwell_s: float = 0.01
    stall_s: float = 0.6
    stall_progress_m: float = 0.0002
    settle_s: float = 0.2
    time_factor: float = 3.0
    time_base_s: float = 2.0
    axis_play_rel: float = 0.05
    align_tol_m: float = 0.0001
    align_tol_rad: float = 0.001
    align_capture_share: float = 0.25
    delay_bandwidth: float = 0.3
    retries: int = 3
    recovery_time_s: float = 6.0
    backoff_min_m: float = 0.001


@dataclass(frozen=True)
class RobotSettings:
    """The arm that carries the part (:mod:`fixplan.robot`).

    Attributes
    ----------
    ik_tol : float
        Inverse kinematics stops when the tool's pose error (‖log(X⁻¹ X_target)‖: metres and
        radians together) is below this.
    ik_max_iter : int
        Damped least-squares steps per knot at most.
    ik_halvings : int
        A step that does not lower the pose error is halved at most this many times.
    ik_damping : float
        The damping λ² of the least-squares step ``Δq = Jᵀ (J Jᵀ + λ² I)⁻¹ e``.
    ik_starts : int
        Configurations tried for the first knot (the neutral one, then seeded random ones within
        the joint limits); the one with the largest joint-limit margin is kept.
    ik_seed : int
        The seed of those random starts (the answer is the same on every run).
    max_step_rad : float
        The largest joint motion between consecutive knots of a continuous path; beyond it the
        arm flipped to another branch (an elbow or wrist flip the plan's motion does not ask for).
    reach_tol_m : float
        A knot whose best pose error stays above this is out of reach.
    point_radius_m : float
        A point locator tip is measured as a sphere of this radius in the clearance check.
    clearance_every_s : float
        The verification measures the links' clearance along the simulated load this often [s]
        (on the loop's trace, so at most as often as ``verification.trace_every_s``).
    """

    ik_tol: float = 1e-10
    ik_max_iter: int = 200
    ik_halvings: int = 30
    ik_damping: float = 1e-6
    ik_starts: int = 24
    ik_seed: int = 0
    max_step_rad: float = 0.5
    reach_tol_m: float = 1e-6
    point_radius_m: float = 1e-6
    clearance_every_s: float = 0.01


@dataclass(frozen=True)
class ClampSettings:
    """Clamping after loading (:mod:`fixplan.clamping`): the least clamp forces, the order, the check in the engine.

    Attributes
    ----------
    preload_N : float
        Least normal force every locator keeps once clamped, under every load.
    balance_rel : float
        A clamping prefix holds when the least ``M⁻¹``-weighted balance residual of gravity and
        its clamps, over the wrench's own norm, is at most this (as the classifier's ``balance_rel``).
    residual_N : float
        Largest equilibrium or cone residual [N, N·m] accepted in an answer of the force program.
    lift_rel : float
        In a failure's explanation, a locator lifts when its normal acceleration exceeds this
        fraction of the largest (it is kept below).
    spin_rel : float
        ... and the part tips (not slides) when its angular acceleration times its size exceeds
        this fraction of the linear one.
    ramp_s, settle_s, hold_s : float
        In the engine: each clamp ramps to its force over ``ramp_s`` (the hand holding the part),
        the part settles ``settle_s`` after the hand lets go, each load ramps over ``ramp_s`` and
        is held ``hold_s``.
    displacement_m : float
        The part has not moved when no point of it is farther than this from its located pose
        (1e-9 m: rigid contacts, in principle).
    contact_N : float
        In the engine, a locator touching with less normal force than this is reported as unloaded.
    max_order_clamps : int
        The order search tries subsets of at most this many clamps (2ⁿ cone programs).
    direction_rel : float
        A clamp's direction is within its tip's friction cone when its tangential part is at most
        ``μ`` times its normal part plus this (round-off of a direction given along the normal).
    axis_rel : float
        In a tipping explanation, a locator lies on the tipping axis when it is within this
        fraction of the part's size of it.
    """

    preload_N: float = 1.0
    balance_rel: float = 1e-6
    residual_N: float = 1e-6
    lift_rel: float = 1e-3
    spin_rel: float = 0.1
    ramp_s: float = 0.05
    settle_s: float = 0.05
    hold_s: float = 0.1
    displacement_m: float = 1e-9
    contact_N: float = 1e-6
    max_order_clamps: int = 12
    direction_rel: float = 1e-9
    axis_rel: float = 0.05


@dataclass(frozen=True)
class Settings:
    """One of each group: what a profile selects."""

    name: str = "default"
    tolerances: Tolerances = field(default_factory=Tolerances)
    engine: EngineSettings = field(default_factory=EngineSettings)
    haptic: HapticRigSettings = field(default_factory=HapticRigSettings)
    verification: VerificationSettings = field(default_factory=VerificationSettings)
    planner: PlannerSettings = field(default_factory=PlannerSettings)
    search: SearchSettings = field(default_factory=SearchSettings)
    numerics: Numerics = field(default_factory=Numerics)
    execution: ExecutionSettings = field(default_factory=ExecutionSettings)
    witness: WitnessSettings = field(default_factory=WitnessSettings)
    robust: RobustSettings = field(default_factory=RobustSettings)
    policy: PolicySettings = field(default_factory=PolicySettings)
    goal: GoalSettings = field(default_factory=GoalSettings)
    cluster: ClusterSettings = field(default_factory=ClusterSettings)
    plan_file: PlanFileSettings = field(default_factory=PlanFileSettings)
    mesh: MeshSettings = field(default_factory=MeshSettings)
    pins: PinSettings = field(default_factory=PinSettings)
    insertion: InsertionSettings = field(default_factory=InsertionSettings)
    robot: RobotSettings = field(default_factory=RobotSettings)
    clamp: ClampSettings = field(default_factory=ClampSettings)

    def with_(self, **changes: Any) -> Settings:
        """A copy with some groups replaced."""
        return replace(self, **changes)


_STRICT_TOLERANCES = Tolerances(balance_rel=1e-8, cone_eps=1e-10, slip_rel=1e-8)

PROFILES: dict[str, Settings] = {
    "default": Settings(),
    # the loop's engine bounds its work per tick: a haptic-grade residual and at most 1000 NSGS
    # sweeps (0.4-1 µs a sweep with six contacts, measured on gen-box-321-s2026-003: a capped step
    # takes about 1 ms, a missed deadline the loop counts). At 40 sweeps 3 of the 8 generated
    # fixtures in problems/ ended their load with residuals of 1.2e-3 to 3.2e-3 (point tips near an
    # edge: 1.4e-2); at 200 they stay within 1.1e-4, but a free-start box-321-free (seed 303, 000)
    # reached 1.9e-3 in 359 of 2903 steps and a plate 1.8e-3: 1.1e-4 and 9e-4 at 1000 sweeps. The
    # thresholds stay the planner's so the executor's verdicts agree with the plan's
    "haptic": Settings(name="haptic", engine=EngineSettings(tolerance=1e-6, max_iterations=1000)),
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
