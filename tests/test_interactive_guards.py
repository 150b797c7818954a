"""The haptic session's guards: a part that leaves the fixture ends the session, the
coupling is capped without ``[manipulator]``, the guidance answers before the clock starts, and
``device-sim`` ends when fixplan stops answering.

Sessions run without a wall clock (reproducible); the one wall-clock check bounds a time to exit
with a generous timeout, it does not time speed.
"""

import json
import math
import socket
import subprocess
import threading
import time

import numpy as np
import pytest
from conftest import CLI, PROBLEMS

import fixplan
from fixplan.interactive import protocol
from fixplan.interactive.device_sim import DeviceSim, LockstepHandle
from fixplan.interactive.record import plan_json
from fixplan.interactive.session import HapticSession
from fixplan.planner.execute import DivergenceGuard, Executor
from fixplan.settings import HAPTIC, ExecutionSettings


@pytest.fixture(scope="module")
def box():
    return fixplan.load(fixplan.default_fixture_path())


@pytest.fixture(scope="module")
def tilted():
    return fixplan.load(PROBLEMS / "box-tilted-start.toml")


class FlagsHandle(LockstepHandle):
    """A lock-step device that keeps the flags of every answer it was shown."""

    def __init__(self, config, **options):
        super().__init__(config, **options)
        self.flags: list[int] = []

    def display(self, felt, answer=None):
        if answer is not None:
            self.flags.append(answer(0, 0.0).flags)
        super().display(felt, answer)


def test_a_part_pushed_off_its_locators_ends_the_session_as_diverged_and_keeps_the_recording(box):
    """A hand insisting on 30 N along +x slides the box off its base locators: it falls and flies off.

    Friction gives at most μ m g = 0.25 · 19.6 = 4.9 N, so the box leaves at ≥ (30 − 4.9) / 2 ≈ 12.5 m/s²
    and is beyond the guard's reach (3 × (farthest locator + bounding radius) ≈ 0.7 m) within
    √(2 · 0.8 / 12.5) ≈ 0.36 s (plus its fall). Without the guard it ran to the session's 5 s.
    """
    s = HapticSession(box, None, realtime=False, synchronous=True, until_goal=True, duration_s=5.0, guidance=False)
    s.handle = FlagsHandle(s.bridge_config(), push=np.array([30.0, 0, 0, 0, 0, 0]), noise=0.0, delay_s=0.0)
    s._auto = False
    res = s.run()
    assert res.status == "diverged", res.reason
    assert "divergence guard" in res.reason and "from where it started" in res.reason
    assert res.duration_s < 1.0  # bounded: ≈ 0.4 s from the closed form above
    far = np.linalg.norm(res.trace.poses[-1].p_world - box.start.p_world)
    guard = s.guard
    assert guard.far_m * 0.95 < far < guard.far_m * 1.5  # it ended as it crossed the limit, not later
    # the device was told the session ended (the last answer carries FLAG_ENDED)
    assert s.handle.flags[-1] & protocol.FLAG_ENDED
    # the recording is kept, finite, and says why
    data = json.loads(json.dumps(plan_json(res, box), allow_nan=False))
    assert data["status"] == "diverged" and "divergence guard" in data["reason"]
    assert data["verification"]["trace"]["time_s"][-1] > 0.3


def test_the_session_and_the_executor_share_one_divergence_guard(box):
    """One definition: the executor's limits are the guard's; the session's speed limit is at least as large."""
    ex = Executor(box, frozenset(), [], tick_s=1e-3)
    g = DivergenceGuard.for_fixture(box, ExecutionSettings())
    assert (ex.guard.far_m, ex.guard.v_limit_mps) == (g.far_m, g.v_limit_mps)
    np.testing.assert_array_equal(ex.guard.home_world, g.home_world)
    s = HapticSession(box, None, realtime=False, synchronous=True, guidance=False)
    assert s.guard.far_m == pytest.approx(g.far_m)
    a = s.F_max / box.workpiece.mass_kg + 9.81
    assert s.guard.v_limit_mps == pytest.approx(max(g.v_limit_mps, math.sqrt(2 * a * g.far_m)))
    assert g.check(box.start, 0.0) is None
    assert "not finite" in g.check(box.start, float("nan"))
    assert "beyond what the push can cause" in g.check(box.start, 2 * g.v_limit_mps)


def test_without_a_manipulator_the_coupling_is_capped_at_multiples_of_the_weight(tilted, box):
    """box-tilted-start has no [manipulator]: 4 m|g| = 4 · 2 · 9.81 = 78.48 N and 78.48 N × 0.115 m (its
    bounding radius, half the diagonal of 0.2 × 0.1 × 0.05 m) = 8.99 N·m; a 300 N push is held to it."""
    rig = HAPTIC.haptic
    s = HapticSession(tilted, None, realtime=False, synchronous=True, until_goal=False, duration_s=0.2, guidance=False)
    r = 0.5 * math.sqrt(0.2**2 + 0.1**2 + 0.05**2)
    assert s.F_max == pytest.approx(rig.coupling_force_weights * 2.0 * 9.81)
    assert s.T_max == pytest.approx(rig.coupling_torque_weights * 2.0 * 9.81 * r)
    assert "no [manipulator]" in s.cap_note and "78.48 N" in s.cap_note
    # the guidance plans within the same cap
    assert s.guide_fixture.manipulator.max_force_N == pytest.approx(s.F_max)
    s.handle = LockstepHandle(s.bridge_config(), push=np.array([0, 0, -300.0, 0, 0, 0]), noise=0.0, delay_s=0.0)
    s._auto = False
    res = s.run()
    forces = np.linalg.norm(np.asarray(res.trace.coupling_wrench)[:, :3], axis=1)
    assert forces.max() <= s.F_max * (1 + 1e-9)
    assert forces.max() > 0.95 * s.F_max  # the 300 N push reached the cap
    assert res.saturated_ticks > 0
    # a file with [manipulator] keeps its limits
    sb = HapticSession(box, None, realtime=False, synchronous=True, guidance=False)
    assert sb.F_max == box.manipulator.max_force_N and "[manipulator] limits" in sb.cap_note


def test_guidance_answers_before_the_clock_starts(tilted):
    """The guidance processes start and plan before the first tick: the first sample carries a push.

    Free-running (no wall clock), 50 ms of session take far less than the planner's start-up (a
    process, imports, the first plan: seconds), so before the fix no answer had arrived by the end.
    """
    s = HapticSession(tilted, None, realtime=False, synchronous=False, until_goal=False, duration_s=0.05)
    res = s.run()
    assert res.rates["guidance_start_s"] == 0.0
    assert res.trace.suggested[0] is not None and np.all(np.isfinite(res.trace.suggested[0]))
    assert np.linalg.norm(res.trace.suggested[0][:3]) > 0.0  # the plan's first push (not a zero placeholder)


def _silent_peer(config: dict, answers: int, port_box: list, stop: threading.Event) -> None:
    """A stand-in for 'fixplan haptic': CONFIG on HELLO, ``answers`` answers, then silence."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(0.05)
    port_box.append(sock.getsockname()[1])
    n = int(config["ndof"])
    sent = 0
    try:
        while not stop.is_set():
            try:
                data, addr = sock.recvfrom(4096)
            except TimeoutError:
                continue
            kind = protocol.message_type(data)
            if kind == protocol.HELLO:
                sock.sendto(protocol.encode_config(config), addr)
            elif kind == protocol.POSE and sent < answers:
                pose = protocol.decode_pose(data, n)
                z = np.zeros(n)
                pkt = protocol.ForcePacket(sent + 1, pose.seq, pose.t_device_s, 0.0, 0, z, np.asarray(config["x0"]),
                                           z, -1, 0, protocol.VERDICT_UNKNOWN, float("nan"), z, n)  # fmt: skip
                sock.sendto(protocol.encode_force(pkt), addr)
                sent += 1
    finally:
        sock.close()


@pytest.mark.parametrize("answers", [0, 50])
def test_device_sim_ends_when_fixplan_stops_answering(box, answers):
    """After CONFIG (and some answers) the peer goes silent: device-sim ends within its peer time-out."""
    config = HapticSession(box, None, realtime=False, synchronous=True, guidance=False).bridge_config()
    port_box: list = []
    stop = threading.Event()
    peer = threading.Thread(target=_silent_peer, args=(config, answers, port_box, stop), daemon=True)
    peer.start()
    while not port_box:
        time.sleep(0.01)
    try:
        sim = DeviceSim("127.0.0.1", port_box[0], peer_timeout_s=0.3, connect_timeout_s=30.0, delay_ms=0.0)
        sim.connect()
        out: list = []
        # its own thread: device-sim asks real-time priority for the thread that runs it
        runner = threading.Thread(target=lambda: out.append(sim.run()), daemon=True)
        runner.start()
        runner.join(60.0)
        sim.close()
        res = out[0]
    finally:
        stop.set()
        peer.join(5.0)
    assert res.peer_gone_s is not None and res.peer_gone_s >= 0.3
    assert res.received == answers and not res.goal
    assert res.duration_s < 30.0  # ended on its own (it has no --duration)


def test_device_sim_cli_says_fixplan_is_gone_in_one_line_and_exits_1(box):
    config = HapticSession(box, None, realtime=False, synchronous=True, guidance=False).bridge_config()
    port_box: list = []
    stop = threading.Event()
    peer = threading.Thread(target=_silent_peer, args=(config, 10, port_box, stop), daemon=True)
    peer.start()
    while not port_box:
        time.sleep(0.01)
    try:
        p = subprocess.run([*CLI, "device-sim", "--port", str(port_box[0]), "--peer-timeout", "0.5"],
                           capture_output=True, text=True, timeout=120)  # fmt: skip
    finally:
        stop.set()
        peer.join(5.0)
    assert p.returncode == 1, p.stderr
    gone = [line for line in p.stderr.splitlines() if "stopped answering" in line]
    assert len(gone) == 1 and "Traceback" not in p.stderr
    bad = subprocess.run([*CLI, "device-sim", "--peer-timeout", "-1"], capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1 and "--peer-timeout" in bad.stderr


def test_a_wall_clock_udp_session_starts_its_clock_with_the_devices_first_pose(box):
    """No tick (no session time) before a device has said HELLO and sent a pose; then the session runs.

    Before, the clock ran from start(): the part sat under a limp coupling and the device joined a
    session already seconds old, its handle where the part had started (a jerk on the part).
    """
    from fixplan.interactive.handles import UdpHandle

    handle = UdpHandle("127.0.0.1", 0, box.ndof)
    s = HapticSession(box, handle, realtime=False, synchronous=True, guidance=False, until_goal=False,
                      duration_s=0.05)  # fmt: skip
    s.start()
    try:
        assert not s.wait(1.0)  # a second of wall time: nothing happened
        assert s.sim.time_s == 0.0 and s.stats().ticks == 0
        dev = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        dev.settimeout(10.0)
        dev.connect(("127.0.0.1", handle.port))
        dev.send(protocol.encode_hello(None))
        config = protocol.decode_config(dev.recv(65536))
        x0 = np.asarray(config["x0"], dtype=float)
        dev.send(protocol.encode_pose(1, 0.0, x0, np.zeros(box.ndof), box.ndof))
        assert s.wait(60.0)  # then the 50 ms of session run (generous: a busy machine)
        dev.close()
    finally:
        s.stop()
        handle.close()
    assert s.sim.time_s == pytest.approx(0.05)
