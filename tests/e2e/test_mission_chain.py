"""Mission client + planner_node + pd_controller_node + recorder, each its own process, with
sim_node on its numpy rigid-body backend (backend:=rigid, lockstep; no pybullet): the chain
flies a plan to the goal, writes summary.json and plot, and the bag decodes with
mcap-ros2-support."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

roszen = pytest.importorskip("roszen")
from roszen import testing  # noqa: E402

pytestmark = pytest.mark.graph
ROOT = Path(__file__).resolve().parents[2]

HOP = {"description": "hop from Node 2 toward the JEM hatch (tests)", "flight_mode": "nominal",
       "robots": [{"name": "", "position": [10.95, 0.5, 4.84],
                   "orientation": [0.0, 0.0, -0.7071067811865476, 0.7071067811865476]}],
       "bag": None,
       "goal": {"position": [10.95, -1.5, 4.84],
                "orientation": [0.0, 0.0, -0.7071067811865476, 0.7071067811865476]}}


def test_mission_chain_with_rigid_sim(tmp_path):
    cfg = tmp_path / "config"
    shutil.copytree(ROOT / "config", cfg)
    (cfg / "scenarios" / "hop.yaml").write_text(yaml.safe_dump(HOP))
    run = tmp_path / "run"
    run.mkdir()
    procs = []
    with testing.router() as port:
        env = dict(testing.zenoh_env(port), ASTROBEE_CONFIG_DIR=str(cfg))
        py = sys.executable
        try:
            for argv in ([py, "-m", "astrobee_sim.sim_node", "--ros-args", "-p", "backend:=rigid",
                          "-p", "scenario:=hop", "-p", "clock_mode:=lockstep"],
                         [py, "-m", "astrobee_planning.planner_node"],
                         [py, "-m", "astrobee_control.pd_controller_node", "--ros-args",
                          "-p", "use_sim_time:=true"],
                         [py, "-m", "astrobee_bringup.cli", "bag", "record", "-a", "-o", str(run / "bag")]):
                procs.append(testing.spawn(argv, env, stdout=subprocess.DEVNULL,
                                           stderr=subprocess.DEVNULL))
            mission = subprocess.run([py, "-m", "astrobee_bringup.mission", "--scenario", "hop",
                                      "--run-dir", str(run), "--timeout", "120"], env=env,
                                     capture_output=True, text=True, timeout=180)
        finally:
            for p in reversed(procs):
                testing.stop(p, timeout=5.0)
    assert mission.returncode == 0, mission.stdout + mission.stderr
    summary = json.loads((run / "summary.json").read_text())
    assert summary["success"] and summary["contacts"] == 0
    assert summary["final_position_error"] < 0.2 and summary["final_attitude_error"] < 0.35
    assert summary["plan_duration"] > 10 and summary["duration"] >= summary["plan_duration"] - 0.1
    assert (run / "plot.png").stat().st_size > 10_000

    from astrobee_bringup.summary import finalize
    assert "SUCCESS" in finalize(run, run / "bag")
    assert json.loads((run / "summary.json").read_text())["legs"][0]["plot_source"] == "recording"

    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    topics = {}
    for f in sorted((run / "bag").glob("*.mcap")):
        with open(f, "rb") as fh:
            reader = make_reader(fh, decoder_factories=[DecoderFactory()])
            for _, channel, _, msg in reader.iter_decoded_messages():
                topics.setdefault(channel.topic, []).append(msg)
    seg = topics["/gnc/ctl/segment"][-1]
    assert len(seg.segment) > 10 and seg.flight_mode == "nominal"
    states = [m.state for m in topics["/mob/state"]]
    assert 9 in states and states[-1] == 2
    p = topics["/loc/truth/pose"][-1].pose.position
    assert np.linalg.norm([p.x - 10.95, p.y + 1.5, p.z - 4.84]) < 0.2
