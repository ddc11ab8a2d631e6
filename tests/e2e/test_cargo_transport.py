"""The whole graph, each node its own process, started by `astrobee launch cargo_transport`:
a flight to the goal with a recorded bag, the controller killed mid-flight, Ctrl-C."""
from __future__ import annotations

import json
import os
import re
import selectors
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from roszen.testing import free_port, pid_alive
import yaml

pytestmark = [pytest.mark.graph, pytest.mark.slow]
ROOT = Path(__file__).resolve().parents[2]

pytest.importorskip("astrobee_sim.sim_node")
pytest.importorskip("astrobee_planning.planner_node")

# A short hop inside Node 2 (1.5 m): the fault tests need a flight, not the whole trip.
SHORT_HOP = {
    "description": "short hop in Node 2 (tests)",
    "flight_mode": "nominal",
    "robots": [{"name": "", "position": [10.95, 0.6, 4.84],
                "orientation": [0.0, 0.0, -0.7071067811865476, 0.7071067811865476]}],
    "bag": None,
    "goal": {"position": [10.95, -0.9, 4.84],
             "orientation": [0.0, 0.0, -0.7071067811865476, 0.7071067811865476]},
}


@pytest.fixture
def config_dir(tmp_path):
    """The project's config with the test scenario added (ASTROBEE_CONFIG_DIR)."""
    d = tmp_path / "config"
    shutil.copytree(ROOT / "config", d)
    (d / "scenarios" / "short_hop.yaml").write_text(yaml.safe_dump(SHORT_HOP))
    return d


class Launch:
    """`astrobee launch cargo_transport` in its own process group; lines collected as read."""

    def __init__(self, run_dir: Path, config_dir: Path, *args: str) -> None:
        env = dict(os.environ, ASTROBEE_CONFIG_DIR=str(config_dir), PYTHONUNBUFFERED="1")
        env.pop("ZENOH_CONFIG_OVERRIDE", None)
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "astrobee_bringup.cli", "launch", "cargo_transport", *args,
             "--port", str(free_port()), "--run-dir", str(run_dir)],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
            env=env, start_new_session=True, text=True)
        self.lines: list[str] = []
        self.sel = selectors.DefaultSelector()
        self.sel.register(self.proc.stdout, selectors.EVENT_READ)

    def read_until(self, pattern: str, timeout: float) -> re.Match:
        rx = re.compile(pattern)
        for line in self.lines:
            m = rx.search(line)
            if m:
                return m
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if not self.sel.select(0.2):
                continue
            line = self.proc.stdout.readline()
            if not line:
                break
            for part in line.rstrip("\n").split("\r"):
                self.lines.append(part)
                m = rx.search(part)
                if m:
                    return m
        raise AssertionError(f"{pattern!r} not seen; last lines:\n" + "\n".join(self.lines[-40:]))

    def wait(self, timeout: float) -> int:
        end = time.monotonic() + timeout
        while self.proc.poll() is None and time.monotonic() < end:
            if self.sel.select(0.2):
                line = self.proc.stdout.readline()
                if line:
                    self.lines.extend(line.rstrip("\n").split("\r"))
        if self.proc.poll() is None:
            raise AssertionError("launch did not exit; last lines:\n" + "\n".join(self.lines[-40:]))
        rest = self.proc.stdout.read()
        self.lines.extend(rest.splitlines())
        return self.proc.returncode

    def child_pids(self) -> dict[str, int]:
        out = {}
        for line in self.lines:
            m = re.search(r"started '([^']+)' \(?pid (\d+)", line)
            if m:
                out[m.group(1)] = int(m.group(2))
        return out

    def kill(self) -> None:
        if self.proc.poll() is None:
            try:
                os.killpg(self.proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            self.proc.wait()
        for pid in self.child_pids().values():
            try:
                os.killpg(pid, signal.SIGKILL)
            except (ProcessLookupError, PermissionError):
                pass


@pytest.fixture
def launches():
    started: list[Launch] = []
    yield started
    for launch in started:
        launch.kill()


def mcap_messages(bag_dir: Path) -> dict[str, list]:
    """Every message of the bag decoded by an independent reader (mcap-ros2-support)."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    files = sorted(bag_dir.glob("*.mcap"))
    assert files, f"no MCAP file in {bag_dir}"
    out: dict[str, list] = {}
    for path in files:
        with open(path, "rb") as f:
            for m in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
                out.setdefault(m.channel.topic, []).append(m.decoded_message)
    return out


def test_flight_reaches_goal_and_bag_decodes(tmp_path, config_dir, launches):
    run = tmp_path / "run"
    launch = Launch(run, config_dir, "scenario:=node2_to_jem")
    launches.append(launch)
    code = launch.wait(timeout=240.0)
    assert code == 0, "\n".join(launch.lines[-40:])
    summary = json.loads((run / "summary.json").read_text())
    assert summary["success"], summary["reason"]
    assert summary["final_position_error"] <= 0.2
    assert summary["final_attitude_error"] <= 0.35
    assert summary["contacts"] == 0
    assert (run / "plot.png").stat().st_size > 10_000
    msgs = mcap_messages(run / "bag")
    poses = msgs["/loc/truth/pose"]
    assert len(poses) > 100
    last = poses[-1].pose.position
    goal = np.array([10.93, -6.0, 4.85])
    assert np.linalg.norm(np.array([last.x, last.y, last.z]) - goal) <= 0.2
    assert "/gnc/ctl/command" in msgs and "/mob/state" in msgs and "/gnc/ctl/segment" in msgs
    for pid in launch.child_pids().values():
        assert not pid_alive(pid)


def stamp(msg) -> float:
    return msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec


def test_controller_killed_midflight(tmp_path, config_dir, launches):
    """The controller dies: the sim's watchdog stops the thrust and raises a fault, the mission
    ends the leg on it, the launcher reports the failure and stops the others; the bag (the
    recorder is stopped last) holds the fault and the coasting robot."""
    from astrobee import flight_modes
    run = tmp_path / "run"
    # lockstep_timeout: without a controller the sim steps on every 0.05 s (default 1 s)
    # a long flight (126 s of sim, >= 12 s of wall): it cannot end before the kill, even when
    # the CONTROLLING line reaches this test late on a loaded machine
    launch = Launch(run, config_dir, "scenario:=jem_to_node1", "lockstep_timeout:=0.05")
    launches.append(launch)
    launch.read_until(r"CONTROLLING: segment", timeout=120.0)   # the controller took it
    pids = launch.child_pids()
    os.killpg(pids["pd_controller_node"], signal.SIGKILL)
    code = launch.wait(timeout=60.0)
    assert code != 0
    assert any("pd_controller_node" in line and "exited" in line for line in launch.lines)
    assert any("failed" in line and "pd_controller_node" in line for line in launch.lines)
    for pid in pids.values():
        assert not pid_alive(pid)
    summary = json.loads((run / "summary.json").read_text())
    assert not summary["success"]
    assert "propulsion_watchdog" in summary["reason"], summary["reason"]

    msgs = mcap_messages(run / "bag")
    faults = [m for m in msgs.get("/sim/fault", []) if m.active]
    assert faults, f"no active fault in the bag: {msgs.get('/sim/fault')}"
    assert faults[0].source == "sim/propulsion_watchdog" and faults[0].code == 1
    t_fault = stamp(faults[0])
    speeds = [(stamp(m), float(np.linalg.norm([m.twist.linear.x, m.twist.linear.y,
                                               m.twist.linear.z])))
              for m in msgs["/loc/truth/twist"]]
    v_fault = max(v for t, v in speeds if t <= t_fault + 1e-6 and t > t_fault - 0.05)
    after = [v for t, v in speeds if t > t_fault]
    assert len(after) >= 5, "the bag ends at the fault: the robot's coasting is not recorded"
    # propulsion stopped: the speed does not grow, and stays under the flight mode's limit
    assert max(after) <= v_fault + 0.01, (v_fault, max(after))
    assert max(after) < flight_modes.get("nominal").hard_limit_vel


def test_sigint_leaves_nothing_behind(tmp_path, config_dir, launches):
    run = tmp_path / "run"
    # 126 s of sim: lockstep runs at 1-10x real time, so the flight lasts 12 s of wall or more,
    # a wide window even when the launcher's log lines reach this test seconds late (load)
    launch = Launch(run, config_dir, "scenario:=jem_to_node1")
    launches.append(launch)
    launch.read_until(r"CONTROLLING: segment", timeout=120.0)   # the controller took it
    pids = launch.child_pids()
    assert {"sim_node", "planner_node", "pd_controller_node", "recorder", "mission"} <= set(pids)
    # Let the flight run a moment (1 s of wall is 60-600 poses, still mid-flight) before Ctrl-C.
    time.sleep(1.0)
    os.kill(launch.proc.pid, signal.SIGINT)
    launch.wait(timeout=60.0)
    for name, pid in pids.items():
        assert not pid_alive(pid), f"{name} left behind"
    summary = json.loads((run / "summary.json").read_text())
    assert summary["status"] == "interrupted"
    msgs = mcap_messages(run / "bag")
    assert len(msgs["/loc/truth/pose"]) > 10


def test_bag_override_reaches_every_node(tmp_path, config_dir, launches):
    """`bag_model:=` on a scenario without a bag: the sim builds the bag, publishes the scenario
    it built, and the mission reports the bag and plans with its margin."""
    run = tmp_path / "run"
    launch = Launch(run, config_dir, "scenario:=short_hop", "bag_model:=rigid")
    launches.append(launch)
    code = launch.wait(timeout=240.0)
    assert code == 0, "\n".join(launch.lines[-40:])
    summary = json.loads((run / "summary.json").read_text())
    assert summary["success"], summary["reason"]
    leg = summary["legs"][0] if "legs" in summary else summary
    assert leg["carrying_bag"] is True
    assert leg["carry_extent"] == pytest.approx(0.05)
    msgs = mcap_messages(run / "bag")
    info = msgs["/sim/scenario"][-1]
    assert info.carrying_bag and info.bag_model == "rigid" and info.name == "short_hop"
    assert info.bag_mass == pytest.approx(10.0)
    assert msgs["/sim/bag/state"], "the sim flew no bag"


def test_bad_override_starts_nothing(tmp_path, config_dir):
    """A bad launch argument is one line from the launcher; no process, no run folder."""
    run = tmp_path / "run"
    env = dict(os.environ, ASTROBEE_CONFIG_DIR=str(config_dir))
    out = subprocess.run([sys.executable, "-m", "astrobee_bringup.cli", "launch", "cargo_transport",
                          "scenario:=node2_to_jem", "bag_model:=nonsense", "--run-dir", str(run),
                          "--port", str(free_port())],
                         capture_output=True, text=True, timeout=60, env=env)
    assert out.returncode == 1
    lines = [ln for ln in out.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "nonsense" in lines[0], out.stderr
    assert "started" not in out.stdout
    assert not run.exists()


def carry_short_hop(tmp_path, config_dir, launches, controller: str):
    """The whole graph flies short_hop carrying the constraint bag with `controller`: success,
    no contact (the run folder and the launch)."""
    run = tmp_path / "run"
    launch = Launch(run, config_dir, "scenario:=short_hop", f"controller:={controller}",
                    "bag_model:=constraint")
    launches.append(launch)
    code = launch.wait(timeout=300.0)
    assert code == 0, "\n".join(launch.lines[-40:])
    summary = json.loads((run / "summary.json").read_text())
    assert summary["success"], summary["reason"]
    assert summary["contacts"] == 0 and summary["carrying_bag"]
    return run, launch


def test_mpc_controller_flies_a_leg(tmp_path, config_dir, launches):
    """mpc_controller_node (the sampling MPC on controller_node) flies a short leg carrying the
    constraint bag through the whole graph, and publishes what it considered."""
    run, _ = carry_short_hop(tmp_path, config_dir, launches, "mpc")
    msgs = mcap_messages(run / "bag")
    cands = msgs.get("/gnc/ctl/candidates", [])
    assert cands, "no candidates published"
    assert any(m.ns == "chosen" for arr in cands for m in arr.markers)


@pytest.mark.parametrize("controller", ["pair_gov", "wmpc"])
def test_pair_aware_controller_flies_a_leg(tmp_path, config_dir, launches, controller):
    """The pair-aware laws of the controller registry (the governed pair law; the predictive
    controller over the wrench) fly a short leg carrying the constraint bag through the whole
    graph (controller:=<name>); wmpc publishes its predicted trajectory (nav_msgs/Path)."""
    run, launch = carry_short_hop(tmp_path, config_dir, launches, controller)
    assert any(f"{controller}_controller_node" in ln for ln in launch.lines)
    if controller == "wmpc":
        paths = mcap_messages(run / "bag").get("/gnc/ctl/predicted_path", [])
        assert paths and all(p.header.frame_id == "world" for p in paths)
        assert max(len(p.poses) for p in paths) > 5


def test_safety_filter_in_the_loop_is_transparent(tmp_path, config_dir, launches):
    """safety:=true puts the CBF filter between the controller and the sim, inside the
    controller's process: the nominal flight is unchanged (goal reached, no contact) and the
    filter reports no intervention on the same latched /gnc/ctl/safety diagnostics as the
    separate safety_filter_node (safety:=node) publishes; no command_nominal hop."""
    run = tmp_path / "run"
    launch = Launch(run, config_dir, "scenario:=short_hop", "safety:=true")
    launches.append(launch)
    code = launch.wait(timeout=240.0)
    assert code == 0, "\n".join(launch.lines[-40:])
    summary = json.loads((run / "summary.json").read_text())
    assert summary["success"], summary["reason"]
    assert summary["contacts"] == 0
    msgs = mcap_messages(run / "bag")
    assert "/gnc/ctl/command_nominal" not in msgs and "/gnc/ctl/command" in msgs
    diag = msgs["/gnc/ctl/safety"][-1].status[0]
    values = {kv.key: kv.value for kv in diag.values}
    assert int(values["ticks"]) > 100 and int(values["active_ticks"]) == 0, values
