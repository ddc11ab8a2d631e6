"""The nodes on real rclpy + rmw_fastrtps_cpp (ASTROBEE_RUNTIME=rclpy; `make test-rclpy` runs
this in .venv-rclpy): sim_node (rigid backend, lockstep, a rigid bag), planner_node, the PD
controller and the mission, each its own process, fly a short hop to success; a plain rclpy
subscriber (rosidl's generated classes, no project code) hears /loc/truth/pose and
/sim/bag/state; the recorder on rclpy (roszen.rclpy_backend.record) writes a bag that
mcap-ros2-support decodes whole. Skipped where rclpy or the built astrobee_msgs cannot be
imported."""
from __future__ import annotations

import json
import os
import random
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

# rclpy.node: this folder itself can be imported as a namespace package named rclpy
pytest.importorskip("rclpy.node", reason="real rclpy is not installed here (make install-rclpy)")
pytest.importorskip("astrobee_msgs.msg", reason="astrobee_msgs is not built for rclpy "
                    "(make install-rclpy)")
from roszen import testing  # noqa: E402

pytestmark = pytest.mark.graph
ROOT = Path(__file__).resolve().parents[2]
GOAL = [10.95, -1.5, 4.84]
HOP = {"description": "hop from Node 2 toward the JEM hatch with a rigid bag (rclpy tests)",
       "flight_mode": "nominal",
       "robots": [{"name": "", "position": [10.95, 0.5, 4.84],
                   "orientation": [0.0, 0.0, -0.7071067811865476, 0.7071067811865476]}],
       "bag": {"model": "rigid", "variant": "front", "size": [0.5, 0.42, 0.25], "mass": 2.0},
       "goal": {"position": GOAL,
                "orientation": [0.0, 0.0, -0.7071067811865476, 0.7071067811865476]}}

# a ROS 2 user's own node: generated classes only
LISTENER = r"""
import json, os, sys, time
import rclpy
from astrobee_msgs.msg import BagState
from geometry_msgs.msg import PoseStamped
rclpy.init()
node = rclpy.create_node("plain_listener")
got = {"pose": 0, "bag": 0, "last": None, "bag_model": None}
def on_pose(m):
    got["pose"] += 1
    got["last"] = [m.pose.position.x, m.pose.position.y, m.pose.position.z]
def on_bag(m):
    got["bag"] += 1
    got["bag_model"] = m.model
node.create_subscription(PoseStamped, "/loc/truth/pose", on_pose, 10)
node.create_subscription(BagState, "/sim/bag/state", on_bag, 10)
end = time.monotonic() + float(sys.argv[2])
while time.monotonic() < end and not os.path.exists(sys.argv[1]):
    rclpy.spin_once(node, timeout_sec=0.1)
print(json.dumps(got), flush=True)
node.destroy_node()
rclpy.try_shutdown()
"""


def rclpy_env(config_dir: Path) -> dict:
    """The graph on rclpy + Fast DDS in a domain of its own, discovery on this machine, UDP only
    (Fast DDS leaves /dev/shm segments behind when a process is killed)."""
    env = dict(os.environ, ASTROBEE_RUNTIME="rclpy", RMW_IMPLEMENTATION="rmw_fastrtps_cpp",
               ROS_DOMAIN_ID=str(random.randint(1, 100)), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               FASTDDS_BUILTIN_TRANSPORTS="UDPv4", ASTROBEE_CONFIG_DIR=str(config_dir),
               PYTHONUNBUFFERED="1")
    env.pop("ROS_LOCALHOST_ONLY", None)
    return env


def test_hop_on_rclpy_fastrtps(tmp_path):
    cfg = tmp_path / "config"
    shutil.copytree(ROOT / "config", cfg)
    (cfg / "scenarios" / "hop.yaml").write_text(yaml.safe_dump(HOP))
    run = tmp_path / "run"
    run.mkdir()
    stop_file = tmp_path / "stop"
    env = rclpy_env(cfg)
    py = sys.executable
    procs = []
    logs = []
    try:
        listener = subprocess.Popen([py, "-c", LISTENER, str(stop_file), "200"], env=env,
                                    stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                    start_new_session=True)
        procs.append(listener)
        for i, argv in enumerate((
                [py, "-m", "roszen.rclpy_backend.record", "-a", "--use-sim-time", "-o",
                 str(run / "bag")],
                [py, "-m", "astrobee_sim.sim_node", "--ros-args", "-p", "backend:=rigid",
                 "-p", "scenario:=hop", "-p", "clock_mode:=lockstep"],
                [py, "-m", "astrobee_planning.planner_node"],
                [py, "-m", "astrobee_control.pd_controller_node", "--ros-args",
                 "-p", "use_sim_time:=true"])):
            log = open(tmp_path / f"node{i}.log", "w")
            logs.append(log)
            procs.append(testing.spawn(argv, env, stdout=log, stderr=subprocess.STDOUT))
        mission = subprocess.run([py, "-m", "astrobee_bringup.mission", "--scenario", "hop",
                                  "--run-dir", str(run), "--timeout", "150"], env=env,
                                 capture_output=True, text=True, timeout=240)
        stop_file.write_text("")
        out, err = listener.communicate(timeout=20)
    finally:
        for p in reversed(procs):
            testing.stop(p, timeout=5.0)
        for log in logs:
            log.close()
    node_logs = "\n".join((tmp_path / f"node{i}.log").read_text()[-3000:] for i in range(4))
    assert mission.returncode == 0, mission.stdout[-3000:] + mission.stderr[-3000:] + node_logs
    summary = json.loads((run / "summary.json").read_text())
    assert summary["success"] and summary["contacts"] == 0, summary.get("reason")
    assert summary["final_position_error"] < 0.2
    heard = json.loads(out.strip().splitlines()[-1])
    assert heard["pose"] > 100 and heard["bag"] > 100, heard
    assert heard["bag_model"] == "rigid"
    assert sum((a - b) ** 2 for a, b in zip(heard["last"], GOAL)) ** 0.5 < 0.2, heard
    assert all(p.poll() is not None for p in procs)

    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    topics: dict = {}
    for f in sorted((run / "bag").glob("*.mcap")):
        with open(f, "rb") as fh:
            reader = make_reader(fh, decoder_factories=[DecoderFactory()])
            for _, channel, _, msg in reader.iter_decoded_messages():   # every one decodes
                topics.setdefault(channel.topic, []).append(msg)
    assert {"/clock", "/tf", "/gnc/ctl/command", "/gnc/ctl/segment", "/mob/state",
            "/sim/scenario"} <= set(topics), sorted(topics)
    assert topics["/sim/bag/state"][-1].model == "rigid"
    p = topics["/loc/truth/pose"][-1].pose.position
    assert sum((a - b) ** 2 for a, b in zip([p.x, p.y, p.z], GOAL)) ** 0.5 < 0.2
    assert topics["/mob/state"][-1].state == 2                  # reached
