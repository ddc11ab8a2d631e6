"""The mission notices a peer killed outside the launcher (kill -9) by the graph: the simulator
or the flying robot's controller. The leg fails naming it ("lost node sim_node", "lost node
pd_controller_node ...") in bounded time instead of waiting out its 600 s timeout (issue
19.8). Router, sim_node (rigid backend, lockstep), planner, PD controller and the mission, each
its own process; nothing left behind."""
from __future__ import annotations

import json
import time

import pytest

roszen = pytest.importorskip("roszen")
from roszen import testing  # noqa: E402

pytestmark = pytest.mark.graph


@pytest.mark.parametrize("victim", ["sim_node", "pd_controller_node"])
def test_killed_peer_fails_the_leg_naming_it(tmp_path, victim):
    run = tmp_path / "run"
    with testing.router() as port:
        env = testing.zenoh_env(port)
        peers = {
            "sim_node": testing.spawn(testing.python_cmd(
                "-m", "astrobee_sim.sim_node", "--ros-args", "-p", "backend:=rigid",
                "-p", "scenario:=node2_to_jem", "-p", "clock_mode:=lockstep",
                "-p", "lockstep_timeout:=20.0", "-p", "lockstep_start_timeout:=120.0"), env),
            "planner_node": testing.spawn(testing.python_cmd("-m", "astrobee_planning.planner_node"),
                                          env),
            "pd_controller_node": testing.spawn(testing.python_cmd(
                "-m", "astrobee_control.pd_controller_node", "--ros-args",
                "-p", "use_sim_time:=true"), env)}
        mission = testing.spawn(testing.python_cmd(
            "-m", "astrobee_bringup.mission", "--scenario", "node2_to_jem", "--run-dir", str(run)),
            env)
        ctx = roszen.Context(env=env)
        node = roszen.Node("mission_peers_test", context=ctx)
        try:
            states = []
            node.create_subscription("astrobee_msgs/msg/MotionState", "/mob/state",
                                     lambda m: states.append(int(m.state)),
                                     roszen.QoSProfile(depth=50, durability=roszen.Durability.TRANSIENT_LOCAL))
            end = time.monotonic() + 180.0
            while 9 not in states:                      # CONTROLLING: the leg is flying
                assert mission.poll() is None, mission.communicate()[0][-2000:]
                assert time.monotonic() < end, "the flight never started"
                node.spin_once(timeout_sec=0.05)
            testing.kill9(peers[victim])
            out, err = mission.communicate(timeout=120)  # far below the 600 s leg timeout
            assert mission.returncode == 1, out[-2000:] + err[-2000:]
            leg = json.loads((run / "summary.json").read_text())["legs"][0]
            assert not leg["success"]
            assert leg["reason"].startswith(f"lost node {victim}"), leg["reason"]
            assert f"lost node {victim}" in out.strip().splitlines()[-1]   # the mission's last line
        finally:
            node.destroy_node()
            ctx.shutdown()
            for p in [mission, *peers.values()]:
                testing.stop(p)
