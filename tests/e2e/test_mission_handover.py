"""The mission's deterministic hand-over outside the launcher: sim_node (rigid
backend, lockstep, start_paused), planner, PD controller, a recorder and `mission --handover
--await-recorder`, each its own process. The sim publishes no state until the mission's reset,
then exactly one pose per tick from t=0 to the chunk end at which the leg ended (nothing after:
the sim stays paused), and a RESUME asking for more steps than one request may is refused."""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

roszen = pytest.importorskip("roszen")
from roszen import testing  # noqa: E402

pytestmark = pytest.mark.graph


def test_handover_records_one_pose_per_tick_from_zero_to_the_legs_end(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    py = sys.executable
    procs = []
    with testing.router() as port:
        env = testing.zenoh_env(port)
        try:
            for argv in ([py, "-m", "astrobee_sim.sim_node", "--ros-args", "-p", "backend:=rigid",
                          "-p", "scenario:=node2_to_jem", "-p", "clock_mode:=lockstep",
                          "-p", "start_paused:=true", "-p", "lockstep_timeout:=60.0"],
                         [py, "-m", "astrobee_planning.planner_node"],
                         [py, "-m", "astrobee_control.pd_controller_node", "--ros-args",
                          "-p", "use_sim_time:=true"],
                         [py, "-m", "astrobee_bringup.cli", "bag", "record", "-a",
                          "--use-sim-time", "-o", str(run / "bag")]):
                procs.append(testing.spawn(argv, env, stdout=subprocess.DEVNULL,
                                           stderr=subprocess.DEVNULL))
            mission = subprocess.run([py, "-m", "astrobee_bringup.mission", "--scenario",
                                      "node2_to_jem", "--run-dir", str(run), "--handover",
                                      "--await-recorder", "--timeout", "300"], env=env,
                                     capture_output=True, text=True, timeout=400)
            assert mission.returncode == 0, mission.stdout[-2000:] + mission.stderr[-2000:]
            # one request may not ask for more steps than the sim's bound: refused, nothing run
            ctx = roszen.Context(env=env)
            node = roszen.Node("handover_test", context=ctx)
            try:
                cli = node.create_client("astrobee_msgs/srv/SimControl", "/sim/control")
                assert cli.wait_for_service(timeout_sec=30.0)
                req = roszen.request_class("astrobee_msgs/srv/SimControl")()
                req.command, req.steps = 1, 4294967295
                fut = cli.call_async(req)
                while not fut.done():
                    node.spin_once(timeout_sec=0.05)
                assert not fut.result().success and "steps" in fut.result().message
            finally:
                node.destroy_node()
                ctx.shutdown()
        finally:
            for p in reversed(procs):
                testing.stop(p, timeout=5.0)
    leg = json.loads((run / "summary.json").read_text())
    assert leg["success"], leg["reason"]
    from roszen import typestore
    from roszen.bag.reader import BagReader
    stamps = [typestore.deserialize(m.data, m.topic.type).header.stamp
              for m in BagReader(run / "bag").messages(["/loc/truth/pose"])]
    t = np.array([s.sec * 1_000_000_000 + s.nanosec for s in stamps], np.int64)
    assert t[0] == 0 and np.all(np.diff(t) > 0)           # from the reset, one per tick
    ticks = np.round(t / 1e9 * 62.5)                         # 62.5 Hz ticks: none missing
    assert np.array_equal(ticks, np.arange(len(t)))
    # the leg ended at a chunk end after the robot stopped; the sim published nothing after it
    assert leg["sim_t1"] == pytest.approx(t[-1] / 1e9, abs=1e-9)
    assert t[-1] / 1e9 >= leg["plan_duration"] + 1.0         # the hand-over lead and the plan
