"""Bounded planner requests: a local plan of 1e5 s returned a million states,
a goal 1e9 m away succeeded. The library rejects them with one-line ValueErrors; the node
answers with a failure code and keeps serving."""
import time

import numpy as np
import pytest

from astrobee import config
from astrobee import rotations as rot
from astrobee_planning import boxes, local_planner, planner, trajectory

N2 = np.array(config.iss()["waypoints"]["node_2"], float)
Z = np.zeros(3)


def _state(p, q=rot.IDENTITY, v=Z, w=Z) -> dict:
    return {"pos": np.asarray(p, float), "vel": np.asarray(v, float), "acc": Z, "quat": q,
            "omega": np.asarray(w, float), "alpha": Z}


def test_local_duration_is_bounded():
    with pytest.raises(ValueError, match="longer than the 600 s"):
        local_planner.plan(_state(N2), _state(N2 + [0.5, 0, 0]), 1e5)
    with pytest.raises(ValueError, match="longer than"):
        local_planner.plan_within_limits(_state(N2), _state(N2 + [0.5, 0, 0]), 1e5)
    tr = local_planner.plan_within_limits(_state(N2), _state(N2 + [0.5, 0, 0]), local_planner.MAX_DURATION)
    assert tr.duration == local_planner.MAX_DURATION


def test_local_goal_far_away_or_path_through_a_wall_is_rejected():
    with pytest.raises(boxes.OutsideSafeSet, match="goal .* outside the station's keep-in"):
        local_planner.plan_within_limits(_state(N2), _state(N2 + [1e9, 0, 0]), 5.0)
    with pytest.raises(boxes.OutsideSafeSet, match="start"):
        local_planner.plan_within_limits(_state(N2 + [0, 0, 50.0]), _state(N2), 5.0)
    cupola = np.array(config.iss()["waypoints"]["cupola"], float)
    with pytest.raises(boxes.OutsideSafeSet, match="leaves the station's keep-in"):
        local_planner.plan_within_limits(_state(N2), _state(cupola), 500.0)


def test_local_duration_too_short_for_the_limits_is_rejected_with_the_shortest_that_does():
    a = _state(N2, v=[0.05, 0, 0], w=[0, 0, 0.02])
    b = _state(N2 + [0.5, 0, 0], rot.from_euler(0, 0, 1.0))
    with pytest.raises(ValueError, match=r"beyond the nominal limit .* at least ([\d.]+) s would do") as err:
        local_planner.plan_within_limits(a, b, 5.0, "nominal")
    need = float(str(err.value).split("at least ")[1].split(" s")[0])
    tr = local_planner.plan_within_limits(a, b, need, "nominal")      # that one is accepted
    pk = tr.peaks(100.0)
    assert pk["acc"] <= 0.0175 * (1 + 1e-6) and pk["vel"] <= 0.2
    with pytest.raises(ValueError, match="does not allow motion"):
        local_planner.plan_within_limits(a, b, 20.0, "off")


def test_state_count_is_bounded():
    assert trajectory.sample_count(5.0, 10.0) == 51
    assert trajectory.sample_count(5.05, 10.0) == 52      # the end is a state
    with pytest.raises(ValueError, match="1000001 states, more than the 100000"):
        trajectory.check_sample_count(1e5, 10.0)
    tr = local_planner.plan(_state(N2), _state(N2 + [0.5, 0, 0]), 20.0)
    assert len(tr.sample_rate(10.0, max_states=201)) == 201
    with pytest.raises(ValueError, match="more than the 200"):
        tr.sample_rate(10.0, max_states=200)
    gp = planner.plan_global(N2, rot.IDENTITY, config.iss()["waypoints"]["jem"], rot.IDENTITY, "nominal")
    with pytest.raises(ValueError, match="lower the sample rate"):
        gp.trajectory.sample_rate(1000.0, max_states=10_000)


# ---- through planner_node -----------------------------------------------------------------
roszen = pytest.importorskip("roszen")
from roszen import testing  # noqa: E402

from astrobee_planning import conversions as cv  # noqa: E402


@pytest.fixture
def planner_client(router_env):
    proc = testing.spawn(testing.python_cmd("-m", "astrobee_planning.planner_node"), router_env)
    node = roszen.Node("planner_bounds_client")
    try:
        cli = node.create_client("astrobee_msgs/srv/PlanLocal", "/mob/planner/local")
        assert cli.wait_for_service(timeout_sec=20.0)
        yield proc, cli
    finally:
        node.destroy_node()
        testing.stop(proc)


@pytest.mark.graph
def test_node_answers_unbounded_local_requests_with_codes(planner_client):
    proc, cli = planner_client
    CS = roszen.message_class("astrobee_msgs/msg/ControlState")

    def request(goal, duration, rate=10.0):
        req = roszen.request_class("astrobee_msgs/srv/PlanLocal")()
        a, b = CS(), CS()
        cv.set_pose(a.pose, N2, rot.IDENTITY)
        cv.set_pose(b.pose, np.asarray(goal, float), rot.IDENTITY)
        req.start, req.goal, req.duration, req.sample_rate = a, b, duration, rate
        t = time.monotonic()
        r = cli.call(req, timeout_sec=30.0)
        return r, time.monotonic() - t

    r, _ = request(N2 + [0.5, 0, 0], 1e5)
    assert not r.success and r.code == planner.INVALID_COMMAND and "600 s" in r.message
    assert len(r.segment) == 0
    r, _ = request(N2 + [0.5, 0, 0], 500.0, rate=1000.0)       # 500,001 states
    assert not r.success and r.code == planner.INVALID_COMMAND and "states" in r.message
    r, _ = request(N2 + [1e9, 0, 0], 5.0)
    assert not r.success and r.code == planner.VIOLATES_KEEP_IN and "\n" not in r.message
    r, _ = request(N2 + [0.5, 0, 0], 5.0)
    assert not r.success and r.code == planner.INVALID_COMMAND and "at least" in r.message
    r, _ = request(N2 + [0.5, 0, 0], 20.0)                       # still serving, bounded
    assert r.success and len(r.segment) == 201
    assert proc.poll() is None
