"""The command line's names for the library's settings and arguments: one table.

The library names what is wrong by the setting or argument a caller of the API sets
(``RobustSettings.mu_spread``, ``solve.order``); a command's user sets it with a flag. When the
CLI prints an error it puts the flag in place of the name (:func:`with_flags`), so the library
knows nothing of flags and the user reads the option they typed.
"""

from __future__ import annotations

from typing import Any

FLAGS: dict[str, str] = {
    "RobustSettings.samples": "--samples",
    "RobustSettings.seed": "--seed",
    "RobustSettings.mu_spread": "--mu-spread",
    "RobustSettings.pose_sigma_m": "--pose-sigma (translation)",
    "RobustSettings.pose_sigma_deg": "--pose-sigma (rotation)",
    "RobustSettings.locator_sigma_m": "--locator-sigma",
    "RobustSettings.force_noise": "--force-noise",
    "RobustSettings.latency_s [ms]": "--latency-ms",
    "search_wrench.motion": "--motion",
    "search_wrench.min_margin_N": "--min-margin",
    "classify.at": "--at",
    "solve.order": "--order",
    "solve.run_verification=False": "--no-verify",
    "analyse_clamping.order": "--order",
    "analyse_clamping.preload_N": "--preload",
    "fixture_files.directory": "--batch",
    "check_address.address": "--scheduler",
    "check_output.force": "--force",
    "generate.rotate_world": "--rotate-world",
    "figure_path.report": "--report",
    # the haptic commands (fixplan haptic, device-sim, verify)
    "DeviceSim.noise": "--noise",
    "DeviceSim.delay_ms": "--delay-ms",
    "DeviceSim.duration_s": "--duration",
    "DeviceSim.peer_timeout_s": "--peer-timeout",
    "DeviceSim.port": "--port",
    "parse_until.text": "--until",
    "check_host.token": "--token",
    "run_session.port": "--port",
    "run_session.device": "--device",
    "run_device_sim.push": "--push",
    "run_device_sim.wait_s": "--wait",
    "run_verify.fixture_path": "--fixture FILE",
    "TokenGate.host": "--host",
    "TokenGate.port": "--port",
    "HapticSession.clock": "--clock",
    "HapticSession.clamp": "--clamp",
    "HapticApp.port": "--port",
}
_LONGEST_FIRST = sorted(FLAGS, key=len, reverse=True)


def with_flags(message: str) -> str:
    """``message`` with every setting or argument name of :data:`FLAGS` replaced by its flag."""
    for name in _LONGEST_FIRST:
        if name in message:
            message = message.replace(name, FLAGS[name])
    return message


def with_flags_in(data: Any) -> Any:
    """A JSON document (what a command prints or writes) with :func:`with_flags` applied to every string value in it.

    A result's reasons name settings and arguments too (``solve.run_verification=False``,
    ``solve.order``, ``search_wrench.min_margin_N``): the command shows its flags there as well.
    """
    if isinstance(data, str):
        return with_flags(data)
    if isinstance(data, list | tuple):
        return [with_flags_in(x) for x in data]
    if isinstance(data, dict):
        return {k: with_flags_in(v) for k, v in data.items()}
    return data
