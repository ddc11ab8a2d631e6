"""`astrobee bag render` of a damaged recording: 4 KB of zeros in the MCAP or 50
flipped bits end in one line naming the file, exit 1, no traceback (they were a ZstdError or
BagError traceback); the recording reader turns a damaged chunk into RecordingError."""
from __future__ import annotations

import random

import pytest

from test_render import write_recording

from astrobee_bringup.render_recording import main as render_main
from astrobee_lab.recording import Recording, RecordingError


def _damaged(tmp_path, how: str):
    bag = tmp_path / "bag"
    write_recording(bag, seconds=2.0)
    mcap = next(bag.glob("*.mcap"))
    data = bytearray(mcap.read_bytes())
    if how == "zeros":
        mid = len(data) // 2
        data[mid: mid + 4096] = bytes(4096)
    else:                                  # 50 flipped bits, placed by the seed
        rnd = random.Random(int(how))
        for _ in range(50):
            i = rnd.randrange(len(data))
            data[i] ^= 1 << rnd.randrange(8)
    mcap.write_bytes(bytes(data))
    return bag


@pytest.mark.parametrize("how", ["zeros", "1", "2", "3", "4", "5", "7"])
def test_a_damaged_recording_is_one_line(tmp_path, capsys, how):
    bag = _damaged(tmp_path, how)
    code = render_main([str(bag), "-o", str(tmp_path / "f.gif"), "--gif", "--scale", "0.25",
                        "--fps", "2"])
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err
    if code == 0:                          # the bits fell where nothing we draw reads them
        assert (tmp_path / "f.gif").exists()
        return
    assert code == 1
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("astrobee bag render: "), err
    assert not (tmp_path / "f.gif").exists()


def test_zeros_name_the_damaged_file(tmp_path, capsys):
    bag = _damaged(tmp_path, "zeros")
    assert render_main([str(bag), "-o", str(tmp_path / "f.gif"), "--gif"]) == 1
    err = capsys.readouterr().err
    assert "unreadable MCAP" in err and str(bag) in err, err


def test_the_reader_says_recording_error_for_a_damaged_chunk(tmp_path):
    rec = Recording(_damaged(tmp_path, "zeros"))
    with pytest.raises(RecordingError, match="unreadable MCAP"):
        list(rec.messages(rec.topics))
