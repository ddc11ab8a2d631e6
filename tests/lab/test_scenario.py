"""Scenario.with_start_goal: the environments' random legs replace the first robot's start pose
and the goal pose, and nothing else."""
import numpy as np

from astrobee.scenario import Scenario


def test_with_start_goal_replaces_only_the_first_robot_and_the_goal():
    base = Scenario.load("node2_to_jem")
    start = ((10.5, -0.2, 4.9), (0.0, 0.0, 0.0, 2.0))       # orientation normalised
    goal = ((10.9, -1.5, 4.8), (0.0, 0.0, -1.0, 1.0))
    sc = base.with_start_goal(start, goal)
    assert sc.robots[0].position == start[0] and sc.robots[0].orientation == (0.0, 0.0, 0.0, 1.0)
    assert sc.goal_position == goal[0]
    np.testing.assert_allclose(sc.goal_orientation, np.array(goal[1]) / np.sqrt(2.0))
    assert sc.robots[1:] == base.robots[1:] and sc.bag == base.bag and sc.name == base.name
    assert base.with_start_goal() == base
    assert base.with_start_goal(goal=goal).robots == base.robots
