"""fixplan haptic's core: the bridge protocol, the coupling's physics, sessions to the goal and to a jam, recordings.

Sessions here run without a wall clock (``realtime=False``, the guidance inside the loop), so they
are reproducible; the real-time loop's timing is measured in ``benchmarks/bench_haptic.py``.
"""

import json
import socket

import numpy as np
import pytest
from conftest import PROBLEMS

import fixplan
from fixplan.errors import InputError
from fixplan.haptics.coordinates import coordinates_from_pose, pose_from_coordinates
from fixplan.interactive import protocol
from fixplan.interactive.commands import check_host, parse_until
from fixplan.interactive.device_sim import LockstepHandle, OperatorDevice
from fixplan.interactive.handles import UdpHandle, parse_device
from fixplan.interactive.record import plan_json, verify_recording
from fixplan.interactive.session import HapticSession
from fixplan.present.replay import replay_from_plan


@pytest.fixture(scope="module")
def box():
    return fixplan.load(fixplan.default_fixture_path())


@pytest.fixture(scope="module")
def auto_session(box):
    """The planner's executor drives the simulated device (auto), no wall clock: to the goal."""
    s = HapticSession(box, None, realtime=False, synchronous=True, duration_s=10.0)
    return s, s.run()


@pytest.fixture(scope="module")
def auto_recording(box, auto_session):
    return json.loads(json.dumps(plan_json(auto_session[1], box), allow_nan=False))


# -- protocol --------------------------------------------------------------------------------------
def test_pose_and_force_packets_round_trip(rng):
    pose, twist = rng.normal(size=6), rng.normal(size=6)
    data = protocol.encode_pose(41, 1.25, pose, twist, 6)
    assert len(data) == protocol.POSE_SIZE
    p = protocol.decode_pose(data, 6)
    assert (p.seq, p.t_device_s) == (41, 1.25)
    np.testing.assert_array_equal(p.pose, pose)
    np.testing.assert_array_equal(p.twist, twist)
    f = protocol.ForcePacket(7, 41, 1.25, 0.5, protocol.FLAG_GOAL | protocol.FLAG_JAMMED, rng.normal(size=6),
                             rng.normal(size=6), rng.normal(size=6), 3, 2, 1, 0.25, rng.normal(size=6), 6)  # fmt: skip
    g = protocol.decode_force(protocol.encode_force(f))
    assert (g.seq, g.echo_seq, g.t_echo_s, g.flags, g.target, g.transition, g.verdict) == (7, 41, 1.25, 3, 3, 2, 1)
    assert g.margin == pytest.approx(0.25)
    for a, b in ((g.felt, f.felt), (g.part_pose, f.part_pose), (g.part_twist, f.part_twist), (g.push, f.push)):
        np.testing.assert_array_equal(a, b)
    # 2D scenes pad their three coordinates with zeros
    p2 = protocol.decode_pose(protocol.encode_pose(1, 0.0, [1, 2, 3], [4, 5, 6], 3), 3)
    np.testing.assert_array_equal(p2.pose, [1, 2, 3, 0, 0, 0])


@pytest.mark.parametrize(
    ("data", "match"),
    [
        (b"FXP1\x01", "POSE is"),
        (b"XXXX" + bytes(protocol.POSE_SIZE - 4), "not a POSE"),
        (protocol.encode_pose(1, 0.0, np.zeros(6), np.zeros(6), 3), "ndof 3"),
        (protocol.encode_pose(1, 0.0, [np.nan] + [0] * 5, np.zeros(6), 6), "non-finite"),
    ],
)
def test_malformed_poses_are_refused(data, match):
    with pytest.raises(protocol.ProtocolError, match=match):
        protocol.decode_pose(data, 6)


def test_bridge_counts_and_drops_malformed_and_out_of_order_packets(box):
    h = UdpHandle("127.0.0.1", 0, 6, {"ndof": 6})
    client = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    client.settimeout(2.0)
    try:
        client.sendto(protocol.encode_hello(), ("127.0.0.1", h.port))
        for seq, x in ((5, 0.1), (3, 0.9), (6, 0.2)):  # 3 arrives after 5: out of order
            client.sendto(protocol.encode_pose(seq, 0.0, [x] * 6, np.zeros(6), 6), ("127.0.0.1", h.port))
        client.sendto(b"garbage", ("127.0.0.1", h.port))
        client.sendto(protocol.encode_pose(7, 0.0, [np.inf] * 6, np.zeros(6), 6), ("127.0.0.1", h.port))
        for _ in range(200):  # the datagrams arrive in their own time on loopback
            out = h.read(0.0)
            if h.stats.received >= 6:
                break
        assert protocol.decode_config(client.recv(65536)) == {"ndof": 6}  # HELLO was answered
        assert (h.stats.accepted, h.stats.out_of_order, h.stats.malformed, h.stats.hellos) == (2, 1, 2, 1)
        assert out is not None
        np.testing.assert_array_equal(out[0], [0.2] * 6)  # the newest valid pose; the loop went on
        assert h.read(1.0) is None  # silent past the time-out: the coupling goes limp
        assert h.stats.timeouts == 1
    finally:
        client.close()
        h.close()


def test_device_option_and_until_and_host_parsing():
    assert parse_device("udp") == ("udp", 7777)
    assert parse_device("UDP:9000") == ("udp", 9000)
    assert parse_device("mouse") == ("mouse", None)
    for bad in ("joystick", "udp:x", "udp:70000"):
        with pytest.raises(InputError, match="run_session.device"):
            parse_device(bad)
    assert parse_until("goal") == (True, None)
    assert parse_until("2.5") == (False, 2.5)
    for bad in ("soon", "-1", "nan", "1e9"):
        with pytest.raises(InputError, match="parse_until.text"):
            parse_until(bad)
    assert check_host("127.0.0.1", None) is None
    generated = check_host("0.0.0.0", None)  # noqa: S104 - the check under test
    assert generated is not None and len(generated) >= 16
    with pytest.raises(InputError, match="check_host.token"):
        check_host("0.0.0.0", "short")  # noqa: S104


# -- the coupling's physics ------------------------------------------------------------------------
def test_coordinates_match_the_haptic_loops(box):
    s = HapticSession(box, None, realtime=False, synchronous=False, guidance=False)
    s.sim.set_state(box.start, np.array([0.01, -0.02, 0.03, 0.4, -0.2, 0.1]))
    for _ in range(3):
        s.sim.step(np.zeros(6))
    x, v = s.coordinates()
    x_ref, v_ref = s.rig.loop.workpiece_coordinates()
    np.testing.assert_allclose(x, x_ref, atol=1e-14)
    np.testing.assert_allclose(v, v_ref, atol=1e-14)
    # the proxy pose drawn for device coordinates x is the pose whose coordinates are x
    pose = pose_from_coordinates(x, s.R0, 3)
    np.testing.assert_allclose(coordinates_from_pose(pose, s.R0), x, atol=1e-12)


def test_first_tick_pushes_with_the_spring_and_the_device_feels_its_reaction(box):
    """A handle held 1 mm beside the part at rest: w = K·dx on the part, −w on the device."""
    s = HapticSession(box, None, realtime=False, synchronous=False, guidance=False)
    cfg = s.bridge_config()
    dev = LockstepHandle(cfg, noise=0.0, delay_s=0.0)
    dx = np.array([1e-3, 0, 0, 0, 0, 0])
    dev.device.x = s.x0 + dx
    s.handle, s._auto = dev, False
    s._warm_up()
    s.tick(0.0)
    w = s.trace.coupling_wrench or [s._acc_w]
    np.testing.assert_allclose(w[-1][:3], s.K[:3] * dx[:3], rtol=1e-12)
    assert s.K[0] == pytest.approx(1000.0 * box.workpiece.mass_kg)  # haptic_rig's 1000 N/m per kg
    np.testing.assert_allclose(s._acc_f, -s._acc_w, atol=0)  # felt = −coupling (within the device's limits)


def test_stiffness_scale_is_bounded_by_passivity(box):
    s = HapticSession(box, None, realtime=False, guidance=False)
    T = s.period_s
    # b > K·s·T/2 + |B| holds up to the bound for every coordinate, and fails just past it
    bound = min((b - abs(B)) / (K * T / 2) for K, B, b in zip(s.K, s.B, s.device_damping, strict=True))
    assert s.stiffness_scale_max == pytest.approx(0.99 * bound)
    assert s.set_stiffness_scale(s.stiffness_scale_max) == pytest.approx(s.stiffness_scale_max)
    with pytest.raises(InputError, match="not passive"):
        s.set_stiffness_scale(1.01 * bound)


def test_operator_device_transmits_the_suggested_push_at_rest(box):
    """At equilibrium the hand's push reaches the part: K (x − x_w) = w for a still handle and part."""
    s = HapticSession(box, None, realtime=False, guidance=False)
    cfg = s.bridge_config()
    op = OperatorDevice(cfg, noise=0.0, delay_s=0.0)
    w = np.array([-3.0, 1.0, -5.0, 0.01, 0.0, 0.02])
    x_w = np.asarray(cfg["x0"])
    for k in range(3000):  # part held still; the handle settles under the hand and the felt spring
        felt = -(np.asarray(cfg["K"]) * (op.x - x_w) + np.asarray(cfg["B"]) * op.v)
        op.advance(k * 1e-3, felt, (x_w, np.zeros(6)), w)
    transmitted = np.asarray(cfg["K"]) * (op.x - x_w)
    np.testing.assert_allclose(transmitted, w, rtol=1e-6, atol=1e-9)


# -- sessions --------------------------------------------------------------------------------------
def test_auto_session_reaches_the_goal_and_felt_is_the_coupling_reaction(box, auto_session):
    s, res = auto_session
    assert res.status == "reached", res.reason
    names = {loc.name for loc in box.locators}
    assert set(res.states[-1][1]) == names
    assert res.states[0][1] == ("B1", "B2", "B3")  # rests on the base at the start
    W, F = np.array(res.trace.coupling_wrench), np.array(res.trace.felt_wrench)
    np.testing.assert_allclose(F, -W, atol=1e-12)  # what the device displays is the coupling's reaction
    assert res.felt_equals_coupling_max_N == 0.0
    # the verdict of the current push is refreshed every 40 ms of session time (25 Hz ≥ the 20 Hz asked)
    assert res.rates["verdict_hz"] >= 20.0 and res.rates["guidance_hz"] >= 90.0
    assert max(abs(g) for g in res.final_gaps_m.values()) < 1e-4
    assert res.max_penetration_m < 1e-5
    # the push stays within the hand's limits (the coupling saturates there)
    assert np.max(np.linalg.norm(W[:, :3], axis=1)) <= s.F_max * (1 + 1e-9)


def test_recording_replays_and_verifies(box, auto_recording):
    data = auto_recording
    assert data["source"] == "haptic session" and data["status"] == "reached"
    assert data["sequence"][-1] == sorted(loc.name for loc in box.locators)
    assert [t["added"] for t in data["transitions"]] == ["E1", "S1", "S2"]
    for tr in data["transitions"]:
        W = np.array(tr["pushes"]["wrench"])
        assert W.shape[1] == 6 and len(tr["pushes"]["time_s"]) == len(W)
        np.testing.assert_allclose(tr["wrench"], W.mean(axis=0), rtol=1e-5, atol=1e-5)
    replay = replay_from_plan(data, box, "rec")  # what fixplan view --plan shows
    assert replay.source == "trace" and len(replay) == len(data["verification"]["trace"]["time_s"])
    assert replay.note.startswith("haptic session (passed)")
    v = verify_recording(box, data)
    assert v.passed, v.reason
    assert [tuple(s) for s in v.observed_sequence][-1] == tuple(sorted(loc.name for loc in box.locators))
    assert v.max_penetration_m < 1e-5


def test_lockstep_device_with_noise_and_delay_follows_the_guidance_to_the_goal(box):
    """device-sim's operator (5 % force noise, 50 ms reaction delay) wired one period per tick."""
    s = HapticSession(box, None, realtime=False, synchronous=True, duration_s=10.0)
    s.handle = LockstepHandle(s.bridge_config(), noise=0.05, delay_s=0.05, seed=1)
    s._auto = False
    res = s.run()
    assert res.status == "reached", res.reason
    data = json.loads(json.dumps(plan_json(res, box)))
    v = verify_recording(box, data)
    assert v.passed, v.reason


def test_jammed_session_is_recorded_as_jammed_with_where(box):
    """A hand that insists on pushing down and sideways: friction holds the part, classify says jammed."""
    s = HapticSession(box, None, realtime=False, synchronous=True, until_goal=True, duration_s=1.0)
    s.handle = LockstepHandle(s.bridge_config(), push=np.array([0.0, -3.0, -30.0, 0, 0, 0]), noise=0.0, delay_s=0.0)
    s._auto = False
    res = s.run()
    assert res.status == "jammed", res.reason
    assert res.where["state"] == ["B1", "B2", "B3"]
    assert res.where["margin"] is not None and res.where["margin"] < 1e-6
    np.testing.assert_allclose(res.where["push"][:3], [0.0, -3.0, -30.0], atol=0.5)
    data = json.loads(json.dumps(plan_json(res, box)))
    assert data["status"] == "jammed" and data["where"]["state"] == ["B1", "B2", "B3"]
    assert data["verification"]["passed"] is False
    v = verify_recording(box, data)
    assert not v.passed and "jammed" in v.reason


def test_recording_of_a_long_session_stays_within_the_plan_file_limit(box, auto_session):
    from dataclasses import replace

    from fixplan.interactive.record import MAX_SAMPLES
    from fixplan.limits import MAX_FILE_BYTES

    res = auto_session[1]
    tr = res.trace
    long = replace(tr, **{f: getattr(tr, f) * 20 for f in tr.__dataclass_fields__})  # 20× the samples
    long.time_s = [k * res.every_s for k in range(len(long.time_s))]
    data = plan_json(replace(res, trace=long), box)
    assert len(data["verification"]["trace"]["time_s"]) <= MAX_SAMPLES
    assert len(json.dumps(data)) < MAX_FILE_BYTES


def test_bridge_with_a_token_answers_only_devices_that_present_it():
    h = UdpHandle("127.0.0.1", 0, 6, {"ndof": 6}, token="tok-0123456789")
    stranger = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    device = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    device.settimeout(2.0)
    try:
        stranger.sendto(protocol.encode_hello("wrong-token"), ("127.0.0.1", h.port))
        stranger.sendto(protocol.encode_pose(1, 0.0, [0.5] * 6, np.zeros(6), 6), ("127.0.0.1", h.port))
        device.sendto(protocol.encode_hello("tok-0123456789"), ("127.0.0.1", h.port))
        device.sendto(protocol.encode_pose(1, 0.0, [0.1] * 6, np.zeros(6), 6), ("127.0.0.1", h.port))
        out = None
        for _ in range(200):
            out = h.read(0.0)
            if h.stats.received >= 4:
                break
        assert (h.stats.refused, h.stats.hellos, h.stats.accepted) == (2, 1, 1)
        assert out is not None
        np.testing.assert_array_equal(out[0], [0.1] * 6)  # the stranger's pose was not used
        assert protocol.decode_config(device.recv(65536)) == {"ndof": 6}
    finally:
        stranger.close()
        device.close()
        h.close()


def test_reset_puts_the_part_back_at_rest_and_restarts_the_recording(box):
    s = HapticSession(box, None, realtime=False, synchronous=False, guidance=False)
    s._warm_up()
    s.guidance = s.guidance.__class__(push=np.array([-8.0, 0, -10.0, 0, 0, 0]))  # a push that slides the part
    for _ in range(200):
        s.tick(0.0)
    moved = np.linalg.norm(s.sim.pose.p_world - box.start.p_world)
    assert moved > 1e-4 and s.trace.time_s
    s.request_reset()
    s.tick(0.0)  # the loop thread applies it at its next tick
    assert s.resets == 1
    assert np.linalg.norm(s.sim.pose.p_world - box.start.p_world) < 1e-5  # one step from the start, at rest
    assert s.trace.time_s == [] and s.states == []


def test_a_2d_fixture_loads_and_its_recording_verifies():
    """A generated 2D plate (x, y, θ): the same loop with three coordinates."""

    fx = fixplan.load(PROBLEMS / "gen-plate-2d-s2026-000.toml")
    s = HapticSession(fx, None, realtime=False, synchronous=True, duration_s=10.0)
    assert s.ndof == 3 and s.bridge_config()["ndof"] == 3
    res = s.run()
    assert res.status == "reached", res.reason
    assert set(res.states[-1][1]) == {loc.name for loc in fx.locators}
    np.testing.assert_allclose(np.array(res.trace.felt_wrench), -np.array(res.trace.coupling_wrench), atol=1e-12)
    v = verify_recording(fx, json.loads(json.dumps(plan_json(res, fx))))
    assert v.passed, v.reason
