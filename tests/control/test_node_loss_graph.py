"""controller_node's parameters and peer-loss watch, in a lockstep loop with sim_node (rigid
backend) in other processes: `astrobee param set` refuses read-only,
non-finite and out-of-range values with a reason and applies run-time ones; a sim killed with
SIGKILL is reported as a lost node on /mob/state and in one log line, and commanding stops."""
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from astrobee import rotations as rot
from astrobee_control.reference import rest_to_rest
from test_pd_node_graph import DT, graph, segment_msg  # noqa: F401  (graph: the fixture)

roszen = pytest.importorskip("roszen")
from roszen import testing  # noqa: E402

pytestmark = pytest.mark.graph
ASTROBEE = str(Path(sys.executable).parent / "astrobee")
CTL = "/pd_controller_node"


def param_set(env, node, name, value):
    r = subprocess.run([ASTROBEE, "param", "set", node, name, value], env=env,
                       capture_output=True, text=True, timeout=60)
    return r.returncode, (r.stdout + r.stderr).strip()


def spin_wall(sim, seconds, until=lambda: False):
    """Spin the test node for `seconds` of wall time (or until `until()`), whatever the sim does."""
    end = time.monotonic() + seconds
    while time.monotonic() < end and not until():
        sim.node.spin_once(timeout_sec=0.02)
    return until()


def sim_control(sim, command):
    cli = sim.node.create_client("astrobee_msgs/srv/SimControl", "/sim/control")
    assert cli.wait_for_service(timeout_sec=10.0)
    req = roszen.request_class("astrobee_msgs/srv/SimControl")()
    req.command = command
    fut = cli.call_async(req)
    assert spin_wall(sim, 30.0, fut.done)
    assert fut.result().success, fut.result().message


def test_param_set_refuses_read_only_and_bad_values_and_applies_runtime_ones(graph):
    sim = graph(np.zeros(3), rot.IDENTITY)
    sim.commanded()
    env = sim.env
    rc, out = param_set(env, CTL, "state_source", "truth")
    assert rc == 1 and "parameter 'state_source' is read-only" in out, out
    rc, out = param_set(env, "/sim_node", "publish_rate", "10.0")
    assert rc == 1 and "parameter 'publish_rate' is read-only" in out, out
    for bad in (".nan", "nan", "-1.0", ".inf"):
        rc, out = param_set(env, CTL, "settle_time", bad)
        assert rc == 1 and "settle_time" in out, (bad, out)
    rc, out = param_set(env, CTL, "flight_mode", "warp")
    assert rc == 1 and "warp" in out, out
    assert param_set(env, CTL, "settle_time", "2.5") == (0, "Set parameter successful")
    # a run-time parameter changes what the node does: with the sim paused, the stall is
    # reported after the new state_timeout
    assert param_set(env, CTL, "state_timeout", "0.3") == (0, "Set parameter successful")
    sim_control(sim, 0)                                   # pause
    assert spin_wall(sim, 20.0, lambda: any("for 0.3 s (wall)" in e for _, e in sim.states)), \
        sim.states
    n = len(sim.states)
    sim_control(sim, 1)                                   # resume: the loop goes on
    t = sim.t
    sim.spin_until(lambda: sim.t > t + 0.5, 30.0)
    assert not any("lost" in e for _, e in sim.states[n:])


def test_killed_sim_is_reported_and_commanding_stops(graph):
    p0 = np.zeros(3)
    sim = graph(p0, rot.IDENTITY)
    sim.commanded()
    sim.seg_pub.publish(segment_msg(rest_to_rest(p0, p0 + [1.0, 0, 0], rot.IDENTITY,
                                                 rot.IDENTITY, 60.0)))
    sim.run_for(3.0, until=lambda: any(s == 9 for s, _ in sim.states))
    sim.run_for(20 * DT)
    sim_proc, ctl_proc = sim.procs
    testing.kill9(sim_proc)
    lost = lambda: [e for _, e in sim.states if e.startswith("lost node")]  # noqa: E731
    assert spin_wall(sim, 20.0, lambda: bool(lost())), sim.states[-5:]
    assert lost()[0] == "lost node sim_node: no publisher of /gnc/ekf"
    assert sim.states[-1][0] == 4                                 # STOPPING: holding
    spin_wall(sim, 0.3)
    n = len(sim.forces)
    spin_wall(sim, 1.0)
    assert len(sim.forces) == n, "commands after the sim was lost"
    assert ctl_proc.poll() is None                                # the controller lives on
    ctl_proc.terminate()
    _, err = ctl_proc.communicate(timeout=10)
    lines = [ln for ln in err.splitlines() if "lost node sim_node" in ln]
    assert len(lines) == 1, err[-2000:]
