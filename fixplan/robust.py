"""Robustness under uncertainty: one nominal plan, verified on N perturbed worlds.

The plan is made once on the nominal fixture, as ``fixplan solve`` makes it: verified in the
nominal world, and where the simulated load of the best sequence fails, the next sequence that
loads (:func:`fixplan.planner.solve.solve`). The study measures the plan a user would be handed;
when no sequence loads in the nominal world, the best one is studied all the same. Sample ``k``
is a perturbed world drawn from ``np.random.default_rng([seed, k])`` — deterministic, whatever
process or machine runs it (:func:`perturbed_fixture`):

1. friction: each locator's ``μ_i (1 + u_i)``, ``u_i`` uniform in ``±mu_spread``, clipped at 0;
2. locator positions: each tip moved by normal noise of ``locator_sigma_m`` per axis, so the
   located (goal) pose moves with them (recomputed from the geometry);
3. start pose: the centre of mass moved by normal noise of ``pose_sigma_m`` per axis, projected
   on the plane normal to gravity (the plane of the resting contacts), and the part turned about
   the gravity axis (3D) or in the plane (2D) by normal noise of ``pose_sigma_deg``; then the
   locators the part rests on nominally are made to touch again (Gauss–Newton on their gaps,
   least-norm steps, as :func:`fixplan.locating.solve_goal` does for all locators). A draw
   whose start does not rest on exactly the nominal locators (a touching gap above 1e-9 m, any
   other locator within touching distance or penetrating) is redrawn from the same generator;
4. the operator: :class:`~fixplan.planner.execute.ExecutionNoise` with ``force_noise`` and
   ``latency_s`` and a seed from the same generator.

Each sample runs :func:`fixplan.planner.verify.verify` with the nominal plan's policy from the
nominal start state, the executor's settings as ``solve`` uses them, and a re-planner on the
perturbed fixture. The success rate carries a Wilson 95 % interval (:func:`wilson_interval`).
Samples run as Dask tasks (:mod:`fixplan.cluster`).
"""

from __future__ import annotations

import dataclasses
import math
import re
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from fixplan import locating
from fixplan.errors import FixplanError, InfeasibleError, InputError
from fixplan.locating import contact_set, locator_contact, locator_gaps, solve_goal, with_goal
from fixplan.model import Fixture, Locator
from fixplan.planner.execute import ExecutionNoise, Step
from fixplan.settings import DEFAULT, RobustSettings
from fixplan.spatial import Pose

if TYPE_CHECKING:
    from fixplan.planner.policy import Policy
    from fixplan.planner.solve import PlanResult, PlanStatus
    from fixplan.planner.verify import Verification

FloatArray = NDArray[np.float64]

Z95 = 1.959963984540054  # the standard normal's 97.5 % quantile
MAX_DRAWS = 100  # start-pose redraws before a sample is declared impossible


def wilson_interval(k: int, n: int, z: float = Z95) -> tuple[float, float] | None:
    """Wilson score interval for ``k`` successes in ``n`` trials (None when ``n = 0``).

    ``(p̂ + z²/2n ± z √(p̂(1−p̂)/n + z²/4n²)) / (1 + z²/n)`` with ``p̂ = k/n``: unlike the normal
    approximation it stays inside [0, 1] and is not empty at ``k = 0`` or ``k = n``.
    """
    if n <= 0:
        return None
    if not 0 <= k <= n:
        raise InputError(f"expected 0 ≤ successes ≤ trials, got {k} of {n}")
    p = k / n
    z2 = z * z
    denom = 1.0 + z2 / n
    centre = (p + z2 / (2 * n)) / denom
    half = z / denom * math.sqrt(p * (1 - p) / n + z2 / (4 * n * n))
    return max(0.0, centre - half), min(1.0, centre + half)


# -- the perturbed world ---------------------------------------------------------------------------
@dataclass(frozen=True)
class Perturbation:
    """What sample ``k`` changed (for a report and for tests)."""

    sample: int
    friction: dict[str, float]
    locator_offsets_m: dict[str, list[float]]
    start: Pose
    draws: int  # start-pose draws (1 unless a draw was rejected)
    noise_seed: int

    def to_json(self) -> dict[str, Any]:
        return {
            "sample": self.sample,
            "friction": self.friction,
            "locator_offsets_m": self.locator_offsets_m,
            "start": self.start.to_json(),
            "draws": self.draws,
            "noise_seed": self.noise_seed,
        }


def _rest_on(fixture: Fixture, locators: Sequence[Locator], pose: Pose, touching: Sequence[str]) -> Pose:
    """Gauss–Newton (least-norm steps) on the gaps of ``touching``: the nearby pose where they touch."""
    wp = fixture.workpiece
    chosen = [loc for loc in locators if loc.name in touching]
    if not chosen:
        return pose
    for _ in range(50):
        contacts = [locator_contact(wp, pose, loc) for loc in chosen]
        gaps = np.array([c.gap_m for c in contacts])
        if np.max(np.abs(gaps)) <= 1e-13:
            break
        c_w = pose.point_world_from_body(wp.com_body)
        G = np.array([c.jacobian(c_w)[0] for c in contacts])
        pose = pose.retract(-np.linalg.lstsq(G, gaps, rcond=DEFAULT.numerics.rcond)[0], wp.com_body)
    return pose


def draw_world(fixture: Fixture, sample: int, settings: RobustSettings) -> tuple[Fixture, ExecutionNoise, Perturbation]:
    """The perturbed fixture, the operator's noise and what changed, for sample ``sample``."""
    if not settings.perturbs:
        noise_seed = int(np.random.default_rng([settings.seed, sample]).integers(0, 2**31 - 1))
        nothing = Perturbation(sample, {}, {}, fixture.start, 0, noise_seed)
        return fixture, settings.noise(noise_seed), nothing
    rng = np.random.default_rng([settings.seed, sample])
    d = fixture.dimension
    n = len(fixture.locators)
    # every number is drawn whatever the sigmas, so a sample's draws do not depend on them
    u = rng.uniform(-1.0, 1.0, n) * settings.mu_spread
    offsets = rng.standard_normal((n, d)) * settings.locator_sigma_m
    noise_seed = int(rng.integers(0, 2**31 - 1))
    locators = tuple(
        dataclasses.replace(loc, friction=max(loc.friction * (1.0 + float(ui)), 0.0), p_world=loc.p_world + off)
        for loc, ui, off in zip(fixture.locators, u, offsets, strict=True)
    )
    touching = list(dict.fromkeys(c.owner for c in contact_set(fixture, "start").contacts if c.kind == "locator"))
    wp = fixture.workpiece
    g = np.asarray(fixture.gravity, dtype=float)
    g_hat = g / np.linalg.norm(g) if np.linalg.norm(g) > 0 else np.eye(d)[-1]
    tol_touch = fixture.tolerances.touch_m
    start: Pose | None = None
    draws = 0
    while start is None:
        draws += 1
        if draws > MAX_DRAWS:
            raise InfeasibleError(
                f"sample {sample}: no start pose resting on exactly {{{', '.join(touching)}}} in {MAX_DRAWS} draws "
                f"(pose sigma {settings.pose_sigma_m:g} m, {settings.pose_sigma_deg:g} deg)"
            )
        dp = rng.standard_normal(d) * settings.pose_sigma_m
        dp -= (dp @ g_hat) * g_hat  # in the resting plane
        angle = float(rng.standard_normal()) * math.radians(settings.pose_sigma_deg)
        twist = np.concatenate([dp, [angle]]) if d == 2 else np.concatenate([dp, angle * -g_hat])
        trial = _rest_on(fixture, locators, fixture.start.retract(twist, wp.com_body), touching)
        gaps = locator_gaps(wp, trial, locators)
        rest = [i for i, loc in enumerate(locators) if loc.name in touching]
        free = [i for i, loc in enumerate(locators) if loc.name not in touching]
        if rest and np.max(np.abs(gaps[rest])) > settings.rest_gap_m:
            continue
        if free and np.min(gaps[free]) <= tol_touch:
            continue
        if np.min(gaps) < -settings.max_penetration_m:
            continue
        start = trial
    goal_given = fixture.goal_given
    if goal_given is not None:
        res = solve_goal(wp, locators, goal_given)
        goal_given = res.pose if res.converged else None
    # located again: raises InfeasibleError if no pose touches every locator
    try:
        perturbed = with_goal(dataclasses.replace(fixture, locators=locators, start=start, goal_given=goal_given))
    except InfeasibleError as exc:
        moved = max(float(np.linalg.norm(off)) for off in offsets) if len(offsets) else 0.0
        raise InfeasibleError(
            f"world {sample} has no located pose: with its locators moved by up to {moved * 1e3:.3g} mm, {exc}"
        ) from exc
    what = Perturbation(
        sample,
        {loc.name: loc.friction for loc in locators},
        {loc.name: [float(x) for x in off] for loc, off in zip(locators, offsets, strict=True)},
        start,
        draws,
        noise_seed,
    )
    return perturbed, settings.noise(noise_seed), what


def draw_pin_world(
    fixture: Fixture, sample: int, settings: RobustSettings
) -> tuple[Fixture, ExecutionNoise, Perturbation]:
    """The perturbed world of a fixture with pins or bores, for sample ``sample``.

    The pose error of the part in the hand, seen from the part: the pins, bores and rests moved
    together by normal noise of ``pose_sigma_m`` per axis normal to the insertion axis and turned
    about it by ``pose_sigma_deg`` (:func:`fixplan.planner.insertion.shifted_world`), while the plan
    guides the part to the nominal pins (a start touching them moves with them); each pin's, bore's and rest's μ times ``1 + u``, ``u``
    uniform in ``±mu_spread``; the operator's noise. The start stays.
    """
    from fixplan.locating import insertion_axis
    from fixplan.planner.insertion import shifted_world

    rng = np.random.default_rng([settings.seed, sample])
    u = insertion_axis(fixture)
    e1 = np.cross(u, [1.0, 0.0, 0.0] if abs(u[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(u, e1)
    xy = rng.standard_normal(2) * settings.pose_sigma_m
    yaw = math.radians(float(rng.standard_normal()) * settings.pose_sigma_deg)
    owners: list[Any] = [*fixture.locators, *fixture.pins, *fixture.bores]
    spread = rng.uniform(-1.0, 1.0, len(owners)) * settings.mu_spread
    noise_seed = int(rng.integers(0, 2**31 - 1))
    mu = {o.name: max(o.friction * (1.0 + float(k)), 0.0) for o, k in zip(owners, spread, strict=True)}
    world = dataclasses.replace(
        fixture,
        locators=tuple(dataclasses.replace(o, friction=mu[o.name]) for o in fixture.locators),
        pins=tuple(dataclasses.replace(o, friction=mu[o.name]) for o in fixture.pins),
        bores=tuple(dataclasses.replace(o, friction=mu[o.name]) for o in fixture.bores),
    )
    offset = float(xy[0]) * e1 + float(xy[1]) * e2
    # a part that starts touching (a shaft resting in a chamfer) rests where the world put it: it moves too
    touching = bool(contact_set(fixture, "start").contacts)
    world = shifted_world(world, offset, yaw, with_start=touching)
    what = Perturbation(sample, mu, {"pins": [float(x) for x in offset] + [yaw]}, fixture.start, 1, noise_seed)
    return world, settings.noise(noise_seed), what


def perturbed_fixture(fixture: Fixture, sample_seed: int, settings: RobustSettings) -> tuple[Fixture, ExecutionNoise]:
    """The perturbed world of sample ``sample_seed`` (drawn from ``default_rng([settings.seed, k])``)."""
    fx, noise, _ = draw_world(fixture, sample_seed, settings)
    return fx, noise


# -- one sample ------------------------------------------------------------------------------------
def failure_cause(verification: Verification) -> str | None:
    """A short category for a failed verification (None when it passed).

    The executor's own failure kind (``ExecutionLog.failure_kind``: lost contact, unplanned
    contact, replan failed, stall, diverged, timeout) when it failed, else the first failed check
    of the verification (final gap, penetration, limits).
    """
    if verification.passed:
        return None
    ex = verification.execution
    if ex is not None and ex.failure_kind is not None:
        return ex.failure_kind
    checks = [c for c in verification.failed_checks if c != "executor"]
    return checks[0] if checks else "other"


def _transition(verification: Verification) -> int | None:
    if verification.passed:
        return None
    ex = verification.execution
    if ex is not None and ex.outcome == "failed" and ex.transition_at_end:
        return int(ex.transition_at_end)
    m = re.search(r"transition (\d+)", verification.reason)
    return int(m.group(1)) if m else None


def verify_sample(
    fixture: Fixture,
    start_state: frozenset[str],
    steps: Sequence[Step],
    sample: int,
    settings: RobustSettings,
    policy: Policy | None = None,
) -> Verification:
    """Verify the nominal ``steps`` on the perturbed world ``sample`` (the full verification).

    ``policy`` (the nominal plan's, :mod:`fixplan.planner.policy`) is what the executor takes from a
    state the plan does not expect, before it re-plans in the perturbed world.
    """
    from fixplan.planner.solve import Planner
    from fixplan.planner.verify import verify

    if fixture.has_pins:  # the staged insertion, its pins and rests where the plan does not expect them
        from fixplan.planner.insertion import plan_insertion, verify_insertion

        world, noise, _ = draw_pin_world(fixture, sample, settings)
        return verify_insertion(world, plan_insertion(fixture), noise=noise)
    world, noise = perturbed_fixture(fixture, sample, settings)
    profile = settings.profile()
    planner = Planner(world, knots=settings.knots, settings=profile)
    return verify(
        world, start_state, list(steps), settings=profile, noise=noise, replan=planner.replan,
        policy=policy, avoid=planner.avoid,
    )  # fmt: skip


def verify_on_world(
    fixture: Fixture, result: PlanResult, sample: int, settings: RobustSettings
) -> tuple[PlanResult, dict[str, Any]]:
    """``fixplan solve --perturb-seed``: the nominal ``result`` verified on world ``sample``, as ``robust`` does.

    Returns the plan with that verification and its status (``planned`` when it passed, else
    ``unverified``), and what the world changed (JSON-ready). An infeasible plan is returned as it is.
    """
    from fixplan.planner.solve import plan_steps

    _, _, what = (draw_pin_world if fixture.has_pins else draw_world)(fixture, sample, settings)
    info = {**what.to_json(), "settings": settings.to_json()}
    if result.status == "infeasible":
        return result, info
    start_state = locating.start_state(fixture)
    t0 = time.perf_counter()
    v = verify_sample(fixture, start_state, plan_steps(result.transitions), sample, settings, result.policy)
    timings = {**result.timings, "verify_s": time.perf_counter() - t0}
    where = f"on perturbed world {sample} (seed {settings.seed})"
    status: PlanStatus
    if v.passed:
        status, reason = "planned", f"verified {where}"
    else:
        status, reason = "unverified", f"verification {where} failed ({failure_cause(v)}): {v.reason}"
    info["cause"] = failure_cause(v)
    info["transition"] = _transition(v)
    return dataclasses.replace(result, status=status, reason=reason, verification=v, timings=timings), info


def run_sample(
    sample: int,
    fixture: Fixture,
    start_state: frozenset[str],
    steps: Sequence[Step],
    settings: RobustSettings,
    policy: Policy | None = None,
) -> dict[str, Any]:
    """One Dask task: the verdict on world ``sample`` as a small dict (JSON-ready)."""
    t0 = time.perf_counter()
    try:
        v = verify_sample(fixture, start_state, steps, sample, settings, policy)
    except (FixplanError, np.linalg.LinAlgError) as exc:
        # a world whose locators admit no located pose fails the fixture's design, not the plan
        cause = "no located pose" if isinstance(exc, InfeasibleError) else "error"
        return {
            "seed": sample, "passed": False, "transition": None, "cause": cause, "reason": str(exc),
            "replans": 0, "retries": 0, "sim_time_s": None, "wall_time_s": time.perf_counter() - t0,
        }  # fmt: skip
    ex = v.execution
    return {
        "seed": sample,
        "passed": bool(v.passed),
        "transition": _transition(v),
        "cause": failure_cause(v),
        "reason": v.reason,
        "replans": int(ex.counts["replans"]) if ex is not None else 0,
        # the pin insertion's policy: back-offs and re-entries after a stall or a lost pin
        "retries": int(ex.counts.get("retries", 0)) if ex is not None else 0,
        "sim_time_s": None if v.duration_s is None else float(v.duration_s),
        "wall_time_s": time.perf_counter() - t0,
    }


# -- the study -------------------------------------------------------------------------------------
@dataclass
class RobustResult:
    """The success rate of one nominal plan over perturbed worlds, with what failed and why."""

    samples: int
    succeeded: int
    failures: list[dict[str, Any]]  # seed, transition, cause, reason
    plan_status: str
    plan_reason: str
    wall_time_s: float
    settings: RobustSettings
    outcomes: list[dict[str, Any]] = field(default_factory=list)  # every sample, in seed order
    sequence: list[tuple[str, ...]] = field(default_factory=list)

    @property
    def success_rate(self) -> float | None:
        return self.succeeded / self.samples if self.samples else None

    @property
    def interval(self) -> tuple[float, float] | None:
        return wilson_interval(self.succeeded, self.samples)

    def to_json(self) -> dict[str, Any]:
        iv = self.interval
        return {
            "samples": self.samples,
            "succeeded": self.succeeded,
            "success_rate": self.success_rate,
            "interval": None if iv is None else [iv[0], iv[1]],
            "failures": [{k: f[k] for k in ("seed", "transition", "cause", "reason")} for f in self.failures],
            "plan_status": self.plan_status,
            "plan_reason": self.plan_reason,
            "sequence": [list(s) for s in self.sequence],
            "outcomes": [
                {k: o[k] for k in ("seed", "passed", "transition", "cause", "replans", "retries", "sim_time_s")}
                for o in self.outcomes
            ],
            "settings": {"samples": self.samples, **self.settings.to_json()},
            "wall_time_s": self.wall_time_s,
        }


def nominal_plan(fixture: Fixture, settings: RobustSettings) -> tuple[PlanResult, frozenset[str], list[Step]]:
    """The plan ``solve`` delivers on the nominal world, the start state and the executor's steps.

    Verified as ``solve`` verifies (its fall-back to the next sequence included): the first-ranked
    sequence is not always the one that loads (a tall slab whose best-priced order rocked it off its
    side locators in the nominal world loaded by the second), and a study of a plan ``solve`` would
    not hand out measures nothing a user gets.
    """
    from fixplan.planner.solve import plan_steps, solve

    result = solve(fixture, run_verification=True, settings=settings.profile(), knots=settings.knots)
    start_state = locating.start_state(fixture)
    return result, start_state, plan_steps(result.transitions)


def robust(
    fixture: Fixture,
    settings: RobustSettings | None = None,
    *,
    client: Any = None,
    scheduler: str | None = None,
    processes: bool = True,
    progress: Callable[[int, int], None] | None = None,
) -> RobustResult:
    """Plan once on ``fixture`` and verify the plan on ``settings.samples`` perturbed worlds.

    The samples run on ``client`` (a :class:`distributed.Client`), else on the scheduler at
    ``scheduler``, else on a local cluster (processes unless ``processes=False``).
    """
    from fixplan.cluster import dask_client

    settings = settings or RobustSettings()
    settings.check()
    t0 = time.perf_counter()
    if client is not None:
        return _robust_on(client, fixture, settings, t0, progress)
    # connect first: an unreachable scheduler fails in seconds, before any planning
    with dask_client(scheduler, tasks=settings.samples, processes=processes) as c:
        return _robust_on(c, fixture, settings, t0, progress)


def _robust_on(
    client: Any, fixture: Fixture, settings: RobustSettings, t0: float, progress: Callable[[int, int], None] | None
) -> RobustResult:
    from fixplan.cluster import run_tasks

    result, start_state, steps = nominal_plan(fixture, settings)
    if result.status == "infeasible":
        return RobustResult(0, 0, [], result.status, result.reason, time.perf_counter() - t0, settings)
    seeds = list(range(settings.samples))
    outcomes = run_tasks(
        client, run_sample, seeds, fixture, start_state, steps, settings, result.policy, progress=progress
    )
    failures = [o for o in outcomes if not o["passed"]]
    return RobustResult(
        samples=len(outcomes),
        succeeded=len(outcomes) - len(failures),
        failures=failures,
        plan_status=result.status,  # as solve gives it: "planned" when it loaded in the nominal world
        plan_reason="",
        wall_time_s=time.perf_counter() - t0,
        settings=settings,
        outcomes=outcomes,
        sequence=list(result.sequence),
    )


def group_failures(failures: Sequence[dict[str, Any]]) -> list[tuple[int | None, str, list[int]]]:
    """Failures grouped by (transition, cause): ``(transition, cause, seeds)``, most frequent first."""
    groups: dict[tuple[int | None, str], list[int]] = {}
    for f in failures:
        groups.setdefault((f["transition"], f["cause"] or "other"), []).append(int(f["seed"]))
    return sorted(
        ((tr, cause, seeds) for (tr, cause), seeds in groups.items()),
        key=lambda g: (-len(g[2]), g[0] if g[0] is not None else 0, g[1]),
    )


__all__ = [
    "Perturbation",
    "RobustResult",
    "RobustSettings",
    "draw_world",
    "failure_cause",
    "group_failures",
    "nominal_plan",
    "perturbed_fixture",
    "robust",
    "run_sample",
    "verify_sample",
    "wilson_interval",
]
