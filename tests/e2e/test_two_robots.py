"""Two Astrobees carry one two-handle cargo bag through the whole graph (`astrobee launch
cargo_transport scenario:=two_robots_bag`): a controller per robot in its namespace, the
formation plan from planner_node, the mission following both; and the leg fails, naming the
robot, when one robot's controller is killed."""
from __future__ import annotations

import json
import os
import signal

import pytest

from roszen.testing import pid_alive
from test_cargo_transport import Launch, config_dir, launches, mcap_messages  # noqa: F401

pytestmark = [pytest.mark.graph, pytest.mark.slow]

pytest.importorskip("astrobee_sim.sim_node")
pytest.importorskip("astrobee_planning.planner_node")


def test_two_robots_carry_the_cargo_bag_node2_to_jem(tmp_path, config_dir, launches):  # noqa: F811
    run = tmp_path / "run"
    launch = Launch(run, config_dir, "scenario:=two_robots_bag")     # constraint bag, lockstep
    launches.append(launch)
    code = launch.wait(timeout=300.0)
    assert code == 0, "\n".join(launch.lines[-40:])
    pids = launch.child_pids()
    assert {"pd_controller_node", "bumble/pd_controller_node"} <= set(pids)
    summary = json.loads((run / "summary.json").read_text())
    assert summary["success"], summary["reason"]
    assert summary["contacts"] == 0 and summary["faults"] == []
    robots = {r["name"]: r for r in summary["robots"]}
    assert set(robots) == {"", "bumble"}
    for r in robots.values():
        assert r["success"] and r["reached_goal"], r
        assert r["contacts"] == 0 and r["faults"] == [] and r["failed_at"] is None
        assert r["final_position_error"] <= summary["tolerance_position"]
        assert r["min_clearance"] > 0 and r["rms_position_error"] is not None
    assert robots[""]["goal"][1] == pytest.approx(-6.0, abs=1e-6)       # the scenario's goal
    assert robots["bumble"]["goal"][1] > robots[""]["goal"][1] + 0.5     # behind, in formation
    assert (run / "plot.png").stat().st_size > 10_000
    msgs = mcap_messages(run / "bag")
    for topic in ("/gnc/ctl/segment", "/bumble/gnc/ctl/segment", "/gnc/ctl/command",
                  "/bumble/gnc/ctl/command", "/bumble/mob/state"):
        assert msgs.get(topic), f"nothing on {topic}"
    a, b = msgs["/gnc/ctl/segment"][-1], msgs["/bumble/gnc/ctl/segment"][-1]
    assert (a.header.stamp.sec, a.header.stamp.nanosec) == (b.header.stamp.sec, b.header.stamp.nanosec)
    assert msgs["/sim/bag/state"][-1].attached == [True, True]         # both handles held
    assert not [f for t in ("/sim/fault", "/bumble/sim/fault") for f in msgs.get(t, []) if f.active]
    for pid in pids.values():
        assert not pid_alive(pid)


def test_killing_one_robots_controller_fails_the_leg_and_names_it(tmp_path, config_dir,  # noqa: F811
                                                                     launches):  # noqa: F811
    run = tmp_path / "run"
    # quiet flight mode: a slow formation (minutes of sim), so the flight cannot end before the
    # kill even when the log lines reach this test late; lockstep_timeout: once bumble's
    # controller is gone the sim steps on every 0.05 s
    launch = Launch(run, config_dir, "scenario:=two_robots_bag", "flight_mode:=quiet",
                    "lockstep_timeout:=0.05")
    launches.append(launch)
    launch.read_until(r"\[bumble/pd_controller_node\].*CONTROLLING: segment", timeout=180.0)
    pids = launch.child_pids()
    os.killpg(pids["bumble/pd_controller_node"], signal.SIGKILL)
    code = launch.wait(timeout=120.0)
    assert code != 0
    for pid in pids.values():
        assert not pid_alive(pid)
    summary = json.loads((run / "summary.json").read_text())
    assert not summary["success"]
    assert "bumble" in summary["reason"] and "propulsion_watchdog" in summary["reason"], \
        summary["reason"]
    robots = {r["name"]: r for r in summary["robots"]}
    assert not robots["bumble"]["success"]
    assert any("propulsion_watchdog" in f for f in robots["bumble"]["faults"])
    assert robots["bumble"]["failed_at"]["why"].startswith("fault")
    assert robots[""]["faults"] == []            # the other robot is not blamed for the fault
    assert any(f.startswith("robot bumble:") for f in summary["faults"])
    msgs = mcap_messages(run / "bag")
    assert [f for f in msgs.get("/bumble/sim/fault", []) if f.active]
