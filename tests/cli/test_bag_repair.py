"""Bag repair tells the truth and never destroys what it cannot replace: a half-written
metadata.yaml beside its MCAP still reads; reindex with no complete chunk is refused and
changes nothing; a reindex keeps the originals; a damaged chunk is one line, no traceback."""
from __future__ import annotations

import subprocess
import sys

import pytest

from roszen import typestore
from roszen.bag.metadata import BagError
from roszen.bag.reader import BagReader, reindex
from roszen.bag.writer import BagWriter

TYPE = "std_msgs/msg/String"


def _bag(path, n=400, chunk=2048):
    w = BagWriter(path, chunk_size=chunk)
    w.add_topic("/chatter", TYPE, typestore.message_definition(TYPE), typestore.type_hash(TYPE))
    msg = typestore.message_class(TYPE)()
    for i in range(n):
        msg.data = f"hello {i} " + "x" * (i % 50)
        w.write("/chatter", typestore.serialize(msg, TYPE), 1_000_000_000 + i * 10_000_000)
    w.close()
    return path


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "roszen.cli", "bag", *args],
                          capture_output=True, text=True, timeout=60)


def test_half_written_metadata_reads_from_the_mcap(tmp_path):
    bag = _bag(tmp_path / "b")
    meta = (bag / "metadata.yaml").read_text()
    (bag / "metadata.yaml").write_text(meta[: len(meta) // 3])
    r = BagReader(bag)
    assert r.meta is None and r.meta_problem
    assert sum(1 for _ in r.messages()) == 400
    out = _cli("info", str(bag))
    assert out.returncode == 0, out.stderr
    assert "Messages:          400" in out.stdout


def test_reindex_with_nothing_to_recover_changes_nothing(tmp_path):
    bag = _bag(tmp_path / "b")
    mcap = bag / "b_0.mcap"
    data = mcap.read_bytes()
    mcap.write_bytes(data[:60])            # the header only: no complete chunk
    before = (bag / "metadata.yaml").read_text()
    with pytest.raises(BagError, match="no complete chunk"):
        reindex(bag)
    assert (bag / "metadata.yaml").read_text() == before
    out = _cli("reindex", str(bag))
    assert out.returncode == 1 and "nothing changed" in out.stderr and "Traceback" not in out.stderr
    assert (bag / "metadata.yaml").read_text() == before


def test_reindex_keeps_the_originals(tmp_path):
    bag = _bag(tmp_path / "b")
    mcap = bag / "b_0.mcap"
    data = mcap.read_bytes()
    mcap.write_bytes(data[: len(data) * 2 // 3])   # cut: no summary, some chunks complete
    meta = reindex(bag)
    assert 0 < meta.message_count < 400
    assert (bag / "b_0.mcap.orig").read_bytes() == data[: len(data) * 2 // 3]
    assert (bag / "metadata.yaml.orig").exists()
    assert sum(1 for _ in BagReader(bag).messages()) == meta.message_count


def test_damaged_chunk_is_one_line(tmp_path):
    bag = _bag(tmp_path / "b", n=2000)
    mcap = bag / "b_0.mcap"
    data = bytearray(mcap.read_bytes())
    mid = len(data) // 2
    data[mid: mid + 4096] = bytes(4096)
    mcap.write_bytes(bytes(data))
    with pytest.raises(BagError, match="unreadable MCAP"):
        list(BagReader(bag).messages())
    out = _cli("play", str(bag), "-r", "1000")
    assert out.returncode == 1
    assert "Traceback" not in out.stderr and "unreadable MCAP" in out.stderr
