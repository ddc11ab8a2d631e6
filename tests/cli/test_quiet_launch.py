"""A normal successful run prints no WARN or ERROR line: the lightest lockstep launch (Node 2 ->
JEM, no cargo bag, no recording) ends with the sim paused while the launch stops, which the
controllers must not report as a hang."""
from __future__ import annotations

import json
import re
import subprocess

import pytest

from conftest import ASTROBEE
from roszen.testing import free_port

pytestmark = pytest.mark.graph


def test_a_successful_lockstep_launch_prints_no_warning(tmp_path):
    run = tmp_path / "run"
    r = subprocess.run([ASTROBEE, "launch", "cargo_transport", "scenario:=node2_to_jem",
                        "record:=false", "video:=false", "--port", str(free_port()),
                        "--run-dir", str(run)],
                       stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, timeout=280,
                       cwd=tmp_path)
    summary = json.loads((run / "summary.json").read_text())
    assert r.returncode == 0 and summary["success"], r.stdout[-3000:]
    loud = [ln for ln in r.stdout.splitlines() if re.search(r"\[(WARN|WARNING|ERROR|FATAL)\]", ln)]
    assert not loud, "\n".join(loud)
