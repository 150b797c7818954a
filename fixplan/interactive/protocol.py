"""The UDP bridge protocol between a haptic device and ``fixplan haptic`` (version 1).

A device process (a small C/C++ program around a vendor SDK or CHAI3D, or ``fixplan device-sim``)
talks to fixplan over UDP, one datagram per message, all numbers little-endian. Device
coordinates are the haptic loop's: the body origin's position in the world frame [m] and the
rotation vector of ``R_world_body · R_startᵀ`` [rad] (3D, ``ndof`` 6); 2D: ``x, y, θ`` (``ndof``
3) followed by three zeros. Wrenches are force [N] and moment about the body origin [N·m] in
world axes, padded the same way.

``HELLO`` (device → fixplan, 8 bytes, then the token when fixplan has one)
    ``magic "FXP1"``, ``type u8 = 3``, 3 zero bytes, then the UTF-8 token (``fixplan haptic --host H
    --token T`` binds the bridge to ``H`` and accepts poses only from addresses whose HELLO carried
    ``T``; on 127.0.0.1 no token is needed). fixplan answers ``CONFIG``; a wrong token gets nothing.
``CONFIG`` (fixplan → device)
    ``magic``, ``type u8 = 4``, 3 zero bytes, then UTF-8 JSON: ``ndof``, ``period_s``, the coupling
    stiffness ``K`` and damping ``B`` per coordinate, the handle damping ``device_damping`` and
    mass ``device_mass`` that keep the coupling passive, the start coordinates ``x0``, the hand's
    limits ``F_max_N``/``T_max_Nm``, the locator ``names`` and the ``mode_names`` of verdicts.
``POSE`` (device → fixplan, :data:`POSE_SIZE` bytes, up to 1 kHz)
    ``magic``, ``type u8 = 1``, ``ndof u8``, ``flags u16`` (0), ``seq u32`` (increasing),
    ``t_device f64`` [s, the device's clock], ``pose 6×f64``, ``twist 6×f64``.
``FORCE`` (fixplan → device, :data:`FORCE_SIZE` bytes, one per haptic tick once a pose came)
    ``magic``, ``type u8 = 2``, ``ndof u8``, ``flags u16`` (:data:`FLAG_GOAL`, :data:`FLAG_JAMMED`,
    :data:`FLAG_AUTO`, :data:`FLAG_ENDED`), ``seq u32`` (fixplan's), ``echo_seq u32`` (the last
    pose used), ``t_echo f64`` (that pose's ``t_device``, so the device measures the round trip
    on its own clock), ``t_session f64`` [s], ``felt 6×f64`` (the wrench to display on the
    handle: minus the coupling wrench on the part), ``part pose 6×f64``, ``part twist 6×f64``,
    guidance: ``target i8`` (index into ``names``; −1 none), ``transition u8``, ``verdict u8``
    (index into ``mode_names``; 255 not yet known), 1 zero byte, ``margin f32``, ``push 6×f64``
    (the suggested non-jamming push on the part).

Malformed datagrams (wrong size, magic, type or ``ndof``, non-finite numbers) and out-of-order
poses (``seq`` not above the last accepted one) are counted and dropped; the loop goes on.

:data:`MESSAGES` describes each message's ``struct`` layout for people; :func:`markdown_table`
renders it, with the sizes the code uses, as the table in docs/haptic.md
(``python tools/protocol_docs.py --write``).
"""

from __future__ import annotations

import json
import math
import struct
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

MAGIC = b"FXP1"
POSE, FORCE, HELLO, CONFIG = 1, 2, 3, 4
FLAG_GOAL, FLAG_JAMMED, FLAG_AUTO, FLAG_ENDED = 1, 2, 4, 8
VERDICT_UNKNOWN = 255

_HEADER = struct.Struct("<4sB3x")
_POSE = struct.Struct("<4sBBHId6d6d")
_FORCE = struct.Struct("<4sBBHIIdd6d6d6dbBBxf6d")
POSE_SIZE = _POSE.size
FORCE_SIZE = _FORCE.size


@dataclass(frozen=True)
class MessageLayout:
    """One message as a device's programmer needs it: its ``struct`` layout, named field by field, and its size."""

    name: str
    direction: str
    layout: struct.Struct
    fields: tuple[str, ...]  # one per code of the format ("6d" is one field of six numbers, "3x" one of pad bytes)
    trailer: str = ""  # what follows the fixed part, if anything

    @property
    def size(self) -> str:
        """The size in bytes: the fixed part's, ``+`` when a variable trailer follows."""
        return f"{self.layout.size}" + (" +" if self.trailer else "")


MESSAGES: tuple[MessageLayout, ...] = (
    MessageLayout("HELLO", "device → fixplan", _HEADER, ("magic", "type 3", "3 zero bytes"),
                  "token (UTF-8, only with `--token`)"),
    MessageLayout("CONFIG", "fixplan → device", _HEADER, ("magic", "type 4", "3 zero bytes"), "UTF-8 JSON"),
    MessageLayout("POSE", "device → fixplan", _POSE,
                  ("magic", "type 1", "ndof", "flags 0", "seq", "t_device [s]", "pose[6]", "twist[6]")),
    MessageLayout("FORCE", "fixplan → device", _FORCE,
                  ("magic", "type 2", "ndof", "flags", "seq", "echo_seq", "t_echo [s]", "t_session [s]", "felt[6]",
                   "part pose[6]", "part twist[6]", "target", "transition", "verdict", "pad", "margin (f32)",
                   "push[6]")),
)  # fmt: skip


def markdown_table() -> str:
    """The messages as the Markdown table of docs/haptic.md: layout, fields and size from the code's structs."""
    rows = ["| message | direction | layout (`struct`) | size [bytes] |", "|---|---|---|---|"]
    for m in MESSAGES:
        layout = f"`{m.layout.format}`: " + ", ".join(m.fields) + (f"; then {m.trailer}" if m.trailer else "")
        rows.append(f"| {m.name} | {m.direction} | {layout} | {m.size} |")
    return "\n".join(rows) + "\n"


@dataclass(frozen=True)
class PosePacket:
    """A device's handle pose and twist (device coordinates, padded to 6)."""

    seq: int
    t_device_s: float
    pose: FloatArray  # (6,)
    twist: FloatArray  # (6,)
    ndof: int


@dataclass(frozen=True)
class ForcePacket:
    """fixplan's answer: the wrench to display, the part's state and the planner's guidance."""

    seq: int
    echo_seq: int
    t_echo_s: float
    t_session_s: float
    flags: int
    felt: FloatArray  # (6,) wrench to display on the handle
    part_pose: FloatArray  # (6,) the part in device coordinates
    part_twist: FloatArray  # (6,)
    target: int  # index of the next target locator, -1 none
    transition: int
    verdict: int  # index into CONFIG's mode_names, VERDICT_UNKNOWN
    margin: float
    push: FloatArray  # (6,) suggested push on the part
    ndof: int


class ProtocolError(ValueError):
    """A datagram that is not a valid message (counted and dropped by the receiver)."""


def _pad(x: Any, ndof: int) -> list[float]:
    a = [float(v) for v in np.asarray(x, dtype=float).reshape(-1)[:ndof]]
    return a + [0.0] * (6 - len(a))


def encode_hello(token: str | None = None) -> bytes:
    """A HELLO datagram (with the token, when the bridge needs one)."""
    return _HEADER.pack(MAGIC, HELLO) + (token or "").encode()


def hello_token(data: bytes) -> str:
    """The token a HELLO carries ('' for none)."""
    return data[_HEADER.size :].decode("utf-8", errors="replace")


def encode_config(config: dict[str, Any]) -> bytes:
    """A CONFIG datagram carrying ``config`` as JSON."""
    return _HEADER.pack(MAGIC, CONFIG) + json.dumps(config).encode()


def message_type(data: bytes) -> int:
    """The type of a datagram, or :class:`ProtocolError` when its header is not fixplan's."""
    if len(data) < _HEADER.size or data[:4] != MAGIC:
        raise ProtocolError(f"not a fixplan bridge datagram ({len(data)} bytes, expected magic {MAGIC!r})")
    return data[4]


def decode_config(data: bytes) -> dict[str, Any]:
    """The JSON of a CONFIG datagram, or :class:`ProtocolError`."""
    if message_type(data) != CONFIG:
        raise ProtocolError("expected a CONFIG message")
    try:
        out = json.loads(data[_HEADER.size :].decode())
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ProtocolError(f"CONFIG is not JSON: {exc}") from None
    if not isinstance(out, dict):
        raise ProtocolError("CONFIG is not a JSON object")
    return out


def encode_pose(seq: int, t_device_s: float, pose: Any, twist: Any, ndof: int) -> bytes:
    """A POSE datagram (``pose`` and ``twist`` padded to 6)."""
    return _POSE.pack(MAGIC, POSE, ndof, 0, seq & 0xFFFFFFFF, t_device_s, *_pad(pose, ndof), *_pad(twist, ndof))


def decode_pose(data: bytes, ndof: int) -> PosePacket:
    """A POSE datagram for a scene with ``ndof`` coordinates, or :class:`ProtocolError`."""
    if len(data) != POSE_SIZE:
        raise ProtocolError(f"POSE is {POSE_SIZE} bytes, got {len(data)}")
    magic, kind, n, _flags, seq, t, *rest = _POSE.unpack(data)
    if magic != MAGIC or kind != POSE:
        raise ProtocolError("not a POSE datagram")
    if n != ndof:
        raise ProtocolError(f"POSE has ndof {n}, the scene has {ndof}")
    values = np.array(rest, dtype=float)
    if not (math.isfinite(t) and np.all(np.isfinite(values))):
        raise ProtocolError("POSE has non-finite numbers")
    return PosePacket(int(seq), float(t), values[:6], values[6:], n)


def encode_force(p: ForcePacket) -> bytes:
    """A FORCE datagram."""
    n = p.ndof
    return _FORCE.pack(
        MAGIC, FORCE, n, p.flags, p.seq & 0xFFFFFFFF, p.echo_seq & 0xFFFFFFFF, p.t_echo_s, p.t_session_s,
        *_pad(p.felt, n), *_pad(p.part_pose, n), *_pad(p.part_twist, n),
        max(-1, min(127, p.target)), min(255, max(0, p.transition)), p.verdict,
        p.margin if math.isfinite(p.margin) else float("nan"), *_pad(p.push, n),
    )  # fmt: skip


def decode_force(data: bytes) -> ForcePacket:
    """A FORCE datagram, or :class:`ProtocolError`."""
    if len(data) != FORCE_SIZE:
        raise ProtocolError(f"FORCE is {FORCE_SIZE} bytes, got {len(data)}")
    v = _FORCE.unpack(data)
    if v[0] != MAGIC or v[1] != FORCE:
        raise ProtocolError("not a FORCE datagram")
    n = int(v[2])
    a = np.array(v[8:26], dtype=float)
    return ForcePacket(
        seq=int(v[4]), echo_seq=int(v[5]), t_echo_s=float(v[6]), t_session_s=float(v[7]), flags=int(v[3]),
        felt=a[0:6], part_pose=a[6:12], part_twist=a[12:18], target=int(v[26]), transition=int(v[27]),
        verdict=int(v[28]), margin=float(v[29]), push=np.array(v[30:36], dtype=float), ndof=n,
    )  # fmt: skip
