"""A network bridge for haptic devices: a driver process (any language, this machine or another) sends
the hand's pose over UDP and gets the rendered force back.

No de-facto network protocol carries force feedback (OpenIGTLink carries poses but no force, VRPN's
force device is legacy, ROS 2 is not pip-installable), so the bridge defines one small versioned
message each way, a fixed little-endian binary layout (Python's ``struct``; never pickle, JSON or
``eval``):

| message | layout (``<`` little-endian) | bytes | fields |
|---|---|---|---|
| pose (device -> softenv) | ``4s H I d 4d`` | 50 | magic ``b"SEVP"``, version 1, sequence number (u32), device time (s, f64), hand x, z (m), pitch (rad), y (m): relative to the device's start pose, as a hand log's columns |
| force (softenv -> device) | ``4s H I d 3d`` | 42 | magic ``b"SEVF"``, version 1, the sequence number of the pose it answers, softenv's time (s), the force to render on the hand: x, y, z (N) |

The server (:class:`BridgeServer`, in the session's process) listens on ``127.0.0.1`` unless an
address is given explicitly, and pairs with the first sender of a valid pose: a datagram from any other
address is counted (``foreign``) and dropped. A datagram of the wrong size, magic or version is counted
``garbled``; a pose that is not finite or lies outside the hand's workspace, ``out_of_range``; one whose
sequence number is not above the last accepted (reordered or repeated: UDP keeps no order), ``late``.
Each is skipped, never raised; the counts are in :attr:`BridgeServer.counts` and the session's log.
:class:`BridgeClient` is the reference client (the device side); its ``send_pose`` and ``receive_force``
are the whole protocol.
"""

from __future__ import annotations

import math
import select
import socket
import struct
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._validation import check_int

PROTOCOL_VERSION = 1
POSE = struct.Struct("<4sHId4d")
FORCE = struct.Struct("<4sHId3d")
POSE_MAGIC, FORCE_MAGIC = b"SEVP", b"SEVF"
LOOPBACK = "127.0.0.1"
COUNTS = ("accepted", "garbled", "out_of_range", "late", "foreign")


@dataclass
class Pose:
    """One accepted pose: its sequence number, the device's time (s), and x, z, pitch, y."""

    seq: int
    time_s: float
    pose: np.ndarray


def encode_pose(seq: int, time_s: float, pose: Any) -> bytes:
    """A pose message (the device's side of the protocol)."""
    x, z, pitch, y = (float(v) for v in pose)
    return POSE.pack(POSE_MAGIC, PROTOCOL_VERSION, seq, float(time_s), x, z, pitch, y)


def encode_force(seq: int, time_s: float, force: Any) -> bytes:
    """A force message answering pose ``seq``."""
    fx, fy, fz = (float(v) for v in force)
    return FORCE.pack(FORCE_MAGIC, PROTOCOL_VERSION, seq, float(time_s), fx, fy, fz)


def decode(data: bytes, layout: struct.Struct, magic: bytes) -> tuple[Any, ...] | None:
    """The fields after magic and version, or None for a datagram of another size, magic or version."""
    if len(data) != layout.size:
        return None
    fields = layout.unpack(data)
    if fields[0] != magic or fields[1] != PROTOCOL_VERSION:
        return None
    return fields[2:]


class BridgeServer:
    """softenv's end of the bridge: non-blocking, polled once per control period.

    ``limits``: the hand's workspace, ``((low x, z, pitch, y), (high ...))`` relative to the start pose
    (:func:`softenv.training.hand.relative_box`); a pose outside it is counted and skipped.
    ``host``: the address to listen on, ``127.0.0.1`` unless given (another address lets other machines
    in: give it on purpose); ``port`` 0 picks a free one (:attr:`address` says which).
    """

    def __init__(self, limits: tuple[Any, Any], host: str = LOOPBACK, port: int = 0) -> None:
        check_int(port, "port", 0, 65535)
        low, high = (np.asarray(v, dtype=np.float64) for v in limits)
        if low.shape != (4,) or high.shape != (4,) or not np.all(low <= high):
            raise ValueError(f"limits={limits!r} must be two sequences of 4 numbers, low <= high")
        self._low, self._high = low, high
        self.counts = dict.fromkeys(COUNTS, 0)
        self.peer: tuple[str, int] | None = None
        self.last_seq = -1
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.sock.bind((host, port))
        except OSError:
            self.sock.close()
            raise
        self.sock.setblocking(False)

    @property
    def address(self) -> tuple[str, int]:
        return self.sock.getsockname()

    def poll(self, wait_s: float = 0.0) -> Pose | None:
        """Read every waiting datagram (first waiting up to ``wait_s`` for one); the newest acceptable
        pose, or None if none came."""
        if wait_s > 0.0:
            select.select([self.sock], [], [], wait_s)
        newest = None
        while True:
            try:
                data, sender = self.sock.recvfrom(2048)
            except (BlockingIOError, InterruptedError):
                return newest
            except OSError:                       # e.g. an ICMP error from a peer that went away
                continue
            pose = self._accept(data, sender)
            if pose is not None:
                newest = pose

    def _accept(self, data: bytes, sender: tuple[str, int]) -> Pose | None:
        if self.peer is not None and sender != self.peer:
            self.counts["foreign"] += 1
            return None
        fields = decode(data, POSE, POSE_MAGIC)
        if fields is None:
            self.counts["garbled"] += 1
            return None
        seq, time_s, *values = fields
        pose = np.array(values)
        if not (math.isfinite(time_s) and np.all(np.isfinite(pose)) and np.all(pose >= self._low)
                and np.all(pose <= self._high)):
            self.counts["out_of_range"] += 1
            return None
        if seq <= self.last_seq:
            self.counts["late"] += 1
            return None
        self.peer = self.peer or sender           # the first valid pose pairs the session with its device
        self.last_seq = seq
        self.counts["accepted"] += 1
        return Pose(seq, time_s, pose)

    def send_force(self, seq: int, time_s: float, force: Any) -> None:
        """The force to render, to the paired device (nothing before one has paired)."""
        if self.peer is not None:
            try:
                self.sock.sendto(encode_force(seq, time_s, force), self.peer)
            except OSError:                       # a full buffer or a vanished peer: the next period tries again
                pass

    def close(self) -> None:
        self.sock.close()


class BridgeClient:
    """The reference client, the device's side: send poses, receive forces (blocking up to ``timeout_s``)."""

    def __init__(self, server: tuple[str, int], timeout_s: float = 1.0) -> None:
        self.server = server
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((LOOPBACK if server[0] == LOOPBACK else "", 0))
        self.sock.settimeout(timeout_s)

    def send_pose(self, seq: int, time_s: float, pose: Any) -> None:
        self.sock.sendto(encode_pose(seq, time_s, pose), self.server)

    def receive_force(self) -> tuple[int, float, np.ndarray] | None:
        """The next force message (its pose's sequence number, softenv's time, the force), or None at the
        timeout or for a datagram that is not one."""
        try:
            data, _ = self.sock.recvfrom(2048)
        except (TimeoutError, socket.timeout):
            return None
        fields = decode(data, FORCE, FORCE_MAGIC)
        if fields is None:
            return None
        seq, time_s, *force = fields
        return seq, time_s, np.array(force)

    def close(self) -> None:
        self.sock.close()
