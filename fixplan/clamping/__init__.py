"""Clamping after loading: how hard to clamp, in which order, checked in the engine (``fixplan clamp``).

- :mod:`.forces` — the least clamp forces that hold every ``[[load]]``: one second-order cone
  program over the locators' exact friction cones (the jamming programs' cones);
- :mod:`.order` — an order in which every prefix of clamps holds under gravity without the
  hand (the jamming classifier as the test, subsets searched once each), and why one fails;
- :mod:`.verify` — the clamps ramped in the engine, the hand let go, each load applied.

:func:`analyse_clamping` runs the three and returns a :class:`ClampResult`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from fixplan.clamping.forces import (
    Case,
    ClampScene,
    build_force_program,
    cases_of,
    clamp_scene,
    refused_direction,
    solve_force_program,
)
from fixplan.clamping.order import OrderSearch
from fixplan.clamping.verify import Verification, verify_clamping
from fixplan.errors import InputError
from fixplan.model import Fixture, require_full
from fixplan.settings import DEFAULT, Settings

__all__ = ["ClampResult", "LoadResult", "Verification", "analyse_clamping"]


@dataclass(frozen=True)
class LoadResult:
    """One case the clamped part must hold: ``clamped`` (gravity alone) or a ``[[load]]``."""

    name: str
    holds: bool
    min_locator_force_N: float | None  # the best least locator force at the clamp forces (None: no balance)
    weakest_locator: str | None = None

    def to_json(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "holds": self.holds,
            "min_locator_force_N": self.min_locator_force_N,
            "weakest_locator": self.weakest_locator,
        }


@dataclass(frozen=True)
class ClampResult:
    """The answer of ``fixplan clamp``, with its residuals (the JSON keys of docs/fixture-format.md and a few more)."""

    holds: bool
    order: tuple[str, ...]
    forces_N: dict[str, float]
    loads: tuple[LoadResult, ...]  # the file's loads (the ``clamped`` case is :attr:`clamped`)
    verification: Verification | None
    reason: str
    preload_N: float
    clamped: LoadResult | None = None
    balance_residual_N: float | None = None  # largest equilibrium residual of the force program's answer
    cone_violation_N: float | None = None
    order_programs: int = 0  # prefixes classified by the order search
    extras: dict[str, Any] = field(default_factory=dict)
    # each counted contact's normal force in the program's answer for the ``clamped`` case [N]
    clamped_forces_N: dict[str, float] | None = None

    def to_json(self) -> dict[str, Any]:
        return {
            "holds": self.holds,
            "order": list(self.order),
            "forces_N": dict(self.forces_N),
            "loads": [x.to_json() for x in self.loads],
            "verification": None if self.verification is None else self.verification.to_json(),
            "reason": self.reason,
            "preload_N": self.preload_N,
            "clamped": None if self.clamped is None else self.clamped.to_json(),
            "residuals": {"balance_N": self.balance_residual_N, "cone_violation_N": self.cone_violation_N},
            "order_programs": self.order_programs,
        }


def analyse_clamping(
    fixture: Fixture,
    order: Sequence[str] | None = None,
    preload_N: float | None = None,
    *,
    verify: bool = True,
    settings: Settings = DEFAULT,
) -> ClampResult:
    """The least clamp forces, a clamping order (or the given one checked) and the engine's verdict.

    Raises
    ------
    InputError
        No clamps; ``order`` not naming every clamp once; a preload that is not a finite force ≥ 0.
    """
    st = settings.clamp
    preload = st.preload_N if preload_N is None else float(preload_N)
    if not (np.isfinite(preload) and preload >= 0.0):
        raise InputError(f"analyse_clamping.preload_N is {preload!r} (expected a force [N] ≥ 0)")
    if not fixture.clamps:
        raise InputError(f"{fixture.source}: no [[clamp]] entries (expected at least one clamp to analyse)")
    require_full(fixture, "clamping")
    names = [k.name for k in fixture.clamps]
    if order is not None:
        order = list(order)
        unknown = [k for k in order if k not in names]
        if unknown:
            raise InputError(
                f"analyse_clamping.order: unknown clamp {unknown[0]!r} (expected the clamps {', '.join(names)})"
            )
        twice = [k for i, k in enumerate(order) if k in order[:i]]
        missing = [k for k in names if k not in order]
        if twice or missing:
            what = f"names a clamp twice ({twice[0]})" if twice else f"misses {', '.join(missing)}"
            raise InputError(f"analyse_clamping.order {what} (expected every clamp once: {', '.join(names)})")
    if len(names) > st.max_order_clamps and order is None:
        raise InputError(
            f"{len(names)} clamps (the order search takes at most {st.max_order_clamps}; give analyse_clamping.order to check one)"
        )
    scene = clamp_scene(fixture)
    cases = cases_of(scene)

    def refused(reason: str, forces: dict[str, float] | None = None, **kw: Any) -> ClampResult:
        return ClampResult(False, (), forces or {}, kw.pop("loads", ()), None, reason, preload, **kw)

    why = refused_direction(scene, settings)
    if why is not None:
        return refused(why)
    answer = solve_force_program(scene, build_force_program(scene, cases, preload), settings)
    if not answer.found:
        per_case = [_case_alone(scene, case, preload, settings) for case in cases]
        failing = [r for r in per_case if not r[0].holds]
        if failing:
            reason = failing[0][1]
        else:
            reason = (
                "each load is held on its own, but no one set of clamp forces within max_force holds them all "
                f"with every locator at ≥ {preload:g} N"
            )
        return refused(reason, loads=tuple(r[0] for r in per_case[1:]), clamped=per_case[0][0])
    forces = answer.forces_N
    held = [_least_force(scene, case, forces, settings) for case in cases]
    search = OrderSearch(scene, forces, settings)
    if order is not None:
        failed = search.check_order(order)
        found: tuple[str, ...] | None = tuple(order) if failed is None else None
        head = f"the order {', '.join(order)} fails: "
    else:
        found, failed = search.search()
        head = "no clamping order holds: "
    base = ClampResult(
        False,
        (),
        forces,
        tuple(held[1:]),
        None,
        "",
        preload,
        clamped=held[0],
        balance_residual_N=answer.balance_residual,
        cone_violation_N=answer.cone_violation,
        order_programs=search.programs,
        clamped_forces_N=answer.locator_forces_N.get("clamped"),
    )
    if found is None:
        return replace(base, reason=head + (failed.reason if failed is not None else "no clamp can come first"))
    total = sum(forces.values())
    if not verify:
        return replace(base, holds=True, order=found, reason=_held(found, total, preload, len(held) - 1, None))
    points = {c.name: c.point_world for c in scene.clamps}
    verification = verify_clamping(
        fixture,
        found,
        forces,
        points,
        settings,
        watched=scene.owners,
        program_forces_N=base.clamped_forces_N,
    )
    if not verification.passed:
        return replace(
            base, order=found, verification=verification, reason=f"the engine refutes it: {verification.reason}"
        )
    reason = _held(found, total, preload, len(held) - 1, verification)
    return replace(base, holds=True, order=found, verification=verification, reason=reason)


def _held(order: tuple[str, ...], total: float, preload: float, loads: int, v: Verification | None) -> str:
    """The one line of a clamping that holds."""
    checked = (
        f"; in the engine the part moved at most {v.max_displacement_m:.2g} m and the least locator force was "
        f"{v.min_locator_force_N:.3g} N ({v.weakest_locator})"
        if v is not None
        else "; not run in the engine"
    )
    reason = (
        f"holds: clamp {', then '.join(order)} ({total:.4g} N in all), every locator ≥ {preload:g} N under gravity "
        f"and each of {loads} load(s){checked}"
    )
    return reason + (f"; {v.reason}" if v is not None and v.reason else "")


def _least_force(scene: ClampScene, case: Case, forces_N: dict[str, float], settings: Settings) -> LoadResult:
    """The best least locator force of ``case`` at these clamp forces (``max t: every locator ≥ t``)."""
    fp = build_force_program(scene, (case,), 0.0, given=forces_N, maxmin=True)
    a = solve_force_program(scene, fp, settings)
    if not a.found:
        return LoadResult(case.name, False, None, None)
    return LoadResult(case.name, True, a.min_locator_force_N[case.name], a.weakest_locator[case.name])


def _case_alone(scene: ClampScene, case: Case, preload: float, settings: Settings) -> tuple[LoadResult, str]:
    """Whether ``case`` alone is held with the clamps free within max_force, and why not."""
    seat = case.seated
    a = solve_force_program(scene, build_force_program(scene, (case,), preload), settings)
    fp = build_force_program(scene, (case,), 0.0, maxmin=True)
    best = solve_force_program(scene, fp, settings)
    least = best.min_locator_force_N[case.name] if best.found else None
    weakest = best.weakest_locator[case.name] if best.found else None
    what = "the clamped part (gravity alone, seated by normal forces)" if seat else f"load {case.name}"
    if a.found:
        return LoadResult(case.name, True, least, weakest), ""
    if least is None:
        return LoadResult(case.name, False, None, None), (
            f"{what} is not balanced by the locators with any clamp forces up to max_force"
        )
    return LoadResult(case.name, False, least, weakest), (
        f"{what} cannot keep every locator at ≥ {preload:g} N with any clamp forces up to max_force: at best "
        f"{weakest} keeps {max(least, 0.0):.3g} N"
    )
