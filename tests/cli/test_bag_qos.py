"""QoS bookkeeping of bags: rosbag2 v9 profile dicts round-trip, the recorder subscribes
compatibly with its publishers, the player republishes latched topics latched."""
from __future__ import annotations

import yaml

from roszen.bag.metadata import BagMetadata, TopicInfo, parse_qos, qos_to_dict, qos_yaml
from roszen.bag.player import publisher_qos
from roszen.bag.recorder import subscription_qos
from roszen.qos import LATCHED, SENSOR_DATA, Durability, History, QoSProfile, Reliability


def test_qos_dict_roundtrip_and_rosbag2_spelling():
    q = QoSProfile(depth=5, reliability=Reliability.BEST_EFFORT, deadline=0.5)
    d = qos_to_dict(q)
    assert d["reliability"] == "best_effort" and d["history"] == "keep_last"
    assert d["deadline"] == {"sec": 0, "nsec": 500_000_000}
    assert d["lifespan"] == {"sec": 9223372036, "nsec": 854775807}       # infinite
    assert parse_qos([d]) == [q]
    assert parse_qos(qos_yaml([q, LATCHED])) == [q, LATCHED]             # MCAP channel string
    # older integer enums (rosbag2 <= v8 strings) parse too
    assert parse_qos("- {history: 1, depth: 1, reliability: 1, durability: 1}")[0].durability \
        == Durability.TRANSIENT_LOCAL


def test_metadata_yaml_roundtrip():
    meta = BagMetadata(topics=[TopicInfo("/a", "std_msgs/msg/String", [LATCHED], "RIHS01_x", count=3)],
                       start_ns=5, duration_ns=7)
    back = BagMetadata.from_dict(yaml.safe_load(meta.to_yaml()))
    assert back.topics[0].offered_qos == [LATCHED] and back.message_count == 3
    assert back.version == 9 and back.storage_identifier == "mcap"


def test_recorder_subscription_qos_matches_publishers():
    assert subscription_qos([LATCHED]).durability == Durability.TRANSIENT_LOCAL
    assert subscription_qos([LATCHED, QoSProfile()]).durability == Durability.VOLATILE
    assert subscription_qos([SENSOR_DATA, QoSProfile()]).reliability == Reliability.BEST_EFFORT
    assert subscription_qos([QoSProfile()]).history == History.KEEP_ALL     # never drops


def test_player_keeps_latched_topics_latched():
    q = publisher_qos([LATCHED])
    assert q.durability == Durability.TRANSIENT_LOCAL and q.depth == 1
    assert publisher_qos([SENSOR_DATA]).reliability == Reliability.BEST_EFFORT
    assert publisher_qos([]).durability == Durability.VOLATILE
