"""Commands of the haptic loop: haptic (drive the part live), device-sim, verify (re-run a plan file)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from fixplan.cli._app import (
    FileArg,
    JsonOpt,
    app,
)


@app.command()
def haptic(
    file: FileArg = None,
    device: Annotated[
        str,
        typer.Option(
            "--device", help="mouse (the viser gizmo), spacemouse, or udp[:PORT] (the bridge, docs/haptic.md)."
        ),
    ] = "mouse",
    port: Annotated[int, typer.Option("--port", help="Web app port (0: any free port).")] = 8080,
    record: Annotated[Path | None, typer.Option("--record", help="Write the session as a plan file.")] = None,
    force: Annotated[bool, typer.Option("--force", help="Overwrite --record if it exists.")] = False,
    no_browser: Annotated[bool, typer.Option("--no-browser", help="Do not open a browser.")] = False,
    host: Annotated[
        str, typer.Option("--host", help="Interface to serve on (not 127.0.0.1: needs --token).")
    ] = "127.0.0.1",
    token: Annotated[str | None, typer.Option("--token", help="Token a browser must present (--host).")] = None,
    until: Annotated[
        str | None, typer.Option("--until", help="End at the 'goal' or after SECONDS (default: at Ctrl-C).")
    ] = None,
    clock: Annotated[
        str, typer.Option("--clock", help="wall: 1 kHz real time; device: one tick per UDP pose (reproducible).")
    ] = "wall",
    clamp: Annotated[
        bool,
        typer.Option(
            "--clamp",
            help="Once the part is located, play the clamping stage: each clamp ramped in the order "
            "'fixplan clamp' finds, the hand let go, each [[load]] applied (docs/haptic.md).",
        ),
    ] = False,
    json_out: JsonOpt = False,
) -> None:
    """Drive the part yourself: a live web app (viser) around the 1 kHz haptic loop, with the planner's guidance.

    Exit 0 when the session reached the goal (every locator pressed, at rest; a shaft in a bore: seated
    on its bottom, its axis within the play; with --clamp, and the clamped part stayed put), 1
    otherwise, 2 on bad input.
    """
    from fixplan.interactive.commands import run_haptic

    code = run_haptic(file, device=device, port=port, record=record, force=force, no_browser=no_browser,
                      host=host, token=token, until=until, json_out=json_out, clock=clock, clamp=clamp)  # fmt: skip
    if code:
        raise typer.Exit(code)


@app.command("device-sim")
def device_sim(
    host: Annotated[str, typer.Option("--host", help="Where 'fixplan haptic --device udp:PORT' runs.")] = "127.0.0.1",
    port: Annotated[int, typer.Option("--port", help="Its UDP port.")] = 7777,
    noise: Annotated[float, typer.Option("--noise", help="Relative force noise of the operator (every 10 ms).")] = 0.05,
    delay_ms: Annotated[float, typer.Option("--delay-ms", help="The operator's reaction delay [ms].")] = 50.0,
    duration: Annotated[float | None, typer.Option("--duration", help="Stop after S seconds.")] = None,
    push: Annotated[
        str | None, typer.Option("--push", help="Push this constant wrench instead of following the guidance.")
    ] = None,
    seed: Annotated[int, typer.Option("--seed", help="Noise seed.", min=0)] = 0,
    lockstep: Annotated[
        bool, typer.Option("--lockstep", help="One period per answer, no wall clock (with 'haptic --clock device').")
    ] = False,
    wait: Annotated[float, typer.Option("--wait", help="Seconds to wait for 'fixplan haptic' to answer.")] = 60.0,
    token: Annotated[
        str | None, typer.Option("--token", help="The token of 'fixplan haptic --host H --token T'.")
    ] = None,
    peer_timeout: Annotated[
        float | None,
        typer.Option("--peer-timeout", help="End (exit 1) when fixplan has not answered for S seconds (default 2)."),
    ] = None,
    json_out: JsonOpt = False,
) -> None:
    """A simulated haptic device with a human-like operator, over the UDP bridge (exit 0 when fixplan reports the goal)."""
    from fixplan.interactive.commands import run_device_sim

    code = run_device_sim(host=host, port=port, noise=noise, delay_ms=delay_ms, duration=duration, push=push,
                          seed=seed, json_out=json_out, lockstep=lockstep, wait_s=wait, token=token,
                          peer_timeout_s=peer_timeout)  # fmt: skip
    if code:
        raise typer.Exit(code)


@app.command("verify")
def verify_plan(
    plan: Annotated[Path, typer.Argument(help="A plan file ('fixplan solve --out' or 'fixplan haptic --record').")],
    fixture: Annotated[
        Path | None,
        typer.Option("--fixture", help="The fixture (default: the one the plan names, else the bundled box)."),
    ] = None,
    json_out: JsonOpt = False,
) -> None:
    """Re-run a plan in the simulated haptic loop: a recorded session's pushes, or a solved plan's executor.

    Exit 0 when the part reaches the goal without jamming, 1 when not, 2 on bad input.
    """
    from fixplan.interactive.commands import run_verify

    code = run_verify(plan, fixture, json_out)
    if code:
        raise typer.Exit(code)
