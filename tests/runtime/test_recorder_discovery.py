"""The bag recorder never loses a topic that appears while it is looking at the graph (a CI
run's recorder missed every sim topic for 89 s: it cleared the graph-change event after its
first look, so a publisher announced during that look went unseen until the next change)."""
from __future__ import annotations

import threading
import time

import pytest

import roszen
from roszen import testing
from roszen.bag import recorder as recorder_mod
from roszen.bag.recorder import Recorder
from roszen.bag.writer import BagWriter

pytestmark = pytest.mark.graph
POSE = "geometry_msgs/msg/PoseStamped"


@pytest.mark.parametrize("safety_net", [False, True], ids=["events_only", "periodic_look"])
def test_a_publisher_announced_during_the_first_look_is_recorded(router_env, tmp_path,
                                                                 monkeypatch, safety_net):
    if not safety_net:      # the graph-change event alone must carry it
        monkeypatch.setattr(recorder_mod, "REDISCOVER_PERIOD", 1e9)
    pub_ctx, rec_ctx = roszen.Context(), roszen.Context()
    stop_pub, stop_rec = threading.Event(), threading.Event()
    threads: list = []
    try:
        node = roszen.Node("recorder", context=rec_ctx, start_parameter_services=False,
                           enable_rosout=False)
        writer = BagWriter(tmp_path / "bag")
        recorder = Recorder(node, writer)
        talker = roszen.Node("talker", context=pub_ctx)
        msg = roszen.message_class(POSE)()
        pubs: list = []
        look = recorder.discover

        def first_look_then_a_publisher() -> None:
            look()
            if not pubs:            # the publisher comes while the recorder is in its look
                pubs.append(talker.create_publisher(POSE, "/late/pose", 10))
                assert rec_ctx.graph.wait_for(
                    lambda: node.count_publishers("/late/pose") > 0, 10)
                if safety_net:      # and the event is lost: only the periodic look finds it
                    recorder._changed.clear()
        recorder.discover = first_look_then_a_publisher

        def publish() -> None:
            while not stop_pub.is_set():
                if pubs:
                    pubs[0].publish(msg)
                time.sleep(0.02)
        threads.append(threading.Thread(target=publish, daemon=True))
        threads.append(threading.Thread(target=recorder.spin, args=(stop_rec,), daemon=True))
        for t in threads:
            t.start()
        assert testing.wait_until(lambda: recorder.received >= 3, 15.0), \
            f"the late topic was not recorded (subscriptions: {sorted(recorder.subscriptions)})"
        assert "/late/pose" in recorder.subscriptions
        stop_rec.set()
        threads[-1].join(10)
        recorder.close()
        writer.close()
    finally:
        stop_pub.set()
        stop_rec.set()
        for t in threads:
            t.join(5)
        for ctx in (pub_ctx, rec_ctx):
            ctx.shutdown()
