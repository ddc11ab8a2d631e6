"""summary.json is written atomically: the whole file or the old one, never half of one; a
failed write is one line and leaves no temporary file behind (no process)."""
from __future__ import annotations

import json
import os

import numpy as np

from astrobee_bringup.mission.result import write_summary


def test_the_summary_is_written_whole_with_numpy_and_nan_made_plain(tmp_path):
    path = tmp_path / "summary.json"
    assert write_summary(path, {"success": True, "e": np.float64(0.5), "n": float("nan"),
                                "k": np.int64(3), "v": np.arange(2)}) == ""
    assert json.loads(path.read_text()) == {"success": True, "e": 0.5, "n": None, "k": 3,
                                            "v": [0, 1]}
    assert os.listdir(tmp_path) == ["summary.json"]


def test_a_failed_write_says_so_in_one_line_and_leaves_nothing(tmp_path, monkeypatch):
    path = tmp_path / "summary.json"
    path.write_text('{"old": true}\n')

    def refuse(*_a):
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(os, "replace", refuse)
    err = write_summary(path, {"success": False})
    assert err.startswith(f"could not write {path}: ") and "No space left" in err
    assert "\n" not in err
    assert os.listdir(tmp_path) == ["summary.json"]              # no temporary left
    assert json.loads(path.read_text()) == {"old": True}         # the old file intact
    monkeypatch.undo()
    assert "could not write" in write_summary(tmp_path / "no_dir" / "summary.json", {})
    assert sorted(os.listdir(tmp_path)) == ["summary.json"]
