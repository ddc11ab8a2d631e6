import numpy as np
import pytest

from astrobee import config, flight_modes, station
from astrobee import rotations as rot
from astrobee_planning import formation_search, multi_robot, planner

OFF = np.array([0.4, 0.0, 0.0])
PAIRS = [("node_2", "jem"), ("node_1", "node_3"), ("us_lab", "node_2"), ("node_2", "eu_lab"),
         ("jem", "node_1")]


def _check(f, p0, q0, p1, q1):
    fm = flight_modes.get("nominal")
    rs = formation_search.robot_set(station.robot_radius())
    t = np.linspace(0.0, f.centre.trajectory.duration, 6000)
    c = f.centre.trajectory.sample(t)
    for r in f.robots:
        st = r.sample(t)
        assert rs.contains_all(st.pos).all()                              # robot spheres
        assert np.linalg.norm(st.vel, axis=1).max() <= fm.hard_limit_vel  # incl. w x r
        assert np.linalg.norm(st.acc, axis=1).max() <= fm.hard_limit_accel
    assert np.linalg.norm(c.omega, axis=1).max() <= fm.hard_limit_omega
    assert np.linalg.norm(c.alpha, axis=1).max() <= fm.hard_limit_alpha
    # the bag box (surface points) stays in the keep-in set
    g = np.linspace(-1, 1, 4)
    pts = np.array([[a, b, d] for a in g for b in g for d in g]) * f.bag_half
    bp = (np.repeat(c.pos[::10], len(pts), 0)
          + rot.rotate(np.repeat(c.quat[::10], len(pts), 0), np.tile(pts, (len(c.pos[::10]), 1))))
    assert formation_search.in_region(bp).all()
    # rigid formation: 0.8 m apart, the centre midway; ends at the requested poses at rest
    a, b = (r.sample(t[::50]) for r in f.robots)
    np.testing.assert_allclose(np.linalg.norm(a.pos - b.pos, axis=1), 0.8, atol=1e-9)
    np.testing.assert_allclose(0.5 * (a.pos + b.pos), c.pos[::50], atol=1e-9)
    np.testing.assert_allclose(c.pos[0], p0, atol=1e-9)
    np.testing.assert_allclose(c.pos[-1], p1, atol=1e-9)
    assert rot.angle_between(c.quat[0], q0) < 1e-6 and rot.angle_between(c.quat[-1], q1) < 1e-6
    for arr in (c.vel, c.acc, c.omega):
        assert np.abs(arr[[0, -1]]).max() < 1e-9
    # continuity: no jumps between neighbouring samples
    assert np.linalg.norm(np.diff(c.pos, axis=0), axis=1).max() < 0.01
    assert np.linalg.norm(np.diff(c.vel, axis=0), axis=1).max() < 1e-3


@pytest.mark.parametrize("a,b", PAIRS)
def test_formation_plans_between_modules(a, b):
    p0, p1 = config.waypoint(a), config.waypoint(b)
    f = multi_robot.plan_two_robots(p0, rot.IDENTITY, p1, rot.IDENTITY, OFF, "nominal")
    _check(f, p0, rot.IDENTITY, p1, rot.IDENTITY)
    # the formation turns in line with the corridor: no turn when the path is along x
    assert any(s.startswith("move") for s in f.steps)


def test_formation_robot_velocity_is_derivative_of_position():
    f = multi_robot.plan_two_robots(config.waypoint("node_2"), rot.IDENTITY, config.waypoint("jem"),
                                    rot.IDENTITY, OFF, "nominal")
    assert any(s.startswith("turn") for s in f.steps)
    turn_t = 5.0    # inside the first turn: the robots move only by the rotation
    h = 1e-4
    for r in f.robots:
        p = r.sample([turn_t - h, turn_t + h]).pos
        v = r.sample([turn_t]).vel[0]
        assert np.linalg.norm(v) > 1e-3
        np.testing.assert_allclose((p[1] - p[0]) / (2 * h), v, atol=1e-6)


def test_formation_too_wide_for_the_hatch_fails_naming_it():
    with pytest.raises(planner.PlanError) as exc:
        multi_robot.plan_two_robots(config.waypoint("node_1"), rot.IDENTITY, config.waypoint("node_3"),
                                    rot.IDENTITY, OFF, "nominal", bag_size=[0.4, 1.3, 1.3])
    assert exc.value.code == planner.PLAN_FAILED
    assert "hatch node_1/node_3" in str(exc.value) and "narrower" in str(exc.value)


def test_robot_outside_keep_in_is_rejected():
    with pytest.raises(planner.PlanError) as exc:
        multi_robot.plan_two_robots(config.waypoint("node_2"), rot.IDENTITY, config.waypoint("jem"),
                                    rot.IDENTITY, [3.0, 0, 0], "nominal")
    assert exc.value.code == planner.VIOLATES_KEEP_IN


def test_bad_formation_input():
    for kw in ({"offset": [np.nan, 0, 0]}, {"offset": OFF, "bag_size": [1, -1, 1]}):
        with pytest.raises(planner.PlanError) as exc:
            multi_robot.plan_two_robots(config.waypoint("node_2"), rot.IDENTITY, config.waypoint("jem"),
                                        rot.IDENTITY, flight_mode="nominal", **kw)
        assert exc.value.code == planner.INVALID_COMMAND
    with pytest.raises(planner.PlanError) as exc:
        multi_robot.plan_two_robots(config.waypoint("node_2"), rot.IDENTITY, config.waypoint("jem"),
                                    rot.IDENTITY, OFF, "warp")
    assert exc.value.code == planner.INVALID_FLIGHT_MODE


@pytest.mark.parametrize("a,b", [("node_2", "jem"), ("node_1", "node_3")])
def test_formation_turns_while_moving_where_the_corridor_allows(a, b):
    """The turns overlap the legs' braking and speeding up instead of holding still: no step
    turns at rest, and the plan is shorter than flying legs and turns one after the other."""
    f = multi_robot.plan_two_robots(config.waypoint(a), rot.IDENTITY, config.waypoint(b),
                                    rot.IDENTITY, OFF, "nominal")
    turns = [s for s in f.steps if s.startswith("turn")]
    assert turns and all("while moving" in s for s in turns)
    sequential = sum(float(s.rsplit("(", 1)[1].split(" s")[0]) for s in f.steps
                     if s.startswith(("turn", "move")))
    assert f.centre.trajectory.duration < sequential


def test_plan_formation_from_robot_poses():
    """The scenario's two robots (facing away from each other, the bag between them): each
    robot's trajectory starts at its own pose, keeps its attitude in the formation, and the
    first robot ends at the goal; a bag placed off the midpoint is checked as a larger box."""
    from astrobee.scenario import Scenario
    sc = Scenario.load("two_robots_bag")
    starts = [(np.array(r.position), np.array(r.orientation)) for r in sc.robots]
    goal = (np.array(sc.goal_position), np.array(sc.goal_orientation))
    plan = multi_robot.plan_formation(starts, goal, bag_size=[0.5, 0.42, 0.25])
    t = np.linspace(0.0, plan.robots[0].duration, 500)
    a, b = (r.sample(t) for r in plan.robots)
    for st, (p, q) in zip((a, b), starts):
        np.testing.assert_allclose(st.pos[0], p, atol=1e-9)
        assert rot.angle_between(st.quat[0], q) < 1e-9
    np.testing.assert_allclose(a.pos[-1], goal[0], atol=1e-9)
    assert rot.angle_between(a.quat[-1], goal[1]) < 1e-9
    np.testing.assert_allclose(np.linalg.norm(a.pos - b.pos, axis=1), 0.9, atol=1e-9)
    turn = [rot.angle_between(x, y) for x, y in zip(a.quat, b.quat)]
    np.testing.assert_allclose(turn, np.pi, atol=1e-6)
    grown = multi_robot.plan_formation(starts, goal, (starts[0][0] * 0.5 + starts[1][0] * 0.5
                                                      + [0, 0, 0.1], rot.IDENTITY), [0.5, 0.42, 0.25])
    # the bag's axes in the formation frame (x along the robots' line = world -y), its
    # height grown by its 0.1 m distance from the midpoint
    np.testing.assert_allclose(grown.formation.bag_half, [0.21, 0.25, 0.125 + 0.1], atol=1e-9)
    # a sampling over the cap a response may hold is refused in one line
    assert plan.robots[0].sample_rate(10.0, max_states=100_000).t[-1] == plan.robots[0].duration
    with pytest.raises(ValueError, match="more than the 100 a request may ask for"):
        plan.robots[1].sample_rate(10.0, max_states=100)
    with pytest.raises(planner.PlanError) as e:
        multi_robot.plan_formation(starts[:1], goal)
    assert e.value.code == planner.INVALID_COMMAND
    with pytest.raises(planner.PlanError) as e:
        multi_robot.plan_formation([starts[0], starts[0]], goal)
    assert e.value.code == planner.INVALID_COMMAND
