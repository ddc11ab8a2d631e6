"""planner_node in its own process (router + planner_node + the test process as client):
global and local plans, bad requests answered with codes, and the node keeps serving."""
import numpy as np
import pytest

from astrobee import config
from astrobee import rotations as rot

roszen = pytest.importorskip("roszen")
from roszen import testing  # noqa: E402

from astrobee_planning import conversions as cv  # noqa: E402
from astrobee_planning import planner  # noqa: E402

pytestmark = pytest.mark.graph


@pytest.fixture
def planner_proc(router_env):
    p = testing.spawn(testing.python_cmd("-m", "astrobee_planning.planner_node", "--ros-args",
                                         "-p", "sample_rate:=2.0"), router_env)
    try:
        yield p
    finally:
        testing.stop(p)


@pytest.fixture
def client_node(router_env):
    node = roszen.Node("planner_test_client")
    try:
        yield node
    finally:
        node.destroy_node()


def _global_req(start, goal, qs=rot.IDENTITY, qg=rot.IDENTITY, **kw):
    req = roszen.request_class("astrobee_msgs/srv/PlanGlobal")()
    cv.set_pose(req.start, np.asarray(start, float), np.asarray(qs, float))
    cv.set_pose(req.goal, np.asarray(goal, float), np.asarray(qg, float))
    req.flight_mode = kw.get("flight_mode", "nominal")
    req.face_forward = kw.get("face_forward", False)
    req.sample_rate = kw.get("sample_rate", 0.0)
    return req


def test_planner_node_serves_and_survives_bad_requests(planner_proc, client_node):
    cli = client_node.create_client("astrobee_msgs/srv/PlanGlobal", "/mob/planner/global")
    assert cli.wait_for_service(timeout_sec=30.0), "planner service never appeared"
    latched = roszen.QoSProfile(depth=1, durability=roszen.Durability.TRANSIENT_LOCAL)
    paths = []
    client_node.create_subscription("nav_msgs/msg/Path", "/mob/planner/path", paths.append, latched)

    n2, jem = config.waypoint("node_2"), config.waypoint("jem")
    q1 = rot.from_euler(0, 0, 1.0)
    resp = cli.call(_global_req(n2, jem, qg=q1), timeout_sec=60.0)
    assert resp.success and resp.code == planner.SUCCESS, resp.message
    st = cv.msgs_to_states(resp.segment)
    assert np.allclose(np.diff(st.t[:-1]), 0.5) and abs(st.t[-1] - resp.duration) < 1e-6
    np.testing.assert_allclose(st.pos[0], n2, atol=1e-6)
    np.testing.assert_allclose(st.pos[-1], jem, atol=1e-6)
    assert rot.angle_between(st.quat[-1], q1) < 1e-6
    # the exact spline in the response reproduces the sampled segment
    tr = cv.trajectory_from_msgs(resp.position_spline, resp.attitude_spline)
    st2 = tr.sample(st.t)
    np.testing.assert_allclose(st2.pos, st.pos, atol=1e-9)
    np.testing.assert_allclose(st2.vel, st.vel, atol=1e-9)
    assert resp.planning_time > 0

    bad = [
        (_global_req([0, 0, 0], jem), planner.VIOLATES_KEEP_IN),
        (_global_req([float("nan"), 0, 4.8], jem), planner.INVALID_COMMAND),
        (_global_req(n2, jem, qg=[0, 0, 0, 3.0]), planner.INVALID_COMMAND),
        (_global_req(n2, jem, flight_mode="ludicrous"), planner.INVALID_FLIGHT_MODE),
    ]
    for req, code in bad:
        r = cli.call(req, timeout_sec=30.0)
        assert not r.success and r.code == code and r.message, (code, r.code, r.message)

    # still serving after the bad requests
    r = cli.call(_global_req(jem, n2, sample_rate=1.0), timeout_sec=60.0)
    assert r.success and r.code == planner.SUCCESS

    # local planner
    lcli = client_node.create_client("astrobee_msgs/srv/PlanLocal", "/mob/planner/local")
    assert lcli.wait_for_service(timeout_sec=10.0)
    CS = roszen.message_class("astrobee_msgs/msg/ControlState")
    lreq = roszen.request_class("astrobee_msgs/srv/PlanLocal")()
    a, b = CS(), CS()
    cv.set_pose(a.pose, n2, rot.IDENTITY)
    a.twist.linear.x, a.twist.angular.z, a.accel.linear.y = 0.05, 0.02, 0.001
    cv.set_pose(b.pose, n2 + [0.5, 0, 0], q1)
    lreq.start, lreq.goal, lreq.duration, lreq.sample_rate = a, b, 15.0, 10.0   # within nominal limits
    lr = lcli.call(lreq, timeout_sec=30.0)
    assert lr.success, lr.message
    ls = cv.msgs_to_states(lr.segment)
    assert len(ls) == 151
    np.testing.assert_allclose(ls.vel[0], [0.05, 0, 0], atol=1e-12)
    np.testing.assert_allclose(ls.omega[0], [0, 0, 0.02], atol=1e-12)
    np.testing.assert_allclose(ls.pos[-1], n2 + [0.5, 0, 0], atol=1e-12)
    lreq.duration = -1.0
    lr = lcli.call(lreq, timeout_sec=30.0)
    assert not lr.success and lr.code == planner.INVALID_COMMAND

    # the latched path of the last global plan
    import time
    end = time.monotonic() + 10.0
    while not paths and time.monotonic() < end:
        client_node.spin_once(timeout_sec=0.1)
    assert paths and len(paths[-1].poses) > 2
    last = paths[-1].poses[-1].pose.position
    np.testing.assert_allclose([last.x, last.y, last.z], n2, atol=1e-6)
    assert planner_proc.poll() is None


def _formation_req(starts, goal, names=("", "bumble"), **kw):
    req = roszen.request_class("astrobee_msgs/srv/PlanFormation")()
    req.robots = list(names)
    poses = []
    for p, q in starts:
        m = roszen.message_class("geometry_msgs/msg/Pose")()
        cv.set_pose(m, np.asarray(p, float), np.asarray(q, float))
        poses.append(m)
    req.starts = poses
    cv.set_pose(req.goal, np.asarray(goal[0], float), np.asarray(goal[1], float))
    req.flight_mode = kw.get("flight_mode", "nominal")
    req.sample_rate = kw.get("sample_rate", 2.0)
    req.start_time.sec = kw.get("start_sec", 0)
    return req


def test_planner_node_serves_formation_plans(planner_proc, client_node):
    """Two robots and a bag Node 2 -> JEM: one segment per robot, same start stamp, the robots
    keep their distance and attitudes in the formation, within the flight mode's speed; bad
    requests get codes and the node keeps serving."""
    from astrobee import flight_modes
    from astrobee.scenario import Scenario

    cli = client_node.create_client("astrobee_msgs/srv/PlanFormation", "/mob/planner/formation")
    assert cli.wait_for_service(timeout_sec=30.0), "formation service never appeared"
    sc = Scenario.load("two_robots_bag")
    starts = [(r.position, r.orientation) for r in sc.robots]
    goal = (sc.goal_position, sc.goal_orientation)
    resp = cli.call(_formation_req(starts, goal, start_sec=7), timeout_sec=60.0)
    assert resp.success and resp.code == planner.SUCCESS, resp.message
    assert list(resp.robots) == ["", "bumble"] and len(resp.segments) == 2 and resp.steps
    a, b = (cv.msgs_to_states(s.segment) for s in resp.segments)
    for seg, st, (p, q) in zip(resp.segments, (a, b), starts):
        assert seg.header.stamp.sec == 7 and abs(st.t[0] - 7.0) < 1e-9
        assert abs(st.t[-1] - 7.0 - resp.duration) < 1e-6
        np.testing.assert_allclose(st.pos[0], p, atol=1e-6)
        assert rot.angle_between(st.quat[0], np.asarray(q)) < 1e-6
        assert np.linalg.norm(st.vel, axis=1).max() <= flight_modes.get("nominal").hard_limit_vel
    np.testing.assert_allclose(a.pos[-1], goal[0], atol=1e-6)
    assert rot.angle_between(a.quat[-1], np.asarray(goal[1])) < 1e-6
    d0 = np.linalg.norm(np.asarray(starts[0][0]) - np.asarray(starts[1][0]))
    np.testing.assert_allclose(np.linalg.norm(a.pos - b.pos, axis=1), d0, atol=1e-6)
    rel = [rot.angle_between(qa, qb) for qa, qb in zip(a.quat, b.quat)]
    np.testing.assert_allclose(rel, rel[0], atol=1e-6)       # attitudes locked together

    outside = [([0.0, 0.0, 0.0], rot.IDENTITY), starts[1]]
    bad = [
        (_formation_req(starts[:1], goal, names=[""]), planner.INVALID_COMMAND),       # one robot
        (_formation_req(starts, goal, names=["", "b", "c"]), planner.INVALID_COMMAND),  # 3 names
        (_formation_req(starts, goal, names=["x", "x"]), planner.INVALID_COMMAND),
        (_formation_req(outside, goal), planner.VIOLATES_KEEP_IN),
        (_formation_req(starts, ([0.0, 0.0, 0.0], rot.IDENTITY)), planner.VIOLATES_KEEP_IN),
        (_formation_req(starts, goal, flight_mode="ludicrous"), planner.INVALID_FLIGHT_MODE),
    ]
    for req, code in bad:
        r = cli.call(req, timeout_sec=30.0)
        assert not r.success and r.code == code and r.message, (code, r.code, r.message)
        assert not r.segments
    r = cli.call(_formation_req(starts, goal), timeout_sec=60.0)
    assert r.success and planner_proc.poll() is None
