"""The UDP bridge a haptic device drives a session through: the protocol both ways, everything a
network can deliver (garbled, truncated, out-of-range, late, foreign) counted and skipped, and a
simulated device process driving a headless session on loopback."""

import math
import socket
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from softenv.training import play
from softenv.haptics.bridge import (COUNTS, FORCE, POSE, BridgeClient, BridgeServer, encode_force, encode_pose,
                                     decode, FORCE_MAGIC)
from softenv.training.logs import example_log, read_log
from softenv.training.scoring import score_file

ROOT = Path(__file__).resolve().parents[1]
LIMITS = ((-0.025, -0.035, -0.5, -0.03), (0.05, 0.04, 0.5, 0.03))


@pytest.fixture
def pair():
    server = BridgeServer(LIMITS)
    client = BridgeClient(server.address, timeout_s=1.0)
    yield server, client
    client.close()
    server.close()


def test_a_pose_goes_in_and_its_force_comes_back_bit_for_bit(pair):
    server, client = pair
    assert server.address[0] == "127.0.0.1"                      # nobody else is let in by default
    client.send_pose(7, 0.125, [0.01, -0.02, 0.3, 0.004])
    got = server.poll(1.0)
    assert got.seq == 7 and got.time_s == 0.125 and got.pose.tolist() == [0.01, -0.02, 0.3, 0.004]
    server.send_force(got.seq, 0.14, [1.5, -0.25, 3.0])
    seq, t, force = client.receive_force()
    assert (seq, t, force.tolist()) == (7, 0.14, [1.5, -0.25, 3.0])
    assert POSE.size == 50 and FORCE.size == 42 and server.counts == dict.fromkeys(COUNTS, 0) | {"accepted": 1}


def test_the_newest_pose_wins_and_late_or_repeated_ones_are_counted(pair):
    server, client = pair
    for seq in (1, 3, 2, 3):                                      # reordered and repeated, as UDP may deliver
        client.send_pose(seq, seq * 0.02, [0.0, 0.0, 0.0, 0.001 * seq])
    got = None
    while server.counts["accepted"] + server.counts["late"] < 4:
        got = server.poll(1.0) or got
    assert got.seq == 3 and server.counts["accepted"] == 2 and server.counts["late"] == 2


@pytest.mark.parametrize("pose", [[0.0, 0.0, 0.0, math.nan], [0.0, 0.0, math.inf, 0.0], [0.06, 0.0, 0.0, 0.0],
                                  [0.0, -0.04, 0.0, 0.0], [0.0, 0.0, 0.0, -0.031]])
def test_a_pose_not_finite_or_outside_the_workspace_is_counted_and_skipped(pair, pose):
    server, client = pair
    client.send_pose(1, 0.0, pose)
    client.send_pose(2, 0.02, [0.0, 0.0, 0.0, 0.0])
    got = server.poll(1.0)
    while got is None:
        got = server.poll(1.0)
    assert got.seq == 2 and server.counts["out_of_range"] == 1 and server.counts["accepted"] == 1
    assert server.peer is not None                               # pairing waits for a valid pose


def test_a_second_sender_is_counted_and_dropped(pair):
    server, client = pair
    client.send_pose(1, 0.0, [0.0] * 4)
    assert server.poll(1.0).seq == 1
    intruder = BridgeClient(server.address)
    intruder.send_pose(2, 0.0, [0.01, 0.0, 0.0, 0.0])
    client.send_pose(2, 0.02, [0.0, 0.0, 0.0, 0.002])
    got = None
    while server.counts["accepted"] + server.counts["foreign"] < 3:
        got = server.poll(1.0) or got
    intruder.close()
    assert got.pose[3] == 0.002 and server.counts["foreign"] == 1
    server.send_force(2, 0.04, [0.0, 0.0, 1.0])
    assert client.receive_force()[0] == 2                         # the answer goes to the paired device only


@settings(max_examples=300, deadline=None)
@given(datagrams=st.lists(st.one_of(st.binary(max_size=120),
                                    st.builds(lambda cut: encode_pose(1, 0.0, [0.0] * 4)[:cut], st.integers(0, 49)),
                                    st.builds(lambda b: b + encode_pose(1, 0.0, [0.0] * 4)[len(b):],
                                              st.binary(min_size=1, max_size=6))),
                          min_size=1, max_size=8))
def test_random_and_truncated_datagrams_never_crash_and_are_counted(datagrams):
    """Whatever arrives, poll returns; a datagram that is not exactly a version-1 pose is garbled."""
    server = BridgeServer(LIMITS)
    sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        for data in datagrams:
            sender.sendto(data, server.address)
        valid = encode_pose(5, 0.0, [0.0] * 4)
        sender.sendto(valid, server.address)
        garbled = sum(decode(d, POSE, b"SEVP") is None for d in datagrams)
        got = None
        while sum(server.counts.values()) < len(datagrams) + 1:
            got = server.poll(1.0) or got
        assert server.counts["garbled"] == garbled and got is not None and got.seq in (1, 5)
    finally:
        sender.close()
        server.close()


def test_the_command_line_refuses_a_bad_address_in_one_line(capsys):
    from softenv.cli import main

    for bad in ("70000", "host:port", "1.2.3.4:"):
        assert main(["play", "--headless", "--bridge", bad]) == 2
        err = capsys.readouterr().err
        assert len(err.strip().splitlines()) == 1 and "PORT or HOST:PORT" in err
    taken = BridgeServer(LIMITS)
    try:
        assert main(["play", "--headless", "--bridge", f"127.0.0.1:{taken.address[1]}", "--seconds", "0.1"]) == 2
        assert "cannot be listened on" in capsys.readouterr().err
    finally:
        taken.close()


def test_a_simulated_device_process_drives_a_session_that_scores_like_its_log(tmp_path):
    """The reference client in another process plays the expert's log in lockstep over loopback: the
    session follows it, the device gets a force for every pose, and the session's log scores as the
    expert's own log does."""
    play.headless()
    expert = example_log("device_logs/expert")
    _, table = read_log(expert)
    bridge = play.open_bridge()
    device = subprocess.Popen([sys.executable, str(ROOT / "examples" / "bridge_device.py"),
                               f"127.0.0.1:{bridge.address[1]}", str(expert), "--lockstep"],
                              cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    out = []
    reader = threading.Thread(target=lambda: out.append(device.communicate(timeout=120)[0]))
    reader.start()
    try:
        session = play.run(seconds=table[-1, 0], out_dir=tmp_path, realtime=False, echo=lambda s: None, bridge=bridge,
                           screens=False)
    finally:
        reader.join()
        bridge.close()
    assert device.returncode == 0, out
    steps = len(table) - 1
    assert f"sent {steps} poses, {steps} answered" in out[0]
    assert bridge.counts == dict.fromkeys(COUNTS, 0) | {"accepted": steps}
    log = next(tmp_path.glob("session_*.csv"))
    assert "accepted 250, garbled 0" in log.read_text().splitlines()[1]
    assert np.allclose(session.log[:, 1:], table[:, 1:] - table[0, 1:], atol=1e-6)    # the hand followed
    assert session.report["score"] == pytest.approx(score_file(expert)["score"], abs=0.05)


def test_force_messages_decode_only_as_force_messages():
    data = encode_force(3, 1.0, [1.0, 2.0, 3.0])
    assert decode(data, FORCE, FORCE_MAGIC) == (3, 1.0, 1.0, 2.0, 3.0)
    assert decode(data, POSE, b"SEVP") is None and decode(data[:-1], FORCE, FORCE_MAGIC) is None


def test_bench_measures_the_round_trip_and_counts_nothing_lost_on_loopback():
    from softenv.bench.bridge import bench_bridge

    median, p99, lost, skipped = bench_bridge(True, None)
    assert median.metric.startswith("pose -> force round trip, median") and p99.metric.endswith("p99")
    assert 0.0 < median.value <= p99.value and median.unit == "us"
    assert lost.value == 0.0 and skipped.value == 0.0 and lost.ok and skipped.ok
