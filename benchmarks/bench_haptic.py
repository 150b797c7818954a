"""The interactive haptic loop's timing: fixplan haptic + device-sim over UDP on loopback, with and without a browser.

Each run is ``fixplan haptic --device udp:P --until goal --record R --json`` (wall clock: one tick
per millisecond) driven by ``fixplan device-sim --json`` at 1 kHz (5 % force noise, 50 ms reaction
delay), optionally with the web page open in headless Chromium (Playwright, software WebGL: the
browser's rendering runs on the same two cores). Measured: the loop's tick compute time (mean,
p99, max), deadline misses (ticks that ended after their 1 ms deadline), how late ticks started
(p99), the bridge's round trip seen by the device (pose sent → its answer received, mean and
p99), whether the session reached the goal, and whether ``fixplan verify`` passes its recording.
A session that has not reached the goal after 60 s is ended with Ctrl-C (status ``short``).
"""

from __future__ import annotations

import json
import math
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from run import Section

ROOT = Path(__file__).resolve().parents[1]
CLI = [sys.executable, "-c", "import sys; from fixplan.cli import main; sys.exit(main())"]
LIMIT_S = 60.0


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _watch_page(url: str, proc: subprocess.Popen, deadline: float) -> dict:
    """Keep the page open in headless Chromium until the session ends; what the page did."""
    from fixplan.present.browser import headless_page

    info = {"console_errors": 0, "opened": False}
    with headless_page(url, width=1100, height=700) as page:
        page.on("console", lambda m: info.__setitem__("console_errors", info["console_errors"] + (m.type == "error")))
        page.goto(url, wait_until="load", timeout=60_000)
        page.wait_for_selector("canvas", timeout=60_000)
        info["opened"] = True
        while proc.poll() is None and time.perf_counter() < deadline:
            page.wait_for_timeout(200)
    return info


def one_run(with_browser: bool, seed: int) -> dict:
    port = _free_udp_port()
    with tempfile.TemporaryDirectory() as tmp:
        record = Path(tmp) / "session.json"
        haptic = subprocess.Popen(
            [*CLI, "haptic", "--device", f"udp:{port}", "--port", "0", "--no-browser", "--until", "goal",
             "--record", str(record), "--json"],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        url = ""
        assert haptic.stderr is not None
        t_start = time.perf_counter()
        while time.perf_counter() - t_start < 60 and not url:
            line = haptic.stderr.readline()
            if line.startswith("fixplan haptic: http://"):
                url = line.split()[2]
        device = subprocess.Popen(
            [*CLI, "device-sim", "--port", str(port), "--seed", str(seed), "--json"],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        deadline = time.perf_counter() + LIMIT_S + 30
        page = {"opened": False, "console_errors": 0}
        if with_browser and url:
            page = _watch_page(url, haptic, deadline)
        try:
            haptic.wait(timeout=max(deadline - time.perf_counter(), 1))
        except subprocess.TimeoutExpired:
            haptic.send_signal(signal.SIGINT)
        out, _ = haptic.communicate(timeout=60)
        try:
            dev_out, dev_err = device.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            device.kill()
            dev_out, dev_err = device.communicate()
        summary = json.loads(out) if out.strip() else {}
        dev = json.loads(dev_out) if dev_out.strip() else {}
        verified = None
        if record.is_file():
            v = subprocess.run([*CLI, "verify", str(record), "--json"], capture_output=True, text=True, timeout=300)
            verified = v.returncode == 0
    loop = summary.get("loop") or {}
    return {
        "case": "UDP device-sim + Chromium page" if with_browser else "UDP device-sim, no browser",
        "seed": seed,
        "status": summary.get("status", "?"),
        "reason": summary.get("reason", ""),
        "device_sim_error": "" if dev else dev_err.strip()[-300:],
        "session_s": summary.get("duration_s", math.nan),
        "ticks": loop.get("ticks", 0),
        "tick_mean_us": loop.get("tick_mean_us", math.nan),
        "tick_p99_us": loop.get("tick_p99_us", math.nan),
        "tick_max_us": loop.get("tick_max_us", math.nan),
        "deadline_misses": loop.get("deadline_misses", 0),
        "late_p99_us": loop.get("late_p99_us", math.nan),
        "rtt_mean_ms": dev.get("rtt_mean_ms") or math.nan,
        "rtt_p99_ms": dev.get("rtt_p99_ms") or math.nan,
        "poses_sent": dev.get("sent", 0),
        "answers": dev.get("received", 0),
        "malformed": (summary.get("bridge") or {}).get("malformed", 0),
        "page_opened": page["opened"],
        "console_errors": page["console_errors"],
        "verify_passed": verified,
        "scheduling": loop.get("scheduling", "?"),
        "guidance_hz": loop.get("guidance_hz", math.nan),
        "verdict_hz": loop.get("verdict_hz", math.nan),
    }


def run(quick: bool) -> Section:
    from fixplan.present.browser import browser_available

    repeats = 1 if quick else 3
    rows = []
    browser_ok = browser_available() is None
    for with_browser in (False, True):
        if with_browser and not browser_ok:
            continue
        for k in range(repeats):
            rows.append(one_run(with_browser, seed=k))
    load = os.getloadavg()[0]

    def f(x: float, fmt: str) -> str:
        return "–" if x is None or (isinstance(x, float) and math.isnan(x)) else format(x, fmt)

    lines = [
        "fixplan haptic with the UDP bridge on loopback: `fixplan device-sim` (1 kHz, 5 % force noise, 50 ms",
        "reaction delay) follows the planner's guidance on the default box until every locator is pressed, at rest.",
        "Tick: the loop's work per 1 ms period (device read, coupling, engine step, contact state, answer);",
        "a deadline miss is a tick that ended after its deadline; *late p99*: how late ticks started.",
        f"Load average when the benchmark ended: {load:.2f} on {os.cpu_count()} cores (the loop, the guidance",
        "process, device-sim and Chromium's software rendering share them).",
        "",
        "| case | run | status | session [s] | ticks | tick mean [µs] | tick p99 [µs] | tick max [µs] | deadline misses"
        " | late p99 [µs] | round trip mean [ms] | round trip p99 [ms] | guidance / verdict [Hz] | verify |",
        "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|",
    ]
    for r in rows:
        share = f"{r['deadline_misses']} ({100 * r['deadline_misses'] / max(r['ticks'], 1):.1f} %)"
        lines.append(
            f"| {r['case']} | {r['seed']} | {r['status']} | {f(r['session_s'], '.2f')} | {r['ticks']} | "
            f"{f(r['tick_mean_us'], '.0f')} | {f(r['tick_p99_us'], '.0f')} | {f(r['tick_max_us'], '.0f')} | {share} | "
            f"{f(r['late_p99_us'], '.0f')} | {f(r['rtt_mean_ms'], '.2f')} | {f(r['rtt_p99_ms'], '.2f')} | "
            f"{f(r['guidance_hz'], '.0f')} / {f(r['verdict_hz'], '.0f')} | "
            f"{'passed' if r['verify_passed'] else 'failed' if r['verify_passed'] is False else '–'} |"
        )
    for r in rows:
        if r["status"] != "reached":
            lines += ["", f"{r['case']}, run {r['seed']}: {r['status']} — {r['reason']}"]
            if r["device_sim_error"]:
                lines.append(f"(device-sim: {r['device_sim_error']})")
    lines += ["", "Loop thread scheduling: " + ", ".join(sorted({r["scheduling"] for r in rows})) + "."]
    if not browser_ok:
        lines += ["", f"The browser runs were skipped: {browser_available()}."]
    return Section("Interactive haptic loop: timing over the UDP bridge", "\n".join(lines), rows, "haptic")
