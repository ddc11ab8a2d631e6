"""rosbag2 MCAP directories without a graph: what the writer produces is read by
mcap-ros2-support and rosbags; a writer killed with SIGKILL leaves a bag that `bag info`
reads and `bag reindex` completes; bad directories give one-line errors."""
from __future__ import annotations

import signal
import struct
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from conftest import ASTROBEE
from roszen.bag.metadata import BagError
from roszen.bag.reader import BagReader, reindex
from roszen.bag.writer import BagWriter
from roszen.qos import LATCHED, QoSProfile

STRING_HASH = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"


def cdr_string(text: str) -> bytes:
    b = text.encode() + b"\0"
    return b"\x00\x01\x00\x00" + struct.pack("<I", len(b)) + b


def _decode(path: Path, topic: str | None = None) -> list:
    """Messages decoded by mcap-ros2-support (an independent CDR decoder)."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        return [m.decoded_message for m in reader.iter_decoded_messages(
            topics=[topic] if topic else None)]


def _write(path: Path, n=50, compression="zstd"):
    w = BagWriter(path, compression=compression)
    w.add_topic("/chatter", "std_msgs/msg/String", "string data", STRING_HASH,
                [QoSProfile(depth=10)])
    w.add_topic("/latched", "std_msgs/msg/String", "string data", STRING_HASH, [LATCHED])
    t0 = 1_700_000_000_000_000_000
    for i in range(n):
        w.write("/chatter", cdr_string(f"hello {i}"), t0 + i * 10_000_000)
    w.write("/latched", cdr_string("mode"), t0 + 1)
    return w.close()


@pytest.mark.parametrize("compression", ["zstd", "lz4"])
def test_written_bag_reads_with_mcap_ros2_and_rosbags(tmp_path, compression):
    bag = tmp_path / "bag"
    _write(bag, compression=compression)
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["version"] == 9 and meta["storage_identifier"] == "mcap"
    assert meta["message_count"] == 51
    topics = {t["topic_metadata"]["name"]: t for t in meta["topics_with_message_count"]}
    assert topics["/chatter"]["message_count"] == 50
    assert topics["/latched"]["topic_metadata"]["offered_qos_profiles"][0]["durability"] \
        == "transient_local"
    assert topics["/chatter"]["topic_metadata"]["type_description_hash"] == STRING_HASH

    got = [m.data for m in _decode(bag / "bag_0.mcap", "/chatter")]
    assert got == [f"hello {i}" for i in range(50)]

    from rosbags.highlevel import AnyReader
    with AnyReader([bag]) as reader:
        qos = {c.topic: c.ext.offered_qos_profiles for c in reader.connections}
        assert qos["/latched"][0].durability.name == "TRANSIENT_LOCAL"
        data = [reader.deserialize(raw, c.msgtype).data for c, _, raw in reader.messages()]
    assert data.count("mode") == 1 and len(data) == 51

    with open(bag / "bag_0.mcap", "rb") as f:
        from mcap.reader import make_reader
        r = make_reader(f)
        assert r.get_header().profile == "ros2"
        summary = r.get_summary()
        assert {s.encoding for s in summary.schemas.values()} == {"ros2msg"}
        assert all(c.message_encoding == "cdr" for c in summary.channels.values())
        assert summary.statistics.chunk_count >= 1
        assert {ci.compression for ci in summary.chunk_indexes} == {compression}
        assert any(m.name == "rosbag2" for m in r.iter_metadata())


def test_output_directory_must_not_exist(tmp_path):
    (tmp_path / "bag").mkdir()
    with pytest.raises(BagError, match="already exists"):
        BagWriter(tmp_path / "bag")
    with pytest.raises(BagError, match="parent directory does not exist"):
        BagWriter(tmp_path / "nope" / "bag")


KILLED_WRITER = r'''
import struct, sys, time
from roszen.bag.writer import BagWriter
from roszen.qos import QoSProfile
w = BagWriter(sys.argv[1], flush_interval=0.1, chunk_size=4096)
w.add_topic("/c", "std_msgs/msg/String", "string data", "", [QoSProfile()])
i = 0
while True:
    b = f"m{i}".encode() + b"\0"
    w.write("/c", b"\x00\x01\x00\x00" + struct.pack("<I", len(b)) + b)
    i += 1
    if i == 300:
        print("ready", flush=True)
    time.sleep(0.001)
'''


def test_bag_survives_sigkill_and_reindex_completes_it(tmp_path):
    bag = tmp_path / "killed"
    p = subprocess.Popen([sys.executable, "-c", KILLED_WRITER, str(bag)], stdout=subprocess.PIPE)
    try:
        assert p.stdout.readline() == b"ready\n"
        time.sleep(0.4)
    finally:
        p.send_signal(signal.SIGKILL)
        p.wait()
    reader = BagReader(bag)
    assert reader.recovered
    msgs = list(reader.messages())
    assert len(msgs) >= 300
    # in order, no gap: the recovered messages are a prefix of what was written
    assert [m.data[8:-1].decode() for m in msgs] == [f"m{i}" for i in range(len(msgs))]
    info = subprocess.run([ASTROBEE, "bag", "info", str(bag)], capture_output=True, text=True)
    assert info.returncode == 0, info.stderr
    assert f"Count: {len(msgs)}" in info.stdout and "no summary" in info.stdout

    rc = subprocess.run([ASTROBEE, "bag", "reindex", str(bag)], capture_output=True, text=True)
    assert rc.returncode == 0, rc.stderr
    # the originals are kept beside (reindex never destroys what it cannot replace)
    assert sorted(x.name for x in bag.iterdir()) == ["killed_0.mcap", "killed_0.mcap.orig",
                                                     "metadata.yaml", "metadata.yaml.orig"]
    assert not BagReader(bag).recovered
    from rosbags.highlevel import AnyReader
    with AnyReader([bag]) as r:
        assert sum(1 for _ in r.messages()) == len(msgs)
    assert [m.data for m in _decode(bag / "killed_0.mcap")] == \
        [f"m{i}" for i in range(len(msgs))]


def test_bag_info_matches_contents(tmp_path):
    _write(tmp_path / "bag", n=7)
    p = subprocess.run([ASTROBEE, "bag", "info", str(tmp_path / "bag")], capture_output=True,
                       text=True)
    assert p.returncode == 0, p.stderr
    assert "Storage id:        mcap" in p.stdout
    assert "Messages:          8" in p.stdout
    assert "Topic: /chatter | Type: std_msgs/msg/String | Count: 7 | Serialization Format: cdr" \
        in p.stdout
    assert "Duration:          0.060000000s" in p.stdout


@pytest.mark.parametrize("setup,needle", [
    ("missing", "does not exist"),
    ("file", "not a bag directory"),
    ("empty", "no metadata.yaml and no .mcap file"),
    ("badyaml", "invalid YAML"),
    ("notmcap", "not an MCAP file"),
])
def test_unreadable_bag_directory_one_line_error(tmp_path, setup, needle):
    d = tmp_path / "bag"
    if setup == "file":
        d.write_text("x")
    elif setup == "empty":
        d.mkdir()
    elif setup == "badyaml":        # and no MCAP (beside a good MCAP it reads: test_bag_repair)
        d.mkdir()
        (d / "metadata.yaml").write_text("rosbag2_bagfile_information: [\n")
    elif setup == "notmcap":
        d.mkdir()
        (d / "x.mcap").write_bytes(b"hello world, not mcap")
    for verb in ("info", "play", "reindex"):
        p = subprocess.run([ASTROBEE, "bag", verb, str(d)], capture_output=True, text=True,
                           timeout=30)
        assert p.returncode != 0, (verb, p.stdout)
        lines = p.stderr.strip().splitlines()
        assert len(lines) == 1 and needle in lines[0], (verb, p.stderr)
        assert lines[0].startswith(f"astrobee bag {verb}:")
