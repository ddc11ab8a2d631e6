import numpy as np
import pytest

from astrobee import config
from astrobee import rotations as rot
from astrobee_planning import multi_robot, planner


def test_two_robots_node2_to_jem_stay_safe_and_within_limits():
    """The paper's tight spot: two robots 0.8 m apart carry a bag through the Node 2 -> JEM hatch."""
    off = np.array([0.4, 0.0, 0.0])
    f = multi_robot.plan_two_robots(config.waypoint("node_2"), rot.IDENTITY, config.waypoint("jem"),
                                    rot.IDENTITY, off, "nominal")
    safe = planner.cached_safe_set(0.0)
    fm = planner.flight_modes.get("nominal")
    for r in f.robots:
        st = r.sample(np.linspace(0, r.duration, 4000))
        assert safe.contains_all(st.pos).all()
        assert np.linalg.norm(st.vel, axis=1).max() <= fm.hard_limit_vel
        assert np.linalg.norm(st.acc, axis=1).max() <= fm.hard_limit_accel
    # rigid formation: the robots stay 0.8 m apart, the centre midway
    a, b = (r.sample(np.linspace(0, f.robots[0].duration, 200)) for r in f.robots)
    np.testing.assert_allclose(np.linalg.norm(a.pos - b.pos, axis=1), 0.8, atol=1e-9)
    c = f.centre.trajectory.sample(a.t)
    np.testing.assert_allclose(0.5 * (a.pos + b.pos), c.pos, atol=1e-9)
    # robot velocity is the derivative of its position
    h = 1e-4
    t = 0.5 * f.robots[0].duration
    p = f.robots[0].sample([t - h, t + h]).pos
    np.testing.assert_allclose((p[1] - p[0]) / (2 * h), f.robots[0].sample([t]).vel[0], atol=1e-6)


def test_robot_outside_keep_in_is_rejected():
    with pytest.raises(planner.PlanError) as exc:
        multi_robot.plan_two_robots(config.waypoint("node_2"), rot.IDENTITY, config.waypoint("jem"),
                                    rot.IDENTITY, [3.0, 0, 0], "nominal")
    assert exc.value.code == planner.VIOLATES_KEEP_IN
