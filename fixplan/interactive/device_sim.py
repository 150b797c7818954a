"""``fixplan device-sim``: the UDP bridge's reference client, a simulated device and its operator.

The device is a handle of mass ``M`` with viscous damping ``b`` (both from fixplan's CONFIG: the
damping that keeps the coupling passive), integrated at 1 kHz under the operator's hand and the
felt wrench fixplan sends back. The operator follows the guidance like a person would: it pushes
with the suggested wrench ``w`` (seen ``delay`` late, with relative force noise redrawn every
10 ms) and holds the handle ``w / K`` ahead of the part with the arm's impedance (PD gains from
CONFIG, those of :func:`~fixplan.haptics.rig.haptic_rig`):

    f_hand = w + b_c ẋ_part + kp (x_part + w/K − x_handle) + kd (ẋ_part − ẋ_handle),

cancelling the handle's damping ``b`` only down to what keeps its sampled PD passive
(``b_c = b − 1.5 kp T``, :func:`~fixplan.haptics.coupling.compensable_damping`): cancelling all of
it made the part and the handle, moving together, gain speed by themselves (a slender shaft's spin
about its own axis doubled every 50 ms, and only guidance without delay held it).

``push`` replaces the guidance by a constant wrench (a person insisting on a push: a jam demo).
Each POSE carries the device's clock; each answer echoes it, so the round trip is measured here.
When fixplan has not answered for ``peer_timeout_s`` (``--peer-timeout``, 2 s by default) it is
taken to be gone: the run ends (``fixplan device-sim`` says so in one line and exits 1, as for any
run that did not see the goal).
"""

from __future__ import annotations

import math
import socket
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fixplan.errors import InputError
from fixplan.haptics.coupling import compensable_damping
from fixplan.interactive import protocol
from fixplan.interactive.handles import Handle
from fixplan.settings import HAPTIC

FloatArray = NDArray[np.float64]


@dataclass
class DeviceSimResult:
    """What the simulated device saw."""

    sent: int = 0
    received: int = 0
    dropped: int = 0  # answers that arrived out of order or malformed
    rtt_s: list[float] = field(default_factory=list)
    goal: bool = False
    ended: bool = False  # fixplan said the session ended
    duration_s: float = 0.0
    last_flags: int = 0
    late_cycles: int = 0  # cycles that started more than one period late
    scheduling: str = "normal"
    peer_gone_s: float | None = None  # fixplan stopped answering: ended after this long without an answer

    @property
    def rtt_mean_ms(self) -> float:
        return float(np.mean(self.rtt_s) * 1e3) if self.rtt_s else float("nan")

    @property
    def rtt_p99_ms(self) -> float:
        return float(np.percentile(self.rtt_s, 99) * 1e3) if self.rtt_s else float("nan")

    def to_json(self) -> dict[str, Any]:
        def fin(x: float) -> float | None:
            return x if math.isfinite(x) else None

        return {
            "sent": self.sent, "received": self.received, "dropped": self.dropped, "goal": self.goal,
            "ended": self.ended, "duration_s": self.duration_s, "rtt_mean_ms": fin(self.rtt_mean_ms),
            "rtt_p99_ms": fin(self.rtt_p99_ms), "late_cycles": self.late_cycles, "scheduling": self.scheduling,
            "peer_gone_s": self.peer_gone_s,
        }  # fmt: skip


class OperatorDevice:
    """The simulated handle and the operator's hand on it, one period at a time (no I/O).

    ``config`` is fixplan's CONFIG. :meth:`advance` integrates the handle for one period under the
    hand and the felt wrench, given fixplan's latest answer (felt wrench, part coordinates and rates,
    suggested push) seen at time ``t``.
    """

    def __init__(self, config: dict[str, Any], *, noise: float = 0.05, delay_s: float = 0.05,
                 push: FloatArray | None = None, seed: int = 0, period_s: float | None = None):  # fmt: skip
        self.n = n = int(config["ndof"])
        self.T = float(period_s if period_s is not None else config["period_s"])
        self.K = np.asarray(config["K"], dtype=float)
        self.b = np.asarray(config["device_damping"], dtype=float)
        self.M = np.asarray(config["device_mass"], dtype=float)
        self.kp = np.asarray(config["operator_kp"], dtype=float)
        self.kd = np.asarray(config["operator_kd"], dtype=float)
        self.x0 = np.asarray(config["x0"], dtype=float)
        # the part of the handle's damping the hand cancels (module text)
        self.b_hand = compensable_damping(self.b, self.kp, self.T, HAPTIC.haptic.passivity_safety)
        self.x = self.x0.copy()
        self.v = np.zeros(n)
        self.noise = noise
        self.delay_s = delay_s
        self.push = None if push is None else np.asarray(push, dtype=float)
        self.rng = np.random.default_rng(seed)
        self._seen: deque[tuple[float, FloatArray]] = deque()
        self._guidance = np.zeros(n)
        self._noisy = np.zeros(n)
        self._next_noise = 0.0

    def advance(self, t: float, felt: FloatArray, part: tuple[FloatArray, FloatArray] | None,
                suggested: FloatArray | None) -> None:  # fmt: skip
        """One period: the operator reacts to the guidance seen ``delay_s`` ago, the handle moves."""
        if suggested is not None:
            self._seen.append((t, np.asarray(suggested, dtype=float)[: self.n].copy()))
        while len(self._seen) > 1 and self._seen[1][0] <= t - self.delay_s:
            self._seen.popleft()
        if self._seen and self._seen[0][0] <= t - self.delay_s:
            self._guidance = self._seen[0][1]
        if t >= self._next_noise:
            self._next_noise = t + 0.01
            self._noisy = self.rng.standard_normal(self.n) * self.noise
        w = self.push.copy() if self.push is not None else self._guidance * (1.0 + self._noisy)
        if part is not None:
            x_w, v_w = part
            hand = w + self.b_hand * v_w + self.kp * (x_w + w / self.K - self.x) + self.kd * (v_w - self.v)
        else:  # the part is not known yet: hold the handle where it started
            hand = self.kp * (self.x0 - self.x) - self.kd * self.v
        T, M = self.T, self.M
        self.v = (self.v + T * (hand + felt[: self.n]) / M) / (1.0 + T * self.b / M)
        self.x = self.x + T * self.v


class LockstepHandle(Handle):
    """An :class:`OperatorDevice` wired straight into a session, one period per tick (reproducible runs).

    A :class:`~fixplan.interactive.handles.Handle` without sockets: :meth:`read` gives the handle's
    pose, :meth:`display` receives the felt wrench and the answer a UDP device would, and advances
    the device.
    """

    kind = "device-sim (lock-step)"

    def __init__(self, config: dict[str, Any], **options: Any):
        self.device = OperatorDevice(config, **options)

    def read(self, now_s: float) -> tuple[FloatArray, FloatArray]:
        return self.device.x.copy(), self.device.v.copy()

    def display(self, felt: FloatArray, answer: Any = None) -> None:
        if answer is None:
            return
        a = answer(0, 0.0)
        n = self.device.n
        self.device.advance(a.t_session_s, np.asarray(felt, dtype=float), (a.part_pose[:n], a.part_twist[:n]), a.push)

    def close(self) -> None:
        pass


class DeviceSim:
    """A simulated haptic device with a human-like operator, speaking the bridge protocol."""

    def __init__(
        self,
        host: str = "127.0.0.1",
        port: int = 7777,
        *,
        noise: float = 0.05,
        delay_ms: float = 50.0,
        duration_s: float | None = None,
        push: FloatArray | None = None,
        rate_hz: float = 1000.0,
        seed: int = 0,
        connect_timeout_s: float = 60.0,
        lockstep: bool = False,
        token: str | None = None,
        peer_timeout_s: float = HAPTIC.haptic.peer_timeout_s,
    ):
        for name, value, lo in (("DeviceSim.noise", noise, 0.0), ("DeviceSim.delay_ms", delay_ms, 0.0)):
            if not (math.isfinite(value) and value >= lo):
                raise InputError(f"{name} must be a finite number ≥ {lo:g}, got {value}")
        if noise > 1.0:
            raise InputError(f"DeviceSim.noise is relative (0..1), got {noise}")
        if delay_ms > 2000.0:
            raise InputError(f"DeviceSim.delay_ms must be at most 2000 ms, got {delay_ms}")
        if duration_s is not None and not (math.isfinite(duration_s) and duration_s > 0):
            raise InputError(f"DeviceSim.duration_s must be a positive number of seconds, got {duration_s}")
        if not (math.isfinite(peer_timeout_s) and peer_timeout_s > 0):
            raise InputError(f"DeviceSim.peer_timeout_s must be a positive number of seconds, got {peer_timeout_s}")
        if not (0 < port <= 65535):
            raise InputError(f"DeviceSim.port must be 1..65535, got {port}")
        self.addr = (host, port)
        self.noise = noise
        self.delay_s = delay_ms * 1e-3
        self.duration_s = duration_s
        self.push = None if push is None else np.asarray(push, dtype=float)
        self.period_s = 1.0 / rate_hz
        self.seed = seed
        self.lockstep = lockstep
        self.token = token
        self.connect_timeout_s = connect_timeout_s
        self.peer_timeout_s = peer_timeout_s
        self.config: dict[str, Any] = {}
        try:
            self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            self.sock.connect(self.addr)
        except OSError as exc:
            raise InputError(f"device-sim: cannot reach {host}:{port}: {exc.strerror or exc}") from None
        self.sock.setblocking(False)

    def connect(self) -> dict[str, Any]:
        """HELLO until fixplan answers with its CONFIG (or the connect time-out)."""
        deadline = time.perf_counter() + self.connect_timeout_s
        while time.perf_counter() < deadline:
            try:
                self.sock.send(protocol.encode_hello(self.token))
            except OSError:
                pass  # nobody listening yet (ICMP refused): try again
            t_wait = time.perf_counter() + 0.2
            while time.perf_counter() < t_wait:
                try:
                    data = self.sock.recv(65536)
                except (BlockingIOError, InterruptedError, ConnectionRefusedError):
                    time.sleep(0.005)
                    continue
                except OSError:
                    time.sleep(0.005)
                    continue
                try:
                    if protocol.message_type(data) == protocol.CONFIG:
                        self.config = protocol.decode_config(data)
                        return self.config
                except protocol.ProtocolError:
                    continue
        host, port = self.addr
        raise InputError(
            f"device-sim: no 'fixplan haptic --device udp:{port}' answered at {host}:{port} within {self.connect_timeout_s:g} s"
        )

    def run(self) -> DeviceSimResult:
        cfg = self.config or self.connect()
        dev = OperatorDevice(cfg, noise=self.noise, delay_s=self.delay_s, push=self.push, seed=self.seed,
                             period_s=self.period_s)  # fmt: skip
        n = dev.n
        T = self.period_s
        felt = np.zeros(n)
        part: tuple[FloatArray, FloatArray] | None = None
        suggested: FloatArray | None = None
        last_seq = -1
        res = DeviceSimResult()
        if not self.lockstep:
            from fixplan.interactive.session import real_time_priority

            res.scheduling = real_time_priority(30)  # a device's servo loop runs at real-time priority too
        seq = 0
        t0 = time.perf_counter()
        next_t = t0
        last_answer = t0  # fixplan answered the HELLO just now
        while True:
            if self.lockstep:
                # the device clock: one period per exchange, as fast as fixplan answers (no wall clock)
                if seq and not self._await_answer(seq, self.peer_timeout_s):
                    res.peer_gone_s = time.perf_counter() - last_answer
                    break
                last_answer = time.perf_counter()
                t = seq * T
            else:
                next_t += T
                now = time.perf_counter()
                if next_t > now:
                    time.sleep(next_t - now)  # sleeps a little long (tens of µs): no busy wait, the cores are shared
                now = time.perf_counter()
                if now - next_t > T:
                    res.late_cycles += 1
                    if now - next_t > 50 * T:
                        next_t = now
                t = now - t0
            suggested = None
            # every answer that came in: the newest (by sequence) is used, the round trip of each kept
            for _ in range(64):
                try:
                    data = self.sock.recv(4096)
                except OSError:  # nothing waiting (BlockingIOError), or fixplan is gone
                    break
                try:
                    ans = protocol.decode_force(data)
                except protocol.ProtocolError:
                    res.dropped += 1
                    continue
                res.received += 1
                last_answer = time.perf_counter()
                res.rtt_s.append(time.perf_counter() - t0 - ans.t_echo_s)
                if ans.seq <= last_seq:
                    res.dropped += 1
                    continue
                last_seq = ans.seq
                felt = ans.felt[:n].copy()
                part = (ans.part_pose[:n].copy(), ans.part_twist[:n].copy())
                suggested = ans.push[:n].copy()
                res.last_flags = ans.flags
                if ans.flags & protocol.FLAG_GOAL:
                    res.goal = True
                if ans.flags & protocol.FLAG_ENDED:
                    res.ended = True
            if res.ended or (self.duration_s is not None and t >= self.duration_s):
                break
            if time.perf_counter() - last_answer > self.peer_timeout_s:  # fixplan is gone (or stopped answering)
                res.peer_gone_s = time.perf_counter() - last_answer
                break
            dev.advance(t, felt, part, suggested)
            seq += 1
            try:
                self.sock.send(protocol.encode_pose(seq, time.perf_counter() - t0, dev.x, dev.v, n))
                res.sent += 1
            except OSError:
                pass
        res.duration_s = time.perf_counter() - t0
        return res

    def _await_answer(self, seq: int, timeout_s: float = 5.0) -> bool:
        """Lock-step: wait until an answer to pose ``seq`` is waiting (it is then read as usual)."""
        import select

        deadline = time.perf_counter() + timeout_s
        while time.perf_counter() < deadline:
            if not select.select([self.sock], [], [], 0.05)[0]:
                continue
            try:
                data = self.sock.recv(4096, socket.MSG_PEEK)
            except OSError:
                return False
            try:
                ans = protocol.decode_force(data)
            except protocol.ProtocolError:
                self.sock.recv(4096)  # drop it
                continue
            if ans.echo_seq >= seq or ans.flags & protocol.FLAG_ENDED:
                return True
            self.sock.recv(4096)  # an answer to an older pose: used for nothing in lock-step
        return False

    def close(self) -> None:
        self.sock.close()
