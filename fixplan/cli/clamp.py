"""``fixplan clamp``: the least clamp forces, the clamping order, and the engine's check."""

from __future__ import annotations

import math
from typing import Annotated

import typer

from fixplan.cli._app import FileArg, JsonOpt, _console, _emit_json, _load, _names, app
from fixplan.errors import InputError, one_line, quote_number


@app.command()
def clamp(
    file: FileArg = None,
    order: Annotated[
        str | None,
        typer.Option(
            "--order", help="Check this clamping order (K1,K2,...: every clamp once) instead of searching one."
        ),
    ] = None,
    preload: Annotated[
        float | None,
        typer.Option(
            "--preload", help="Least normal force every locator keeps once clamped, under every load [N]; default 1."
        ),
    ] = None,
    verify: Annotated[
        bool, typer.Option("--verify/--no-verify", help="Run the clamping stage in the engine (default: on).")
    ] = True,
    json_out: JsonOpt = False,
) -> None:
    """Clamp the located part: the least forces within max_force, an order, and the check in the engine (exit 1 when nothing holds)."""
    from fixplan.clamping import analyse_clamping
    from fixplan.limits import FORCE_MAX_N

    fixture = _load(file)
    if preload is not None and not (math.isfinite(preload) and 0.0 <= preload <= FORCE_MAX_N):
        raise InputError(f"--preload is {quote_number(preload)} (expected a force [N] in [0, {FORCE_MAX_N:g}])")
    result = analyse_clamping(fixture, _names(order, "--order"), preload, verify=verify)
    if json_out:
        _emit_json(result.to_json())
    else:
        _table(fixture, result)
        typer.echo(one_line(result.reason))
    if not result.holds:
        raise typer.Exit(1)


def _table(fixture, result) -> None:  # type: ignore[no-untyped-def]
    from rich.table import Table

    clamps = Table(
        title=f"{fixture.name}: clamps" + (f" in the order {', '.join(result.order)}" if result.order else "")
    )
    clamps.add_column("#", justify="right")
    clamps.add_column("clamp")
    clamps.add_column("force [N]", justify="right")
    clamps.add_column("max_force [N]", justify="right")
    clamps.add_column("kind")
    position = {name: i for i, name in enumerate(result.order, 1)}
    for k in fixture.clamps:
        force = result.forces_N.get(k.name)
        clamps.add_row(
            str(position.get(k.name, "-")),
            k.name,
            "-" if force is None else f"{force:.4g}",
            f"{k.max_force_N:g}",
            "fixed" if k.force_N is not None else "computed",
        )
    _console().print(clamps)
    cases = [c for c in (result.clamped, *result.loads) if c is not None]
    if cases:
        loads = Table(title=f"loads (every locator ≥ {result.preload_N:g} N)")
        loads.add_column("case")
        loads.add_column("holds")
        loads.add_column("least locator force [N]", justify="right")
        loads.add_column("at")
        for c in cases:
            least = "-" if c.min_locator_force_N is None else f"{c.min_locator_force_N:.4g}"
            loads.add_row(c.name, "yes" if c.holds else "no", least, c.weakest_locator or "-")
        _console().print(loads)
    v = result.verification
    if v is not None and v.locator_forces_N:
        both = Table(title="locator forces at the end of the engine's run (clamps on, no load)")
        both.add_column("locator")
        both.add_column("engine [N]", justify="right")
        both.add_column("program [N]", justify="right")
        for name, f in v.locator_forces_N.items():
            engine, program = f.get("engine_N"), f.get("program_N")
            both.add_row(name, "-" if engine is None else f"{engine:.4g}", "-" if program is None else f"{program:.4g}")
        _console().print(both)
    if v is not None:
        typer.echo(
            f"engine: {'passed' if v.passed else 'FAILED'}; largest displacement {v.max_displacement_m:.3g} m, "
            f"widest locator gap {v.max_gap_m:.3g} m, least locator force {v.min_locator_force_N:.4g} N "
            f"({v.weakest_locator}), {v.steps} steps"
        )
