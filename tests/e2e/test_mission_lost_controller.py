"""The mission notices a flying robot's controller killed outside the launcher (kill -9) by the
graph: the leg fails naming it ("lost node pd_controller_node"), in bounded time, instead of
waiting out its 600 s timeout (issue 19.8). Router, sim_node (rigid backend, lockstep),
planner, PD controller and the mission, each its own process; nothing left behind."""
from __future__ import annotations

import json
import time

import pytest

roszen = pytest.importorskip("roszen")
from roszen import testing  # noqa: E402

pytestmark = pytest.mark.graph


def test_killed_controller_fails_the_leg_naming_it(tmp_path):
    run = tmp_path / "run"
    with testing.router() as port:
        env = testing.zenoh_env(port)
        ctl = testing.spawn(testing.python_cmd("-m", "astrobee_control.pd_controller_node",
                                               "--ros-args", "-p", "use_sim_time:=true"), env)
        procs = [ctl, testing.spawn(testing.python_cmd(
            "-m", "astrobee_sim.sim_node", "--ros-args", "-p", "backend:=rigid",
            "-p", "scenario:=node2_to_jem", "-p", "clock_mode:=lockstep",
            "-p", "lockstep_timeout:=20.0", "-p", "lockstep_start_timeout:=120.0"), env),
            testing.spawn(testing.python_cmd("-m", "astrobee_planning.planner_node"), env)]
        mission = testing.spawn(testing.python_cmd(
            "-m", "astrobee_bringup.mission", "--scenario", "node2_to_jem", "--run-dir", str(run)),
            env)
        ctx = roszen.Context(env=env)
        node = roszen.Node("mission_lost_controller_test", context=ctx)
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
            testing.kill9(ctl)
            out, err = mission.communicate(timeout=120)  # far below the 600 s leg timeout
            assert mission.returncode == 1, out[-2000:] + err[-2000:]
            leg = json.loads((run / "summary.json").read_text())["legs"][0]
            assert not leg["success"]
            assert leg["reason"].startswith("lost node pd_controller_node"), leg["reason"]
            assert "lost node pd_controller_node" in out.strip().splitlines()[-1]   # the last line
        finally:
            node.destroy_node()
            ctx.shutdown()
            for p in [mission, *procs]:
                testing.stop(p)
