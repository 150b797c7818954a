"""The device side of the interactive coupling: where the handle is, and where the felt wrench goes.

A handle reports the device's pose and twist in device coordinates (the haptic loop's: body
origin [m] and rotation vector of ``R R_startᵀ`` [rad]; 2D ``x, y, θ``) once per tick, or
``None`` while it has nothing to say (no device yet, or it went silent): the coupling then goes
limp (no push on the part). :meth:`Handle.display` receives the wrench to display.

- :class:`GizmoHandle`: a pose set from another thread (the viser transform gizmo, or a script
  moving it through viser's Python API); its twist is the low-passed finite difference.
- :class:`UdpHandle`: the bridge protocol (:mod:`.protocol`); the socket is drained every tick.
- :class:`SpaceMouseHandle`: a 3Dconnexion SpaceMouse through ``pyspacemouse``, in rate control.
"""

from __future__ import annotations

import hmac
import math
import socket
import threading
import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fixplan.errors import InputError
from fixplan.interactive import protocol

FloatArray = NDArray[np.float64]


class Handle(ABC):
    """A device handle as the loop sees it."""

    kind = "handle"

    @abstractmethod
    def read(self, now_s: float) -> tuple[FloatArray, FloatArray] | None:
        """``(pose, twist)`` in device coordinates, or None when there is no device input."""

    def display(self, felt: FloatArray, answer: Callable[[int, float], protocol.ForcePacket] | None = None) -> None:  # noqa: B027
        """Display the felt wrench (the bridge also sends the guidance: ``answer(seq, t)`` builds it)."""

    def close(self) -> None:  # noqa: B027 - most handles hold nothing to release
        """Release the device."""


class GizmoHandle(Handle):
    """A handle whose pose is set from outside (the viser gizmo); twist from a filtered difference."""

    kind = "mouse"

    def __init__(self, x0: FloatArray, *, period_s: float = 1e-3, filter_s: float = 0.02):
        self._pose = np.array(x0, dtype=float)
        self._x = self._pose.copy()
        self._v = np.zeros_like(self._x)
        self._alpha = min(period_s / filter_s, 1.0)
        self._period = period_s
        self.moves = 0

    def set_pose(self, x: FloatArray) -> None:
        """The gizmo moved (called from the display thread; one reference swap)."""
        x = np.array(x, dtype=float)
        if x.shape == self._pose.shape and np.all(np.isfinite(x)):
            self._pose = x
            self.moves += 1

    @property
    def pose(self) -> FloatArray:
        return self._pose.copy()

    def read(self, now_s: float) -> tuple[FloatArray, FloatArray]:
        target = self._pose
        v_raw = (target - self._x) / self._period
        self._v = self._v + self._alpha * (v_raw - self._v)
        self._x = target
        return target, self._v.copy()


@dataclass
class BridgeStats:
    """What the UDP bridge received and sent."""

    received: int = 0
    accepted: int = 0
    malformed: int = 0
    out_of_order: int = 0
    hellos: int = 0
    sent: int = 0
    send_errors: int = 0
    timeouts: int = 0  # the device went silent for longer than the timeout
    refused: int = 0  # HELLO with a wrong token, or poses from an address without a HELLO (token set)
    last_error: str = ""
    clients: set[Any] = field(default_factory=set)

    def to_json(self) -> dict[str, Any]:
        return {
            "received": self.received, "accepted": self.accepted, "malformed": self.malformed,
            "out_of_order": self.out_of_order, "hellos": self.hellos, "sent": self.sent,
            "send_errors": self.send_errors, "timeouts": self.timeouts, "refused": self.refused,
            "last_error": self.last_error,
        }  # fmt: skip


class UdpHandle(Handle):
    """The UDP bridge: poses in, forces and guidance out (see :mod:`fixplan.interactive.protocol`)."""

    kind = "udp"

    def __init__(
        self,
        host: str,
        port: int,
        ndof: int,
        config: dict[str, Any] | None = None,
        *,
        timeout_s: float = 0.2,
        token: str | None = None,
    ):
        self.ndof = ndof
        self.config: dict[str, Any] = dict(config or {})
        self.timeout_s = timeout_s
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.sock.bind((host, port))
        except OSError as exc:
            self.sock.close()
            raise InputError(
                f"run_session.device udp:{port}: cannot bind {host}:{port}: {exc.strerror or exc}"
            ) from None
        self.sock.setblocking(False)
        self.port = int(self.sock.getsockname()[1])
        self.stats = BridgeStats()
        self.token = token
        self._allowed: set[Any] = set()  # addresses whose HELLO carried the token
        self._client: Any = None
        self._last: protocol.PosePacket | None = None
        self._last_at = -math.inf
        self._last_seq = -1
        self._silent = False
        self._seq = 0
        self.fresh = False  # the last read() accepted a new pose
        self.one_per_read = False  # the device clock: each read takes one pose (one tick per pose)

    def wait_readable(self, timeout_s: float) -> bool:
        """Block until a datagram is waiting (the device clock: one tick per pose)."""
        import select

        try:
            return bool(select.select([self.sock], [], [], timeout_s)[0])
        except (OSError, ValueError):  # closed
            return False

    def read(self, now_s: float) -> tuple[FloatArray, FloatArray] | None:
        self.fresh = False
        for _ in range(64):  # bounded: a flood cannot hold the tick
            try:
                data, addr = self.sock.recvfrom(2048)
            except (BlockingIOError, InterruptedError):
                break
            except OSError as exc:  # e.g. ICMP port unreachable from a client that left
                self.stats.last_error = str(exc)
                break
            self.stats.received += 1
            try:
                kind = protocol.message_type(data)
                if kind == protocol.HELLO:
                    if self.token is not None and not hmac.compare_digest(
                        protocol.hello_token(data).encode(), self.token.encode()
                    ):
                        self.stats.refused += 1
                        continue
                    self.stats.hellos += 1
                    self._allowed.add(addr)
                    self._client = addr
                    self._last_seq = -1  # a new session of the device restarts its sequence
                    self._send(protocol.encode_config(self.config), addr)
                    continue
                if kind != protocol.POSE:
                    raise protocol.ProtocolError(f"unexpected message type {kind}")
                if self.token is not None and addr not in self._allowed:
                    self.stats.refused += 1
                    continue
                pkt = protocol.decode_pose(data, self.ndof)
            except protocol.ProtocolError as exc:
                self.stats.malformed += 1
                self.stats.last_error = str(exc)
                continue
            if pkt.seq <= self._last_seq:
                self.stats.out_of_order += 1
                continue
            self.stats.accepted += 1
            self._last_seq = pkt.seq
            self._last = pkt
            self._last_at = now_s
            self._client = addr
            self._silent = False
            self.fresh = True
            if self.one_per_read:
                break
        if self._last is None:
            return None
        if now_s - self._last_at > self.timeout_s:
            if not self._silent:
                self._silent = True
                self.stats.timeouts += 1
            return None
        n = self.ndof
        return self._last.pose[:n].copy(), self._last.twist[:n].copy()

    @property
    def last_pose(self) -> protocol.PosePacket | None:
        return self._last

    def display(self, felt: FloatArray, answer: Callable[[int, float], protocol.ForcePacket] | None = None) -> None:
        if self._client is None or self._last is None or answer is None:
            return
        self._seq += 1
        self._send(protocol.encode_force(answer(self._seq, self._last.t_device_s)), self._client, self._last.seq)

    def _send(self, data: bytes, addr: Any, _seq: int = 0) -> None:
        try:
            self.sock.sendto(data, addr)
            self.stats.sent += 1
        except OSError as exc:
            self.stats.send_errors += 1
            self.stats.last_error = str(exc)

    def close(self) -> None:
        self.sock.close()


class SpaceMouseHandle(Handle):
    """A 3Dconnexion SpaceMouse in rate control: deflection → handle velocity, integrated."""

    kind = "spacemouse"

    def __init__(self, x0: FloatArray, *, speed_mps: float = 0.05, spin_radps: float = 0.5):
        try:
            import pyspacemouse  # type: ignore[import-not-found]
        except ImportError:
            raise InputError(
                "run_session.device spacemouse needs the optional package pyspacemouse: pip install 'fixplan[devices]'"
            ) from None
        try:
            ok = pyspacemouse.open()
        except Exception as exc:  # noqa: BLE001 - a vendor library's failure, reported as one line
            raise InputError(f"run_session.device spacemouse: cannot open the SpaceMouse: {exc}") from None
        if not ok:
            raise InputError("run_session.device spacemouse: no SpaceMouse found (is it plugged in and readable?)")
        self._mod = pyspacemouse
        self._x = np.array(x0, dtype=float)
        self._rate = np.zeros_like(self._x)
        self._scale = np.array([speed_mps] * 3 + [spin_radps] * 3)[: self._x.shape[0]]
        if self._x.shape[0] == 3:
            self._scale = np.array([speed_mps, speed_mps, spin_radps])
        self._last = time.perf_counter()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._poll, name="spacemouse", daemon=True)
        self._thread.start()

    def _poll(self) -> None:
        while not self._stop.is_set():
            s = self._mod.read()
            if self._x.shape[0] == 6:
                raw = np.array([s.x, s.y, s.z, s.roll, s.pitch, s.yaw], dtype=float)
            else:
                raw = np.array([s.x, s.y, s.yaw], dtype=float)
            self._rate = np.clip(raw, -1.0, 1.0) * self._scale
            time.sleep(0.005)

    def read(self, now_s: float) -> tuple[FloatArray, FloatArray]:
        t = time.perf_counter()
        dt = min(t - self._last, 0.01)
        self._last = t
        v = self._rate
        self._x = self._x + dt * v
        return self._x.copy(), v.copy()

    def close(self) -> None:
        self._stop.set()
        try:
            self._mod.close()
        except Exception:  # noqa: BLE001 - closing a device that may be gone
            pass


def parse_device(text: str) -> tuple[str, int | None]:
    """``mouse``, ``spacemouse``, ``udp`` or ``udp:PORT`` → (kind, port)."""
    t = text.strip().lower()
    if t in ("mouse", "spacemouse"):
        return t, None
    if t == "udp":
        return "udp", 7777
    if t.startswith("udp:"):
        try:
            port = int(t[4:])
        except ValueError:
            raise InputError(f"run_session.device udp:PORT expects a port number, got {text!r}") from None
        if not 0 <= port <= 65535:
            raise InputError(f"run_session.device udp:PORT: port must be 0..65535, got {port}")
        return "udp", port
    raise InputError(f"run_session.device must be mouse, spacemouse or udp[:PORT], got {text!r}")
