"""One /clock per graph: a stray second /clock publisher (alternating 1e9 s and 1 s, the attack
that once grew a bag's time by 1e9 s per step until its writer failed) is ignored, logged once,
by a sim-time recording and by a node's sim clock; a step back of the real clock is a reset,
logged, and the bag's time continues."""
from __future__ import annotations

import time

import pytest

roszen = pytest.importorskip("roszen")
from roszen import testing  # noqa: E402
from roszen.bag.reader import BagReader  # noqa: E402
from roszen.bag.recorder import Recorder  # noqa: E402
from roszen.bag.writer import BagWriter  # noqa: E402
from roszen.qos import CLOCK, QoSProfile  # noqa: E402

pytestmark = pytest.mark.graph


def _clock(pub, sec: int) -> None:
    msg = roszen.message_class("rosgraph_msgs/msg/Clock")()
    msg.clock.sec = sec
    pub.publish(msg)


def test_stray_clock_is_ignored_by_recorder_and_nodes(tmp_path, capfd):
    with testing.router() as port:
        env = testing.zenoh_env(port)
        ctxs = [roszen.Context(env=env) for _ in range(4)]
        try:
            sim = roszen.Node("sim", context=ctxs[0])
            stray = roszen.Node("stray", context=ctxs[1])
            listener = roszen.Node("listener", context=ctxs[2])
            listener.set_parameters([roszen.Parameter("use_sim_time", value=True)])
            rec_node = roszen.Node("recorder", context=ctxs[3])
            clock_pub = sim.create_publisher("rosgraph_msgs/msg/Clock", "/clock", CLOCK)
            tick_pub = sim.create_publisher("std_msgs/msg/Int32", "/tick", QoSProfile(depth=100))
            writer = BagWriter(tmp_path / "bag")
            rec = Recorder(rec_node, writer, topics=["/tick"], use_sim_time=True)
            rec.discover()
            assert testing.wait_until(lambda: (rec.discover() or True) and "/tick" in rec.subscriptions, 10)
            # the real clock first (until both clients heard it: the first publisher heard is
            # the clock), then the stray one interleaved with it
            def heard() -> bool:
                _clock(clock_pub, 1)
                listener.spin_once(timeout_sec=0.05)
                return (listener.get_clock().now_ns() == 1_000_000_000
                        and rec.sim.last == 1_000_000_000)
            assert testing.wait_until(heard, 10, period=0.05)
            stray_pub = stray.create_publisher("rosgraph_msgs/msg/Clock", "/clock", CLOCK)
            assert testing.wait_until(lambda: len(rec_node.get_publishers_info_by_topic("/clock")) == 2, 10)
            tick = roszen.message_class("std_msgs/msg/Int32")()
            for k in range(2, 12):
                _clock(stray_pub, 1_000_000_000 if k % 2 else 1)
                _clock(clock_pub, k)
                tick.data = k
                tick_pub.publish(tick)
                time.sleep(0.02)
                listener.spin_once(timeout_sec=0.01)
                rec_node.spin_once(timeout_sec=0.01)
            assert testing.wait_until(lambda: (rec_node.spin_once(timeout_sec=0.01) or True)
                                      and rec.received >= 10, 10)
            # a step back of the real clock is a reset: logged, the bag's time continues
            _clock(clock_pub, 0)
            tick.data = 99
            time.sleep(0.05)
            tick_pub.publish(tick)
            assert testing.wait_until(lambda: (rec_node.spin_once(timeout_sec=0.01) or True)
                                      and rec.received >= 11, 10)
            testing.spin_until(listener, lambda: False, 0.3)
            assert listener.get_clock().now_ns() == 0          # it follows the real clock only
            assert rec.sim.resets == 1
            rec.close()
            writer.close()
        finally:
            for c in ctxs:
                c.shutdown()
    stamps = [m.log_time_ns for m in BagReader(tmp_path / "bag").messages(["/tick"])]
    assert len(stamps) == 11
    assert stamps == sorted(stamps)
    assert stamps[-1] <= 12_000_000_000          # never the stray's 1e9 s
    assert stamps[-1] >= 11_000_000_000          # the reset continued from the last stamp
    err = capfd.readouterr().err
    assert err.count("ignoring /clock from publisher") == 2   # once by the recorder, once by the node
    assert "(a sim reset)" in err
