"""A node with use_sim_time follows /clock: its timers fire on sim time, now() is the last /clock."""
from __future__ import annotations

import os
import threading

import pytest

import roszen
from roszen.testing import python_cmd, read_until, spawn, stop

PEER = os.path.join(os.path.dirname(__file__), "peer.py")
pytestmark = pytest.mark.graph


def test_timer_follows_clock_in_another_process(router_env):
    p = spawn(python_cmd(PEER, "simtime", "--ros-args", "-p", "use_sim_time:=true"), router_env)
    ctx = roszen.Context()
    try:
        assert read_until(p, "READY")[-1] == "READY True"
        node = roszen.Node("clock_source", context=ctx)
        pub = node.create_publisher("rosgraph_msgs/msg/Clock", "/clock", roszen.CLOCK)
        assert ctx.graph.wait_for(lambda: pub.get_subscription_count() > 0, 10)
        C = roszen.message_class("rosgraph_msgs/msg/Clock")
        published = set()
        stop_ev = threading.Event()

        def pump():
            t = 100_000_000_000  # sim time starts at 100 s, advances 0.1 s per message
            while not stop_ev.is_set():
                m = C()
                m.clock.sec, m.clock.nanosec = divmod(t, 1_000_000_000)
                published.add(t)
                pub.publish(m)
                t += 100_000_000
                stop_ev.wait(0.01)
        th = threading.Thread(target=pump, daemon=True)
        th.start()
        try:
            lines = read_until(p, "TICK", timeout=10)
            lines += read_until(p, "TICK", timeout=10)
            lines += read_until(p, "TICK", timeout=10)
        finally:
            stop_ev.set()
            th.join(5)
        ticks = [int(ln.split()[1]) for ln in lines if ln.startswith("TICK")]
        assert len(ticks) == 3
        assert all(t in published for t in ticks)        # now() is exactly a /clock value
        assert ticks == sorted(ticks) and ticks[0] >= 100_000_000_000
        # one tick per 0.5 s period of SIM time (wall time per period is ~50 ms here)
        assert len({t // 500_000_000 for t in ticks}) == 3
    finally:
        stop(p)
        ctx.shutdown()


def test_clock_wall_time_by_default(router_env):
    node = roszen.Node("wall_clock")
    try:
        import time
        t = node.get_clock().now().nanoseconds
        assert abs(t - time.time_ns()) < 5_000_000_000
        assert not node.get_clock().ros_time_is_active
        msg = node.get_clock().now().to_msg()
        assert msg.sec > 1_600_000_000
    finally:
        node.destroy_node()
