"""Benchmark of the haptic-device bridge on loopback: round-trip latency of a pose and its force, and
what was lost or garbled on the way (:mod:`softenv.haptics.bridge`)."""

from __future__ import annotations

import threading
import time

import numpy as np

from ..haptics.bridge import BridgeClient, BridgeServer
from .timing import Row, Timing

LIMITS = ((-1.0, -1.0, -1.0, -1.0), (1.0, 1.0, 1.0, 1.0))


def bench_bridge(quick: bool, reference: Timing) -> list[Row]:
    """A device (the reference client) sends poses one at a time and waits for each answer; the session
    side (a thread polling as ``softenv play --bridge`` does, without the physics) answers each at once.
    Both in this process, so the figure includes Python's own scheduling of the two threads."""
    messages = 2_000 if quick else 20_000
    server = BridgeServer(LIMITS)
    client = BridgeClient(server.address, timeout_s=0.1)
    done = threading.Event()

    def session() -> None:
        while not done.is_set():
            got = server.poll(0.05)
            if got is not None:
                server.send_force(got.seq, got.time_s, (0.0, 0.0, 1.0))

    answering = threading.Thread(target=session, daemon=True)
    answering.start()
    rtt, lost, mismatched = [], 0, 0
    try:
        for seq in range(1, messages + 1):
            sent = time.perf_counter()
            client.send_pose(seq, seq * 1e-3, (0.0, 0.0, 0.0, 0.0))
            reply = client.receive_force()
            if reply is None:
                lost += 1
                continue
            rtt.append(time.perf_counter() - sent)
            mismatched += reply[0] != seq
    finally:
        done.set()
        answering.join()
        client.close()
        server.close()
    us = np.array(rtt) * 1e6
    skipped = sum(v for k, v in server.counts.items() if k != "accepted")
    note = f"{messages:,} poses on 127.0.0.1, one at a time"
    return [
        Row("bridge", f"pose -> force round trip, median ({note})", float(np.median(us)), "us",
            f"IQR {np.percentile(us, 25):.0f}-{np.percentile(us, 75):.0f} us", "<= 1000 us (a 1 kHz loop)",
            bool(np.median(us) <= 1000)),
        Row("bridge", "pose -> force round trip, p99", float(np.percentile(us, 99)), "us",
            f"max {us.max():.0f} us", "<= 1000 us", bool(np.percentile(us, 99) <= 1000)),
        Row("bridge", "messages lost (no answer in 0.1 s) or answering another pose", float(lost + mismatched),
            "messages", f"of {messages:,}", "0", lost + mismatched == 0),
        Row("bridge", "messages counted garbled, out of range, late or foreign by the session", float(skipped),
            "messages", f"of {messages:,}", "0", skipped == 0),
    ]
