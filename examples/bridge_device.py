"""A simulated haptic device on softenv's UDP bridge: the reference client's whole use.

Start a session that waits for a device (``softenv play --bridge 9870``), then, in another process,
on this machine or another:

    python examples/bridge_device.py 127.0.0.1:9870 softenv/training/examples/device_logs/expert.csv

It sends the log's poses (relative to its first row; x, z, pitch, y) one control period apart and
prints the forces the session renders back. ``--lockstep`` waits for each pose's answer before the
next (a session run with ``realtime=False``); otherwise it paces itself by the log's clock, as a
device streaming its pose would. A driver in another language sends the same 50-byte message
(``softenv.haptics.bridge``'s table) and reads the same 42-byte answer.
"""

from __future__ import annotations

import argparse
import time

from softenv.haptics.bridge import BridgeClient
from softenv.training.logs import HAND_LOG, read_log


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("server", help="HOST:PORT of the session's bridge")
    parser.add_argument("log", help="a hand-pose log to play (CSV or NPZ)")
    parser.add_argument("--lockstep", action="store_true", help="wait for each pose's force before the next")
    args = parser.parse_args()
    host, _, port = args.server.rpartition(":")
    _, table = read_log(args.log, HAND_LOG)
    table[:, 1:] -= table[0, 1:]
    client = BridgeClient((host or "127.0.0.1", int(port)), timeout_s=2.0)
    started, answered = time.perf_counter(), 0
    for seq, (t, *pose) in enumerate(table[1:], start=1):
        if not args.lockstep:
            time.sleep(max(0.0, started + t - table[0, 0] - time.perf_counter()))
        client.send_pose(seq, t - table[0, 0], pose)
        if args.lockstep:
            reply = client.receive_force()
            while reply is not None and reply[0] < seq:          # a stale answer: read on
                reply = client.receive_force()
            if reply is None:
                raise SystemExit(f"no answer to pose {seq}: is a session waiting on {args.server}?")
            answered += 1
            print(f"pose {seq}: force {reply[2].round(2).tolist()} N")
    client.close()
    print(f"sent {len(table) - 1} poses" + (f", {answered} answered" if args.lockstep else ""))


if __name__ == "__main__":
    main()
