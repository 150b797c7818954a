"""What ``fixplan haptic``, ``fixplan device-sim`` and ``fixplan verify`` do (``fixplan.cli.haptic`` registers them)."""

from __future__ import annotations

import json
import math
import secrets
import sys
from pathlib import Path
from typing import Any

import numpy as np

from fixplan.errors import InputError
from fixplan.files import document_stream


def _echo(text: str) -> None:
    sys.stderr.write(text + "\n")
    sys.stderr.flush()


def parse_until(text: str | None) -> tuple[bool, float | None]:
    """``goal`` → (True, None); ``SECONDS`` → (False, seconds); None → run until stopped."""
    if text is None:
        return False, None
    t = text.strip().lower()
    if t == "goal":
        return True, None
    try:
        s = float(t)
    except ValueError:
        raise InputError(f"parse_until.text expects 'goal' or a number of seconds, got {text!r}") from None
    if not (math.isfinite(s) and 0 < s <= 86400):
        raise InputError(f"parse_until.text SECONDS must be within (0, 86400], got {text!r}")
    return False, s


def check_host(host: str, token: str | None) -> str | None:
    """The token a non-loopback bind needs (generated when not given); None on 127.0.0.1."""
    if host in ("127.0.0.1", "localhost", "::1"):
        return token
    if token is None:
        token = secrets.token_urlsafe(16)
        _echo(f"fixplan haptic: --host {host} without --token: generated token {token}")
    elif len(token) < 8 or not token.isprintable() or any(c in token for c in " ;=&?#/"):
        raise InputError("check_host.token must be at least 8 printable characters without spaces or ; = & ? # /")
    return token


def run_haptic(
    file: Path | None,
    *,
    device: str,
    port: int,
    record: Path | None,
    force: bool,
    no_browser: bool,
    host: str,
    token: str | None,
    until: str | None,
    json_out: bool,
    clock: str = "wall",
    clamp: bool = False,
) -> int:
    """Run a session; 0 when the goal was reached (and with ``clamp`` the clamping stage held), 1 otherwise."""
    from fixplan.files import check_distinct, check_output
    from fixplan.fixture import default_fixture_path, load
    from fixplan.interactive.handles import GizmoHandle, Handle, SpaceMouseHandle, UdpHandle, parse_device

    kind, udp_port = parse_device(device)
    until_goal, seconds = parse_until(until)
    if not (0 <= port <= 65535):
        raise InputError(f"run_session.port must be 0..65535, got {port}")
    token = check_host(host, token)
    fixture = load(file if file is not None else default_fixture_path())  # pins and bores too
    if record is not None:
        check_distinct([("FILE", file), ("--record", record)])
        check_output(record, force, option="--record")
    from fixplan.haptics.coordinates import coordinates_from_pose
    from fixplan.interactive.session import HapticSession

    x0 = coordinates_from_pose(fixture.start, fixture.start.R_world_body)
    handle: Handle
    if kind == "udp":
        if udp_port is None:  # parse_device gives udp a port
            raise InputError("run_session.device udp needs a port (udp:PORT)")
        # the bridge listens where the web app does; off 127.0.0.1 a device's HELLO must carry the token
        handle = UdpHandle("127.0.0.1" if host == "localhost" else host, udp_port, fixture.ndof, token=token)
    elif kind == "spacemouse":
        handle = SpaceMouseHandle(x0)
    else:
        handle = GizmoHandle(x0, period_s=fixture.simulation.timestep_s)
    try:
        session = HapticSession(fixture, handle, until_goal=until_goal, duration_s=seconds, clock=clock, clamp=clamp)
    except Exception:
        handle.close()
        raise
    from fixplan.interactive.app import HapticApp

    app = HapticApp(session, host=host, port=port, token=token)
    _ctrl_c_ends_the_session()
    try:
        url = app.start()
        where = f"udp:{handle.port}" if isinstance(handle, UdpHandle) else kind
        _echo(f"fixplan haptic: {url} ({fixture.name}, device {where}; Ctrl-C ends the session)")
        _echo(f"fixplan haptic: {session.cap_note}")
        if not no_browser:
            import webbrowser

            webbrowser.open(url)
        session.start()
        try:
            while not session.wait(0.1):
                pass
        except KeyboardInterrupt:
            _echo("fixplan haptic: interrupted: ending the session")
        session.stop()
        result = session.result()
    finally:
        app.stop()
        handle.close()
    payload: dict[str, Any] = {
        "status": result.status,
        "reason": result.reason,
        "duration_s": result.duration_s,
        "sequence": [list(s) for _, s in result.states],
        "loop": {**result.stats.to_json(), "scheduling": session.scheduling, **session.guidance_rates()},
        "coupling_cap": {"force_N": session.F_max, "torque_Nm": session.T_max, "note": session.cap_note},
        "bridge": result.bridge,
    }
    if result.clamping is not None:
        payload["clamping"] = result.clamping
    if record is not None:
        from fixplan.files import write_text
        from fixplan.interactive.record import plan_json

        write_text(record, json.dumps(plan_json(result, fixture), allow_nan=False) + "\n")
        payload["record"] = str(record)
    if json_out:
        document_stream().write(json.dumps(payload, indent=2, allow_nan=False) + "\n")
    else:
        s = result.stats
        _echo(f"status: {result.status} — {result.reason}")
        _echo(
            f"loop: {s.ticks} ticks, tick mean {_us(s.tick_mean_us)} µs, p99 {_us(s.tick_p99_us)} µs, "
            f"{s.deadline_misses} deadline misses ({session.scheduling}); guidance "
            f"{session.guidance_rates()['guidance_hz']:.0f} Hz, verdict {session.guidance_rates()['verdict_hz']:.0f} Hz"
            + (
                f"; bridge: {result.bridge['accepted']} poses, {result.bridge['malformed']} malformed, "
                f"{result.bridge['out_of_order']} out of order"
                if result.bridge
                else ""
            )
        )
        if result.clamping is not None:
            _echo(clamping_line(result.clamping))
        if record is not None:
            _echo(f"wrote {record}")
    held = result.clamping is None or bool(result.clamping.get("passed"))
    return 0 if result.reached and held else 1


def clamping_line(c: dict[str, Any]) -> str:
    """The clamping stage of a session in one line."""
    order = ", then ".join(f"{k} {c['forces_N'][k]:.3g} N" for k in c["order"])
    if not c.get("played"):
        return f"clamping: {order}: {c.get('reason', 'not played')}"
    verdict = "held" if c["passed"] else f"FAILED ({c['reason']})"
    least = c.get("min_locator_force_N")
    return (
        f"clamping: {order}, the hand let go, {len(c['loads']) - 1} load(s): {verdict}; the part moved at most "
        f"{c['max_displacement_m']:.2g} m, the least locator force {least if least is None else f'{least:.3g}'} N "
        f"({c['weakest_locator']})"
    )


def run_device_sim(
    *,
    host: str,
    port: int,
    noise: float,
    delay_ms: float,
    duration: float | None,
    push: str | None,
    seed: int,
    json_out: bool,
    lockstep: bool = False,
    wait_s: float = 60.0,
    token: str | None = None,
    peer_timeout_s: float | None = None,
) -> int:
    """The simulated device; 0 when fixplan reported the goal."""
    from fixplan.interactive.device_sim import DeviceSim

    w = None
    if push is not None:
        try:
            w = np.array([float(x) for x in push.split(",")], dtype=float)
        except ValueError:
            raise InputError(f"run_device_sim.push must be comma-separated numbers, got {push!r}") from None
        if not np.all(np.isfinite(w)) or w.shape[0] not in (3, 6):
            raise InputError(f"run_device_sim.push expects 3 (2D) or 6 (3D) finite numbers, got {push!r}")
    if not (math.isfinite(wait_s) and 0 < wait_s <= 3600):
        raise InputError(f"run_device_sim.wait_s must be within (0, 3600] s, got {wait_s}")
    sim = DeviceSim(host, port, noise=noise, delay_ms=delay_ms, duration_s=duration, push=w, seed=seed,
                    lockstep=lockstep, connect_timeout_s=wait_s, token=token,
                    **({} if peer_timeout_s is None else {"peer_timeout_s": peer_timeout_s}))  # fmt: skip
    try:
        cfg = sim.connect()
        if w is not None and w.shape[0] != int(cfg["ndof"]):
            raise InputError(f"run_device_sim.push has {w.shape[0]} numbers, the scene has {cfg['ndof']} coordinates")
        if not json_out:
            _echo(f"device-sim: connected to {host}:{port} ({cfg['ndof']} coordinates, {1 / cfg['period_s']:.0f} Hz)")
        res = sim.run()
    finally:
        sim.close()
    if res.peer_gone_s is not None:  # one line, on stderr also with --json
        _echo(f"device-sim: fixplan stopped answering ({res.peer_gone_s:.1f} s without an answer): ending")
    if json_out:
        document_stream().write(json.dumps(res.to_json(), indent=2) + "\n")
    else:
        _echo(
            f"device-sim: {res.sent} poses sent, {res.received} answers, round trip mean {res.rtt_mean_ms:.3f} ms, "
            f"p99 {res.rtt_p99_ms:.3f} ms; {'goal reached' if res.goal else 'goal not reached'}"
        )
    return 0 if res.goal else 1


def run_verify(plan: Path, fixture_path: Path | None, json_out: bool) -> int:
    """Re-run a plan file in the haptic loop; 0 when it passes."""
    from fixplan.files import read_plan_json
    from fixplan.fixture import fixture_of_plan, load
    from fixplan.interactive.record import verify_plan_file

    data = read_plan_json(plan, expected="a plan JSON ('fixplan solve --out' or 'fixplan haptic --record')")  # ≤ 1 MiB
    if not isinstance(data, dict):
        raise InputError(f"{plan}: not a fixplan plan (expected a JSON object)")
    path, note = fixture_of_plan(data, plan, fixture_path)  # the fixture the plan names (path, hash)
    fixture = load(path)
    try:
        v = verify_plan_file(fixture, data, source=str(plan))
    except InputError as exc:
        if "another fixture" not in str(exc) or fixture_path is not None:
            raise
        raise InputError(f"{exc} (pass the plan's fixture with run_verify.fixture_path)") from None
    if note:  # after the plan was read: bad input stays one line
        _echo(f"fixplan: {note}")
    if json_out:
        out = v.to_json()
        out.pop("trace", None)
        document_stream().write(json.dumps(out, indent=2, allow_nan=False, default=float) + "\n")
    else:
        kind = "recorded pushes" if data.get("source") == "haptic session" else "plan"
        seq = " → ".join("{" + ", ".join(s) + "}" for s in v.observed_sequence) or "(none)"
        print(
            f"{plan}: {'passed' if v.passed else 'FAILED'} ({kind} re-run in the loop, {v.duration_s:.2f} s) — {v.reason}"
        )
        pen = "n/a (not run)" if v.max_penetration_m is None else f"{v.max_penetration_m:.2e} m"
        print(f"observed states: {seq}; max penetration {pen}")
    return 0 if v.passed else 1


def _us(value: float | None) -> str:
    """A tick time [µs] in words: ``n/a`` when unknown (no tick ran)."""
    return "n/a" if value is None else f"{value:.0f}"


def _ctrl_c_ends_the_session() -> None:
    """Make Ctrl-C (SIGINT) end the session, as the command promises, even where it was ignored.

    A command started in the background of a non-interactive shell (``cmd &`` in a script, or under
    a supervisor) inherits SIGINT ignored, and Python then installs no handler: the session said
    "Ctrl-C ends the session" and then could not be ended by it (found when the test suite itself
    ran in the background). The default handler raises KeyboardInterrupt in the main thread.
    """
    import signal
    import threading

    if threading.current_thread() is threading.main_thread() and signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
