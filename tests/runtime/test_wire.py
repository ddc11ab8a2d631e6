"""rmw_zenoh wire details: key expressions, tokens, GIDs, attachments, QoS strings, names."""
from __future__ import annotations

import pytest
import xxhash
import zenoh.ext as zext

import roszen
from roszen import wire
from roszen.names import InvalidNameError, apply_remap, expand_name, normalize_namespace
from roszen.qos import LATCHED, Durability, History, QoSProfile, Reliability
from roszen.zconfig import ConfigError, domain_id, parse_override, session_config

STRING_HASH = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"


def test_topic_keyexpr():
    assert wire.topic_keyexpr(0, "/chatter", wire.ros_to_dds_type("std_msgs/msg/String"), STRING_HASH) == \
        f"0/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}"
    assert wire.ros_to_dds_type("example_interfaces/srv/AddTwoInts") == "example_interfaces::srv::dds_::AddTwoInts_"
    assert wire.dds_to_ros_type("geometry_msgs::msg::dds_::PoseStamped_") == "geometry_msgs/msg/PoseStamped"


def test_qos_strings():
    assert QoSProfile(depth=10).to_token() == "::,10:,:,:,,"
    assert LATCHED.to_token() == ":1:,1:,:,:,,"
    assert QoSProfile(depth=42).to_token() == "::,:,:,:,,"
    assert QoSProfile(depth=5, reliability=Reliability.BEST_EFFORT).to_token() == "2::,5:,:,:,,"
    assert QoSProfile(depth=3, history=History.KEEP_ALL).to_token() == "::2,3:,:,:,,"
    assert QoSProfile(depth=1, deadline=1.5).to_token() == "::,1:1,500000000:,:,,"
    q = QoSProfile(depth=7, reliability=Reliability.BEST_EFFORT, durability=Durability.TRANSIENT_LOCAL)
    assert QoSProfile.from_token(q.to_token()) == q


def test_tokens_and_gid():
    tok = wire.endpoint_token(3, "abc123", 0, 4, wire.PUB, "/", "/ns/sub", "talker", "/ns/sub/chatter",
                              "std_msgs::msg::dds_::String_", STRING_HASH, QoSProfile(depth=10))
    assert tok == ("@ros2_lv/3/abc123/0/4/MP/%/%ns%sub/talker/%ns%sub%chatter/std_msgs::msg::dds_::String_/"
                   f"{STRING_HASH}/::,10:,:,:,,")
    assert wire.node_token(0, "abc", 2, "/", "/", "n") == "@ros2_lv/0/abc/2/2/NN/%/%/n"
    e = wire.parse_token(tok)
    assert (e.kind, e.namespace, e.node_name, e.name, e.ros_type, e.qos.depth) == \
        (wire.PUB, "/ns/sub", "talker", "/ns/sub/chatter", "std_msgs/msg/String", 10)
    h = xxhash.xxh3_128_intdigest(tok.encode())
    low, high = h & (2**64 - 1), h >> 64
    assert wire.gid_of(tok) == low.to_bytes(8, "little") + high.to_bytes(8, "little")
    with pytest.raises(ValueError):
        wire.parse_token("@ros2_lv/0/abc")


def test_attachment_layout_is_zenoh_serialization():
    gid = bytes(range(16))
    att = wire.make_attachment(1, gid, 1_700_000_000_123_456_789)
    assert len(att) == 33 and att[16] == 0x10
    assert att == zext.z_serialize((zext.Int64(1), zext.Int64(1_700_000_000_123_456_789), gid)).to_bytes()
    a = wire.parse_attachment(att)
    assert (a.sequence_number, a.source_timestamp, a.gid) == (1, 1_700_000_000_123_456_789, gid)
    with pytest.raises(ValueError):
        wire.parse_attachment(att[:20])


def test_names():
    assert normalize_namespace("") == "/" and normalize_namespace("a/b/") == "/a/b"
    assert expand_name("chatter", "n", "/ns") == "/ns/chatter"
    assert expand_name("/abs", "n", "/ns") == "/abs"
    assert expand_name("~/priv", "n", "/ns") == "/ns/n/priv"
    assert expand_name("~", "n", "/") == "/n"
    for bad in ("", "a//b", "1abc", "a/", "a b"):
        with pytest.raises(InvalidNameError):
            expand_name(bad, "n", "/")
    assert apply_remap("/ns/chatter", {"chatter": "/talk"}, "n", "/ns") == "/talk"
    assert apply_remap("/ns/other", {"chatter": "/talk"}, "n", "/ns") == "/ns/other"
    with pytest.raises(InvalidNameError):
        roszen.Node("bad-name")


def test_env_config():
    assert domain_id({}) == 0 and domain_id({"ROS_DOMAIN_ID": "7"}) == 7
    with pytest.raises(ConfigError):
        domain_id({"ROS_DOMAIN_ID": "x"})
    assert parse_override('connect/endpoints=["tcp/127.0.0.1:1"];mode="peer"') == \
        [("connect/endpoints", '["tcp/127.0.0.1:1"]'), ("mode", '"peer"')]
    with pytest.raises(ConfigError):
        parse_override("novalue")
    cfg = session_config({"ZENOH_CONFIG_OVERRIDE": 'connect/endpoints=["tcp/127.0.0.1:9"]'})
    assert "127.0.0.1:9" in cfg.get_json("connect/endpoints")
    assert cfg.get_json("scouting/multicast/enabled") == "false"
    with pytest.raises(ConfigError):
        session_config({"ZENOH_SESSION_CONFIG_URI": "/nonexistent.json5"})
