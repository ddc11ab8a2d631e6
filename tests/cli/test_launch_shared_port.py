"""Two launches on one --port do not join one graph: the second one sees the first one's nodes
in the router's graph and refuses in one line, before it starts anything or makes a run folder
(it had reset the first launch's sim mid-flight and both runs failed)."""
from __future__ import annotations

import subprocess

import pytest

from conftest import ASTROBEE, graph_env

pytestmark = pytest.mark.graph


def test_second_launch_on_a_busy_graph_refuses(procs, router, tmp_path):
    env = graph_env(router)
    sim = procs([ASTROBEE, "run", "astrobee_sim", "sim_node", "--ros-args", "-p", "backend:=rigid",
                 "-p", "start_paused:=true"], env=env)
    sim.wait_line("sim_node", stream="err", timeout=60)
    p = subprocess.run([ASTROBEE, "launch", "cargo_transport", "--port", str(router)], cwd=tmp_path,
                       capture_output=True, text=True, timeout=60, env=env)
    assert p.returncode == 1, (p.stdout[-2000:], p.stderr[-2000:])
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and "already runs /sim_node" in lines[0], p.stderr
    assert not (tmp_path / "runs").exists()
    assert sim.popen.poll() is None          # the first graph's sim is untouched
