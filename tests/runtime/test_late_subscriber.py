"""A late-joining `topic echo` gets its first message (the interop check's miss).

The graph cache declares its liveliness subscriber (with history) before its liveliness query,
so a token declared at any moment reaches it by one of the two. The window found is in `topic
echo`: with no publisher seen within --discovery-timeout it subscribed blind (volatile) and
never adapted, so a latched publisher whose token showed up later was never asked for its
history: a one-shot latched sample never arrived, while the next run (token seen, transient
local) got it at once. It now adapts once the publishers show up. The rounds against
zenoh-ros2-sdk start the two at random offsets; each must receive within a bounded time."""
from __future__ import annotations

import random
import subprocess
import sys
import time
import os

import pytest

import roszen
from roszen import cli
from roszen.node import Node
from roszen.testing import python_cmd, read_until, spawn, stop

SDK = os.path.join(os.path.dirname(__file__), "sdk_peer.py")
pytestmark = pytest.mark.graph
ROUNDS = 8


def test_echo_adapts_when_a_latched_publisher_is_seen_late(router_env, monkeypatch, capsys):
    """The discovery race made certain: the latched sample is published before the echo starts,
    and the echo's view of the topic's publishers lags 1 s behind its 0.3 s discovery wait."""
    ctx = roszen.Context()
    try:
        talker = roszen.Node("late_latched_talker", context=ctx)
        pub = talker.create_publisher("std_msgs/msg/String", "/late_latched", roszen.LATCHED)
        msg = roszen.message_class("std_msgs/msg/String")()
        msg.data = "latched once"
        pub.publish(msg)
        real = Node.get_publishers_info_by_topic
        seen_from = time.monotonic() + 1.3

        def lagging(self, topic):
            return real(self, topic) if time.monotonic() >= seen_from else []
        monkeypatch.setattr(Node, "get_publishers_info_by_topic", lagging)
        code = cli.main(["topic", "echo", "--once", "/late_latched", "std_msgs/msg/String",
                         "--discovery-timeout", "0.3", "--timeout", "10"])
        out, err = capsys.readouterr()
        assert code == 0, err
        assert "data: latched once" in out
    finally:
        ctx.shutdown()


def test_echo_receives_from_an_sdk_publisher_started_at_any_offset(router_env):
    """ROUNDS rounds: zenoh-ros2-sdk's publisher and `topic echo --once` (type discovered from
    the graph) started -1..2 s apart; every echo prints a message within 20 s."""
    pytest.importorskip("zenoh_ros2_sdk")
    rnd = random.Random(27)
    missed = []
    for i in range(ROUNDS):
        topic = f"/late_{i}"
        echo_cmd = [sys.executable, "-m", "roszen.cli", "topic", "echo", "--once", topic,
                    "--timeout", "20", "--discovery-timeout", "10"]
        offset = rnd.uniform(-1.0, 2.0)
        procs = []
        try:
            if offset < 0:
                procs.append(spawn(echo_cmd, router_env))
                time.sleep(-offset)
                procs.append(spawn(python_cmd(SDK, "pub", topic), router_env))
            else:
                procs.append(spawn(python_cmd(SDK, "pub", topic), router_env))
                time.sleep(offset)
                procs.append(spawn(echo_cmd, router_env))
            echo = procs[0] if offset < 0 else procs[1]
            try:
                out, err = echo.communicate(timeout=40)
            except subprocess.TimeoutExpired:
                out, err = "", "no exit in 40 s"
            if "data: sdk-" not in out:
                missed.append((i, round(offset, 2), err.strip()[-200:]))
        finally:
            for p in procs:
                stop(p)
    assert not missed, missed


def test_sdk_peer_starts(router_env):
    """The peer the rounds use comes up (a failure here is the SDK, not discovery)."""
    pytest.importorskip("zenoh_ros2_sdk")
    p = spawn(python_cmd(SDK, "pub", "/late_probe"), router_env)
    try:
        read_until(p, "READY", timeout=20)
    finally:
        stop(p)
