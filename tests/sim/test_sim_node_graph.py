"""sim_node in its own process (router + sim + this test: three processes)."""
import math
import subprocess
import time

import numpy as np
import pytest

roszen = pytest.importorskip("roszen")
from roszen import testing  # noqa: E402

pytestmark = pytest.mark.graph

TOPICS = {
    "/clock": "rosgraph_msgs/msg/Clock",
    "/loc/truth/pose": "geometry_msgs/msg/PoseStamped",
    "/loc/truth/twist": "geometry_msgs/msg/TwistStamped",
    "/gnc/ekf": "astrobee_msgs/msg/EkfState",
    "/tf": "tf2_msgs/msg/TFMessage",
    "/sim/bag/state": "astrobee_msgs/msg/BagState",
    "/sim/bag/mesh": "astrobee_msgs/msg/BagMesh",
    "/sim/contacts": "astrobee_msgs/msg/Contacts",
    "/sim/markers": "visualization_msgs/msg/MarkerArray",
    "/mob/flight_mode": "astrobee_msgs/msg/FlightMode",
    "/sim/fault": "astrobee_msgs/msg/Fault",
}
LATCHED = {"/sim/markers", "/mob/flight_mode", "/sim/fault"}


class Graph:
    """A router, one sim_node process and a test node in this process."""

    def __init__(self, port, *params):
        self.env = testing.zenoh_env(port)
        args = ["-m", "astrobee_sim.sim_node", "--ros-args"]
        for p in params:
            args += ["-p", p]
        self.sim = testing.spawn(testing.python_cmd(*args), self.env)
        self.ctx = roszen.Context(env=self.env)
        self.node = roszen.Node("sim_test", context=self.ctx)

    def spin_until(self, cond, timeout=20.0):
        end = time.monotonic() + timeout
        while not cond():
            if time.monotonic() > end:
                return False
            if self.sim.poll() is not None:
                raise AssertionError(f"sim_node exited {self.sim.returncode}: {self.sim.stderr.read()[-2000:]}")
            self.node.spin_once(timeout_sec=0.02)
        return True

    def call(self, srv_type, name, **fields):
        cli = self.node.create_client(srv_type, name)
        assert cli.wait_for_service(timeout_sec=15.0), name
        req = roszen.request_class(srv_type)()
        for k, v in fields.items():
            setattr(req, k, v)
        fut = cli.call_async(req)
        self.spin_until(fut.done, 15.0)
        return fut.result()

    def close(self):
        try:
            self.node.destroy_node()
            self.ctx.shutdown()
        finally:
            testing.stop(self.sim)


@pytest.fixture
def graph():
    made = []
    with testing.router() as port:
        def make(*params):
            g = Graph(port, *params)
            made.append(g)
            return g
        try:
            yield make
        finally:
            for g in made:
                g.close()


def test_every_topic_with_its_type(graph):
    g = graph("scenario:=node2_to_jem_bag", "bag_model:=fem", "bag_resolution:=200",
              "clock_mode:=fast", "mesh_rate:=10.0")
    got = {}
    for topic, typ in TOPICS.items():
        qos = roszen.LATCHED if topic in LATCHED else 10
        g.node.create_subscription(typ, topic, lambda m, t=topic: got.setdefault(t, m), qos)
    assert g.spin_until(lambda: len(got) == len(TOPICS), 40.0), f"missing {set(TOPICS) - set(got)}"
    for topic, typ in TOPICS.items():
        assert type(got[topic]).__name__ == typ.split("/")[-1], topic
    pose = got["/loc/truth/pose"].pose.position
    assert abs(pose.x - 10.95) < 0.2 and abs(pose.y) < 0.2 and abs(pose.z - 4.84) < 0.2
    assert got["/loc/truth/pose"].header.frame_id == "world"
    bag = got["/sim/bag/state"]
    assert bag.model == "fem" and list(bag.attached) == [True]
    mesh = got["/sim/bag/mesh"]
    assert mesh.num_nodes > 150 and len(mesh.positions) == 3 * mesh.num_nodes
    assert np.all(np.isfinite(np.asarray(mesh.positions)))
    assert len(got["/sim/markers"].markers) == 26 + 7
    assert got["/mob/flight_mode"].name == "nominal" and got["/mob/flight_mode"].speed == 2
    children = {t.child_frame_id for t in got["/tf"].transforms}
    assert {"body", "bag"} <= children
    assert got["/sim/contacts"].robot_clearance > 0
    # no controller: the watchdog reports a fault
    faults = []
    g.node.create_subscription("astrobee_msgs/msg/Fault", "/sim/fault", faults.append, roszen.LATCHED)
    assert g.spin_until(lambda: any(f.active for f in faults), 20.0)


def _publish_wrench(g, pub, wrench, stamp_ns=0):
    m = roszen.message_class("astrobee_msgs/msg/FamCommand")()
    m.header.stamp.sec, m.header.stamp.nanosec = stamp_ns // 10**9, stamp_ns % 10**9
    (m.wrench.force.x, m.wrench.force.y, m.wrench.force.z,
     m.wrench.torque.x, m.wrench.torque.y, m.wrench.torque.z) = wrench
    pub.publish(m)


def test_command_from_another_process_moves_the_robot_and_bad_input(graph):
    g = graph("scenario:=node2_to_jem", "clock_mode:=realtime")
    poses = []
    g.node.create_subscription("geometry_msgs/msg/PoseStamped", "/loc/truth/pose",
                               lambda m: poses.append((m.pose.position.x, m.pose.position.y,
                                                       m.pose.position.z)), 10)
    pub = g.node.create_publisher("astrobee_msgs/msg/FamCommand", "/gnc/ctl/command", 10)
    assert g.spin_until(lambda: len(poses) > 5, 20.0)
    # bad commands first: NaN, inf, absurd; the robot must stay put and finite
    for bad in ([math.nan, 0, 0, 0, 0, 0], [0, math.inf, 0, 0, 0, 0], [1e7, 0, 0, 0, 0, 0]):
        for _ in range(5):
            _publish_wrench(g, pub, bad)
            g.spin_until(lambda: False, 0.03)
    g.spin_until(lambda: False, 0.3)
    p0 = np.array(poses[-1])
    assert np.all(np.isfinite(p0)) and abs(p0[1]) < 0.01
    # then a real one: body +x is world -y in this scenario
    end = time.monotonic() + 2.5
    while time.monotonic() < end:
        _publish_wrench(g, pub, [0.6, 0, 0, 0, 0, 0])
        g.spin_until(lambda: False, 0.016)
    p1 = np.array(poses[-1])
    assert p1[1] < p0[1] - 0.05, (p0, p1)
    assert abs(p1[0] - p0[0]) < 0.02 and abs(p1[2] - p0[2]) < 0.02
    # bad service requests get a failure response
    r = g.call("astrobee_msgs/srv/Reset", "/sim/reset", scenario="no_such_scenario", seed=0)
    assert not r.success and "no_such_scenario" in r.message
    r = g.call("astrobee_msgs/srv/SetFlightMode", "/sim/set_flight_mode", flight_mode="warp")
    assert not r.success and "warp" in r.message
    r = g.call("astrobee_msgs/srv/SetFlightMode", "/sim/set_flight_mode", flight_mode="quiet")
    assert r.success
    # pause + step: sim time advances by exactly the steps asked
    r0 = g.call("astrobee_msgs/srv/SimControl", "/sim/control", command=0)
    r1 = g.call("astrobee_msgs/srv/SimControl", "/sim/control", command=2, steps=35)
    t0 = r0.sim_time.sec + r0.sim_time.nanosec * 1e-9
    t1 = r1.sim_time.sec + r1.sim_time.nanosec * 1e-9
    assert r0.success and r1.success and abs(t1 - t0 - 0.1) < 1e-6
    r = g.call("astrobee_msgs/srv/Reset", "/sim/reset", scenario="node2_to_jem_bag", seed=3)
    assert r.success
    g.sim.terminate()
    out, err = g.sim.communicate(timeout=10)
    assert "command rejected" in out + err


def _lockstep_stream(graph, ticks=40):
    g = graph("scenario:=node2_to_jem_bag", "bag_model:=composite", "clock_mode:=lockstep",
              "seed:=5", "lockstep_timeout:=5.0")
    states = []
    pub = g.node.create_publisher("astrobee_msgs/msg/FamCommand", "/gnc/ctl/command", 10)

    def on_ekf(m):
        s = m.header.stamp
        if states and states[-1][0] == s.sec * 10**9 + s.nanosec:
            return      # a republished state we already answered
        states.append((s.sec * 10**9 + s.nanosec, m.pose.position.x, m.pose.position.y,
                       m.pose.position.z, m.velocity.y, m.omega.z))
        # a state-dependent command so any divergence would grow
        _publish_wrench(g, pub, [0.5 - 2.0 * m.velocity.y, 0.1, 0, 0, 0, 0.01 - m.omega.z],
                        s.sec * 10**9 + s.nanosec)
    g.node.create_subscription("astrobee_msgs/msg/EkfState", "/gnc/ekf", on_ekf, 50)
    assert g.spin_until(lambda: len(states) >= ticks, 60.0)
    testing.stop(g.sim)
    return np.array(states[:ticks])


def test_lockstep_is_deterministic(graph):
    a = _lockstep_stream(graph)
    b = _lockstep_stream(graph)
    # ticks 16 ms apart, starting where the sim started, no tick missed
    assert np.allclose(np.diff(a[:, 0]), 16e6, atol=3e6)
    assert abs(a[-1, 2] - a[0, 2]) > 1e-3                      # the robot moved
    # the sim waited for our first command: both streams start at t=0 and match exactly
    assert a[0, 0] == 0 and b[0, 0] == 0
    assert np.array_equal(a, b)


@pytest.mark.parametrize("params,env,needle", [
    (["bag_variant:=sideways", "scenario:=node2_to_jem_bag"], {}, "sideways"),
    (["scenario:=nowhere"], {}, "nowhere"),
    ([], {"ASTROBEE_CONFIG_DIR": "/nonexistent/config"}, "not found"),
])
def test_bad_startup_exits_with_one_line(params, env, needle):
    args = ["-m", "astrobee_sim.sim_node", "--ros-args"]
    for p in params:
        args += ["-p", p]
    e = testing.zenoh_env(testing.free_port())
    e.update(env)
    r = subprocess.run(testing.python_cmd(*args), env=e, capture_output=True, text=True, timeout=60)
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert r.returncode != 0
    assert any(needle in ln and ln.startswith("sim_node: error:") for ln in lines), r.stderr
    assert not any("Traceback" in ln for ln in lines)


def test_two_robots_each_under_its_namespace(graph):
    g = graph("scenario:=two_robots_bag", "bag_model:=constraint", "clock_mode:=fast")
    got = {}
    for topic, typ in (("/loc/truth/pose", "geometry_msgs/msg/PoseStamped"),
                       ("/bumble/loc/truth/pose", "geometry_msgs/msg/PoseStamped"),
                       ("/bumble/gnc/ekf", "astrobee_msgs/msg/EkfState"),
                       ("/bumble/mob/flight_mode", "astrobee_msgs/msg/FlightMode"),
                       ("/sim/bag/state", "astrobee_msgs/msg/BagState")):
        qos = roszen.LATCHED if topic.endswith("flight_mode") else 10
        g.node.create_subscription(typ, topic, lambda m, t=topic: got.setdefault(t, m), qos)
    assert g.spin_until(lambda: len(got) == 5, 30.0), set(got)
    a, b = got["/loc/truth/pose"].pose.position, got["/bumble/loc/truth/pose"].pose.position
    assert abs(a.y - b.y) > 0.5                        # on either side of the bag
    assert list(got["/sim/bag/state"].attached) == [True, True]
    assert got["/bumble/gnc/ekf"].child_frame_id == "bumble/body"
    r = g.call("astrobee_msgs/srv/SetFlightMode", "/bumble/mob/set_flight_mode", flight_mode="quiet")
    assert r.success
    modes = []
    g.node.create_subscription("astrobee_msgs/msg/FlightMode", "/bumble/mob/flight_mode",
                               modes.append, roszen.LATCHED)
    assert g.spin_until(lambda: any(m.name == "quiet" for m in modes), 10.0)


def test_lockstep_drops_commands_from_before_a_reset(graph):
    """A command answering a pre-reset state must not let lockstep run ahead unanswered."""
    g = graph("scenario:=node2_to_jem", "clock_mode:=lockstep", "lockstep_timeout:=30.0")
    pub = g.node.create_publisher("astrobee_msgs/msg/FamCommand", "/gnc/ctl/command", 10)
    answering = [True]
    stamps = []

    def on_ekf(m):
        t = m.header.stamp.sec * 10**9 + m.header.stamp.nanosec
        stamps.append(t)
        if answering[0]:
            _publish_wrench(g, pub, [0.1, 0, 0, 0, 0, 0], t)
    g.node.create_subscription("astrobee_msgs/msg/EkfState", "/gnc/ekf", on_ekf, 50)
    assert g.spin_until(lambda: stamps and stamps[-1] >= 700_000_000, 60.0)
    answering[0] = False
    stale = stamps[-1]                                     # ~0.7 s: a state from before the reset
    r = g.call("astrobee_msgs/srv/Reset", "/sim/reset", scenario="", seed=0)
    assert r.success
    stamps.clear()
    for stale_ns in (stale, 300_000_000):                  # far ahead (dropped), slightly ahead
        for _ in range(3):
            _publish_wrench(g, pub, [0.1, 0, 0, 0, 0, 0], stale_ns)
            g.spin_until(lambda: False, 0.05)
    g.spin_until(lambda: False, 1.5)
    # the sim may take one tick on the slightly-ahead command, never run on to its stamp
    assert stamps and max(stamps) < 20_000_000, max(stamps)      # at most one tick (17.1 ms)
    # answering again, it steps on
    answering[0] = True
    _publish_wrench(g, pub, [0.1, 0, 0, 0, 0, 0], max(stamps))
    assert g.spin_until(lambda: max(stamps) >= 100_000_000, 30.0)
    g.sim.terminate()
    out, err = g.sim.communicate(timeout=10)
    assert "ahead of sim time" in out + err


def _latest_scenario(g):
    infos = []
    g.node.create_subscription("astrobee_msgs/msg/ScenarioInfo", "/sim/scenario", infos.append,
                               roszen.LATCHED)
    return infos


def test_bad_reset_is_refused_and_the_old_world_runs_on(graph):
    """A bad /sim/reset (negative seed, a path for a name, an unknown
    scenario) gets success false and the sim keeps publishing the world it had."""
    import yaml

    from astrobee.scenario import Scenario
    g = graph("scenario:=node2_to_jem", "clock_mode:=realtime", "seed:=2")
    infos = _latest_scenario(g)
    poses = []
    g.node.create_subscription("geometry_msgs/msg/PoseStamped", "/loc/truth/pose",
                               lambda m: poses.append((m.header.stamp.sec * 10**9 + m.header.stamp.nanosec,
                                                       m.pose.position.x, m.pose.position.y)), 10)
    assert g.spin_until(lambda: infos and len(poses) > 5, 30.0)
    info = infos[-1]
    assert info.name == "node2_to_jem" and info.seed == 2 and list(info.robots) == [""]
    assert info.has_goal and not info.carrying_bag and info.flight_mode == "nominal"
    assert Scenario.from_dict(yaml.safe_load(info.yaml), info.name) == Scenario.load("node2_to_jem")
    for scenario, seed, needle in (("node2_to_jem_bag", -1, "seed"), ("../etc/passwd", 0, "scenario name"),
                                   ("/etc/passwd", 0, "scenario name"),
                                   ("no_such_scenario", 0, "no_such_scenario")):
        r = g.call("astrobee_msgs/srv/Reset", "/sim/reset", scenario=scenario, seed=seed)
        assert not r.success and needle in r.message, (scenario, r.message)
        assert "root:" not in r.message                # nothing of the file echoed
    t_refused = poses[-1][0]
    assert g.spin_until(lambda: poses[-1][0] > t_refused + 200_000_000, 20.0)   # time runs on
    assert g.sim.poll() is None
    stamps = [t for t, _, _ in poses]
    assert stamps == sorted(stamps)                     # never restarted: no reset happened
    assert abs(poses[-1][1] - 10.95) < 0.05 and abs(poses[-1][2]) < 0.05   # the same robot
    assert len(infos) == 1                              # the scenario was not republished
    r = g.call("astrobee_msgs/srv/Reset", "/sim/reset", scenario="node2_to_jem_bag", seed=4)
    assert r.success
    assert g.spin_until(lambda: infos[-1].name == "node2_to_jem_bag", 10.0)
    info = infos[-1]
    assert info.seed == 4 and info.carrying_bag and info.bag_model == "rigid" and info.bag_nodes == 1
    assert abs(info.bag_mass - 10.0) < 1e-9 and info.carry_extent > 0
    assert abs(info.bag_size.x - 0.50) < 1e-9


def test_rigid_backend_serves_the_robot_topics(graph):
    g = graph("backend:=rigid", "scenario:=node2_to_jem_bag", "bag_mass:=12.5", "clock_mode:=fast")
    got = {}
    topics = {k: v for k, v in TOPICS.items() if k != "/sim/bag/mesh"}
    topics["/sim/scenario"] = "astrobee_msgs/msg/ScenarioInfo"
    for topic, typ in topics.items():
        qos = roszen.LATCHED if topic in LATCHED | {"/sim/scenario"} else 10
        g.node.create_subscription(typ, topic, lambda m, t=topic: got.setdefault(t, m), qos)
    assert g.spin_until(lambda: len(got) == len(topics), 30.0), f"missing {set(topics) - set(got)}"
    pose = got["/loc/truth/pose"].pose.position
    assert abs(pose.x - 10.95) < 0.01 and abs(pose.y) < 0.01 and abs(pose.z - 4.84) < 0.01
    assert got["/sim/scenario"].bag_mass == 12.5 and got["/sim/scenario"].carrying_bag
    assert list(got["/sim/bag/state"].attached) == [True]
    assert got["/sim/contacts"].robot_clearance > 0 and got["/sim/contacts"].bag_clearance > 0
    faults = []
    g.node.create_subscription("astrobee_msgs/msg/Fault", "/sim/fault", faults.append, roszen.LATCHED)
    assert g.spin_until(lambda: any(f.active for f in faults), 20.0)      # the watchdog, no controller


@pytest.mark.parametrize("param,needle", [
    ("mesh_rate:=0", "mesh_rate"), ("publish_rate:=0.000001", "publish_rate"),
    ("bag_resolution:=10000000", "bag_resolution"), ("bag_resolution:=-5", "bag_resolution"),
    ("max_sim_time:=-1", "max_sim_time"), ("fem_solver:=warp", "fem_solver"),
    ("bag_model:=nonsense", "bag_model"), ("backend:=ode", "backend"),
])
def test_bad_parameter_exits_1_with_one_line_naming_it(param, needle):
    args = ["-m", "astrobee_sim.sim_node", "--ros-args", "-p", param]
    e = testing.zenoh_env(testing.free_port())
    r = subprocess.run(testing.python_cmd(*args), env=e, capture_output=True, text=True, timeout=60)
    lines = [ln for ln in r.stderr.splitlines() if ln.startswith("sim_node: error:")]
    assert r.returncode == 1, r.stderr
    assert len(lines) == 1 and needle in lines[0], r.stderr
    assert "Traceback" not in r.stderr
