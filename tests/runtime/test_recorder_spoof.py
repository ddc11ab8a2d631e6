"""A liveliness token advertising a known topic with another type must not stop the bag
recorder from recording the real publisher."""
from __future__ import annotations

import threading
import time

import pytest
import yaml

import roszen
from roszen import testing, wire
from roszen.bag.recorder import Recorder
from roszen.bag.writer import BagWriter

pytestmark = pytest.mark.graph
POSE = "geometry_msgs/msg/PoseStamped"


def test_spoofed_type_tokens_do_not_hide_the_real_publisher(router_env, tmp_path, capsys):
    spoof_ctx, real_ctx, rec_ctx = roszen.Context(), roszen.Context(), roszen.Context()
    stop_pub, stop_rec = threading.Event(), threading.Event()
    threads: list = []
    try:
        # 1) a node advertising /truth/pose as std_msgs/String (a valid String token, no data)
        spoof = roszen.Node("spoofer", context=spoof_ctx)
        spoof.create_publisher("std_msgs/msg/String", "/truth/pose", 10)
        # 2) a bare token claiming PoseStamped with a hash that is not PoseStamped's
        sup = roszen.codec.msg_support(POSE)
        bogus = wire.endpoint_token(spoof_ctx.domain_id, spoof_ctx.zid, spoof._nid, 999, wire.PUB, "/", "/",
                                    "spoofer", "/truth/pose", sup.dds_name, "RIHS01_" + "ab" * 32,
                                    roszen.QoSProfile(depth=10))
        bogus_token = spoof_ctx.session.liveliness().declare_token(bogus)  # noqa: F841 (kept alive)
        # 3) the real publisher, publishing until the end of the test
        real = roszen.Node("truth", context=real_ctx)
        pub = real.create_publisher(POSE, "/truth/pose", 10)
        msg = roszen.message_class(POSE)()
        msg.header.frame_id = "world"

        def publish() -> None:
            while not stop_pub.is_set():
                pub.publish(msg)
                time.sleep(0.02)
        threads.append(threading.Thread(target=publish, daemon=True))
        threads[-1].start()

        node = roszen.Node("recorder", context=rec_ctx, start_parameter_services=False,
                           enable_rosout=False)
        assert rec_ctx.graph.wait_for(
            lambda: len(node.get_publishers_info_by_topic("/truth/pose")) >= 3, 20)
        writer = BagWriter(tmp_path / "bag")
        recorder = Recorder(node, writer)
        threads.append(threading.Thread(target=recorder.spin, args=(stop_rec,), daemon=True))
        threads[-1].start()
        assert testing.wait_until(lambda: recorder.received >= 5, 20.0), "nothing recorded from the real publisher"
        stop_rec.set()
        threads[-1].join(20)
        recorder.close()
        writer.close()
        meta = yaml.safe_load((tmp_path / "bag" / "metadata.yaml").read_text())
        topics = {t["topic_metadata"]["name"]: t for t in
                  meta["rosbag2_bagfile_information"]["topics_with_message_count"]}
        assert topics["/truth/pose"]["topic_metadata"]["type"] == POSE
        assert topics["/truth/pose"]["message_count"] >= 5
        err = capsys.readouterr().err
        assert "which is not that type's hash" in err          # the bogus-hash token, named
        assert "no message came as std_msgs/msg/String" in err  # the String claim, named
    finally:
        stop_pub.set()
        stop_rec.set()
        for t in threads:
            t.join(5)
        for ctx in (spoof_ctx, real_ctx, rec_ctx):
            ctx.shutdown()
