"""Recording a live graph and playing it back, from a shell: the bag decodes with
mcap-ros2-support and rosbags, `bag play` into `topic echo` reproduces the messages in order
with the recorded timing, latched topics stay latched, bad input leaves nothing behind."""
from __future__ import annotations

import signal
import subprocess
import sys
import time

import pytest
import yaml

from conftest import ASTROBEE, HERE, graph_env

pytestmark = pytest.mark.graph


def _record(procs, env, out, *extra):
    rec = procs([ASTROBEE, "bag", "record", "-a", "-o", str(out), *extra], env=env)
    rec.wait_line("Recording...", stream="err")
    return rec


def test_record_play_roundtrip(procs, router, tmp_path):
    env = graph_env(router)
    adder = procs([sys.executable, str(HERE / "adder_node.py")], env=env)
    adder.wait_line("adder ready")
    bag = tmp_path / "bag"
    rec = _record(procs, env, bag)
    rec.wait_line("Subscribed to topic '/adder/count'", stream="err")
    # a topic that appears while recording is picked up
    pub = procs([ASTROBEE, "topic", "pub", "-r", "20", "/late", "geometry_msgs/msg/PoseStamped",
                 "{header: {frame_id: world}, pose: {position: {x: 1.5}}}"], env=env)
    rec.wait_line("Subscribed to topic '/late'", stream="err")
    time.sleep(2.0)
    pub.kill()
    adder.kill()
    rec.signal(signal.SIGINT)
    assert rec.wait(timeout=20) == 0

    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    topics = {t["topic_metadata"]["name"]: t for t in meta["topics_with_message_count"]}
    from roszen import typestore
    for name, type_name in (("/adder/count", "std_msgs/msg/Int32"),
                            ("/adder/mode", "std_msgs/msg/String"),
                            ("/late", "geometry_msgs/msg/PoseStamped")):
        t = topics[name]["topic_metadata"]
        assert t["type"] == type_name
        assert t["type_description_hash"] == typestore.type_hash(type_name)
    assert topics["/adder/mode"]["topic_metadata"]["offered_qos_profiles"][0]["durability"] \
        == "transient_local"
    assert topics["/adder/mode"]["message_count"] == 1
    n_count = topics["/adder/count"]["message_count"]
    assert n_count >= 15 and topics["/late"]["message_count"] >= 20

    # every message decodes with two independent readers
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    (mcap_file,) = bag.glob("*.mcap")
    with open(mcap_file, "rb") as f:
        decoded = list(make_reader(f, decoder_factories=[DecoderFactory()])
                       .iter_decoded_messages())
    assert len(decoded) == meta["message_count"]
    counts = [m.decoded_message.data for m in decoded if m.channel.topic == "/adder/count"]
    assert counts == list(range(counts[0], counts[0] + n_count))     # nothing lost
    late = [m.decoded_message for m in decoded if m.channel.topic == "/late"]
    assert late[0].header.frame_id == "world" and late[0].pose.position.x == 1.5
    from rosbags.highlevel import AnyReader
    with AnyReader([bag]) as reader:
        n = 0
        for conn, _, raw in reader.messages():
            reader.deserialize(raw, conn.msgtype)
            n += 1
    assert n == meta["message_count"]

    info = subprocess.run([ASTROBEE, "bag", "info", str(bag)], capture_output=True, text=True)
    assert f"Topic: /adder/count | Type: std_msgs/msg/Int32 | Count: {n_count} |" in info.stdout

    # play into `topic echo`: same messages, same order, recorded timing
    echo = procs([ASTROBEE, "topic", "echo", "/adder/count", "std_msgs/msg/Int32",
                  "--field", "data"], env=env)
    time.sleep(1.0)
    play = procs([ASTROBEE, "bag", "play", str(bag)], env=env)
    # a late subscriber to the latched topic still gets it while the player runs
    time.sleep(1.2)
    latched = subprocess.run([ASTROBEE, "topic", "echo", "/adder/mode", "--once",
                              "--timeout", "5"], env=env, capture_output=True, text=True,
                             timeout=30)
    assert play.wait(timeout=30) == 0, play.err
    assert latched.stdout == "data: adding\n---\n", latched.stderr
    deadline = time.monotonic() + 5
    while len([x for x in echo.lines if x != "---"]) < n_count and time.monotonic() < deadline:
        time.sleep(0.05)
    got = [(int(x), t) for x, t in zip(echo.lines, echo.times) if x != "---"]
    assert [v for v, _ in got] == counts
    recorded = [m.message.log_time for m in decoded if m.channel.topic == "/adder/count"]
    rec_span = (recorded[-1] - recorded[0]) / 1e9
    play_span = got[-1][1] - got[0][1]
    assert abs(play_span - rec_span) <= 0.05 * rec_span, (play_span, rec_span)
    for (_, t), r in zip(got, recorded):
        assert abs((t - got[0][1]) - (r - recorded[0]) / 1e9) <= 0.05 * rec_span


def test_play_rate_and_clock(procs, router, tmp_path):
    from roszen.bag.writer import BagWriter
    from roszen import typestore
    bag = tmp_path / "bag"
    w = BagWriter(bag)
    w.add_topic("/n", "std_msgs/msg/Int32", typestore.message_definition("std_msgs/msg/Int32"),
                typestore.type_hash("std_msgs/msg/Int32"))
    Int32 = typestore.message_class("std_msgs/msg/Int32")
    t0 = 1_700_000_000_000_000_000
    for i in range(21):
        w.write("/n", typestore.serialize(Int32(data=i), "std_msgs/msg/Int32"), t0 + i * 100_000_000)
    w.close()
    env = graph_env(router)
    echo = procs([ASTROBEE, "topic", "echo", "/n", "std_msgs/msg/Int32", "--field", "data"],
                 env=env)
    clock = procs([ASTROBEE, "topic", "echo", "/clock", "rosgraph_msgs/msg/Clock",
                   "--field", "clock.sec"], env=env)
    time.sleep(1.0)
    play = procs([ASTROBEE, "bag", "play", str(bag), "--rate", "2", "--clock", "20"], env=env)
    assert play.wait(timeout=30) == 0
    time.sleep(0.3)
    got = [(int(x), t) for x, t in zip(echo.lines, echo.times) if x != "---"]
    assert [v for v, _ in got] == list(range(21))
    span = got[-1][1] - got[0][1]
    assert abs(span - 1.0) <= 0.05 * 1.0, span               # 2 s of bag at rate 2
    secs = {int(x) for x in clock.lines if x != "---"}
    assert 1_700_000_000 in secs and secs <= {1_700_000_000 + i for i in range(3)}  # bag time


@pytest.mark.parametrize("argv,needle", [
    (["bag", "play", "BAG", "--rate", "0"], "positive number"),
    (["bag", "play", "BAG", "--rate", "-1"], "positive number"),
    (["bag", "play", "BAG", "--topics", "/nope"], "topic '/nope' is not in the bag"),
    (["bag", "record", "-a", "-o", "BAG"], "already exists"),
    (["bag", "record", "-a", "-s", "sqlite3", "-o", "NEW"], "storage 'sqlite3'"),
    (["bag", "record", "-e", "(", "-o", "NEW"], "invalid regular expression"),
    (["bag", "record", "-o", "NEW"], "no topics given"),
    (["bag", "record", "-a", "-o", "MISSING/NEW"], "parent directory does not exist"),
])
def test_bag_bad_input(router, tmp_path, argv, needle):
    from roszen.bag.writer import BagWriter
    bag = tmp_path / "bag"
    BagWriter(bag).close()
    before = sorted(p.name for p in tmp_path.rglob("*"))
    argv = [a.replace("BAG", str(bag)).replace("NEW", str(tmp_path / "new"))
            .replace("MISSING", str(tmp_path / "missing")) for a in argv]
    p = subprocess.run([ASTROBEE, *argv], env=graph_env(router), capture_output=True, text=True,
                       timeout=30)
    assert p.returncode != 0
    err = p.stderr.strip().splitlines()
    assert len(err) == 1 and needle in err[0], p.stderr
    assert sorted(p.name for p in tmp_path.rglob("*")) == before      # nothing half-written


def test_recorder_killed_bag_is_recoverable(procs, router, tmp_path):
    env = graph_env(router)
    pub = procs([ASTROBEE, "topic", "pub", "-r", "50", "-p", "0", "/fast", "std_msgs/msg/String",
                 "{data: x}"], env=env)
    pub.wait_line("beginning loop")
    bag = tmp_path / "bag"
    rec = _record(procs, env, bag, "--flush-interval", "0.2")
    rec.wait_line("Subscribed to topic '/fast'", stream="err")
    time.sleep(1.5)
    rec.popen.send_signal(signal.SIGKILL)
    rec.wait()
    info = subprocess.run([ASTROBEE, "bag", "info", str(bag)], capture_output=True, text=True)
    assert info.returncode == 0 and "no summary" in info.stdout
    rx = subprocess.run([ASTROBEE, "bag", "reindex", str(bag)], capture_output=True, text=True)
    assert rx.returncode == 0, rx.stderr
    from rosbags.highlevel import AnyReader
    with AnyReader([bag]) as reader:
        data = [reader.deserialize(raw, c.msgtype).data for c, _, raw in reader.messages()
                if c.topic == "/fast"]
    assert len(data) >= 40 and set(data) == {"x"}


def test_play_loop_and_start_offset(procs, router, tmp_path):
    from roszen import typestore
    from roszen.bag.writer import BagWriter
    bag = tmp_path / "bag"
    w = BagWriter(bag)
    w.add_topic("/n", "std_msgs/msg/Int32", typestore.message_definition("std_msgs/msg/Int32"),
                typestore.type_hash("std_msgs/msg/Int32"))
    Int32 = typestore.message_class("std_msgs/msg/Int32")
    for i in range(10):
        w.write("/n", typestore.serialize(Int32(data=i), "std_msgs/msg/Int32"),
                1_700_000_000_000_000_000 + i * 50_000_000)
    w.close()
    env = graph_env(router)
    echo = procs([ASTROBEE, "topic", "echo", "/n", "std_msgs/msg/Int32", "--field", "data"],
                 env=env)
    time.sleep(1.0)
    play = procs([ASTROBEE, "bag", "play", str(bag), "--loop", "--start-offset", "0.2"],
                 env=env)
    deadline = time.monotonic() + 20
    while len([x for x in echo.lines if x != "---"]) < 13 and time.monotonic() < deadline:
        time.sleep(0.05)
    play.signal(signal.SIGINT)
    assert play.wait(timeout=20) == 0
    got = [int(x) for x in echo.lines if x != "---"]
    assert got[:13] == [4, 5, 6, 7, 8, 9, 4, 5, 6, 7, 8, 9, 4]     # 0.2 s in, then again
