"""astrobee.task: the verdict, the metrics and the reward of a leg from hand-made samples."""
from __future__ import annotations

import numpy as np
import pytest

from astrobee.scenario import Scenario
from astrobee.task import RewardWeights, Task, TaskSample, formation_goals

Q = np.array([0.0, 0.0, -0.7071067811865476, 0.7071067811865476])


def sample(t, p, ref=None, v=(0, 0, 0), **kw) -> TaskSample:
    p = np.asarray(p, float)
    return TaskSample(t=t, poses={"": (p, Q)}, velocities={"": (np.asarray(v, float), np.zeros(3))},
                      reference=None if ref is None else {"": np.asarray(ref, float)}, **kw)


def task(**kw) -> Task:
    sc = Scenario.load("node2_to_jem")
    return Task.from_scenario(sc, **kw)


def test_from_scenario_takes_goal_tolerances_and_time_budget():
    t = task(plan_duration=40.0)
    assert np.allclose(t.goals[""].position, [10.93, -6.0, 4.85])
    assert t.tolerance_position == pytest.approx(0.2) and t.tolerance_attitude > 0
    # the budget: the plan's end + the settle budget (30 s by default), both recorded
    assert t.time_limit == pytest.approx(40.0 + 30.0)
    assert t.plan_end == pytest.approx(40.0) and t.settle_budget == pytest.approx(30.0)
    assert task(plan_duration=40.0, settle_budget=5.0).time_limit == pytest.approx(45.0)
    with pytest.raises(ValueError, match="no goal"):
        Task.from_scenario(Scenario.from_dict({"goal": None}, "nogoal"))


def test_success_metrics_and_time_to_goal():
    m = task().monitor()
    goal = np.array([10.93, -6.0, 4.85])
    m.update(sample(0.0, goal + [0, 1.0, 0], ref=goal + [0, 1.0, 0], v=(0, -0.1, 0),
                    robot_clearance=0.5, bag_clearance=-1.0))
    m.update(sample(1.0, goal + [0, 0.1, 0], ref=goal + [0, 0.1, 0.03], v=(0, -0.1, 0),
                    robot_clearance=0.4, bag_robot_speed=0.02))
    assert not m.terminated
    m.update(sample(2.0, goal, ref=goal, robot_clearance=0.45, bag_robot_speed=0.01))
    # at rest at the goal, but not yet for the 2 s asked (the old rule passed it here)
    assert not m.terminated and not m.goal_reached
    for t in (3.0, 4.0):
        m.update(sample(t, goal, robot_clearance=0.45))
    ok, cause = m.verdict()
    assert ok and cause == "goal reached"
    assert m.terminated and m.goal_reached and not m.truncated
    met = m.metrics()
    assert met["rms_position_error"] == pytest.approx(np.sqrt(0.03**2 / 3))
    assert met["min_robot_clearance"] == pytest.approx(0.4)
    assert np.isnan(met["min_bag_clearance"])           # -1: no bag
    assert met["peak_bag_robot_speed"] == pytest.approx(0.02)
    assert met["time_to_goal"] == pytest.approx(1.0)    # within 0.2 m from t = 1 s
    assert met["time_to_rest"] == pytest.approx(2.0)    # at rest from t = 2 s, held to 4 s
    assert met["contacts"] == 0 and met["duration"] == pytest.approx(4.0)


def test_contact_fault_and_final_error_in_the_summary_words():
    m = task().monitor()
    m.update(sample(0.0, [10.95, 0.0, 4.84], contacts=2, contact_bodies=("bag-iss", "robot-iss"),
                    touching=("bag", "robot")))
    m.update(sample(0.1, [10.95, 0.0, 4.84], faults={"": ("sim/propulsion_watchdog: stopped",)}))
    ok, cause = m.verdict()
    assert not ok
    assert cause == ("fault: sim/propulsion_watchdog: stopped; 1 contact samples; "
                     "final position error 6.000 m > 0.2 m; cargo bag: 1 contact samples")
    assert m.faults == ["the default robot: sim/propulsion_watchdog: stopped"]
    assert m.terminated and m.failed_early       # a fault ends an episode
    assert m.metrics()["contact_bodies"] == "bag-iss,robot-iss"


def test_contact_ends_an_episode_only_when_asked():
    for end, expect in ((False, False), (True, True)):
        m = task(end_on_contact=end).monitor()
        m.update(sample(0.0, [10.95, 0.0, 4.84], contacts=1, contact_bodies=("robot-iss",),
                        touching=("robot",)))
        assert m.terminated is expect


def test_time_limit_truncates():
    m = task(time_limit=1.0).monitor()
    m.update(sample(0.0, [10.93, -6.0, 4.85], v=(0.1, 0, 0)))
    m.update(sample(1.0, [10.93, -6.0, 4.85], v=(0.1, 0, 0)))   # in tolerance, not at rest
    assert m.truncated and not m.terminated
    ok, cause = m.verdict()
    assert not ok and "time limit of 1 s reached" in cause
    assert "not at rest: |v| 0.100 m/s" in cause


def test_failure_before_flight():
    m = task().monitor()
    m.fail("planning failed (code -29): goal outside")
    m.update(sample(0.0, [10.93, -6.0, 4.85]))
    ok, cause = m.verdict()
    assert not ok and cause.startswith("planning failed (code -29)")


def test_two_robots_each_judged_and_named():
    sc = Scenario.load("two_robots_bag")
    goals = formation_goals(sc)
    # the second robot keeps its offset from the first, rotated with it (here: no rotation)
    assert np.allclose(goals["bumble"][0] - goals[""][0], [0.0, 0.9, 0.0])
    t = Task.from_scenario(sc)
    m = t.monitor()
    poses = {"": (goals[""][0], goals[""][1]), "bumble": (goals["bumble"][0] + [0, 0, 0.5],
                                                        goals["bumble"][1])}
    still = {n: (np.zeros(3), np.zeros(3)) for n in poses}
    for t in (0.0, 2.0):     # the first robot at rest at its goal for the 2 s asked
        m.update(TaskSample(t=t, poses=poses, velocities=still))
    ok, cause = m.verdict()
    assert not ok and cause == "robot bumble: final position error 0.500 m > 0.2 m"


def test_reward_rewards_progress_and_penalises_contact_and_clearance():
    w = RewardWeights()
    goal = np.array([10.93, -6.0, 4.85])
    m = task(weights=w).monitor()
    m.step(sample(0.0, goal + [0, 1.0, 0], v=(0, -0.1, 0), robot_clearance=0.5))
    r_progress = m.step(sample(1.0, goal + [0, 0.9, 0], v=(0, -0.1, 0), robot_clearance=0.5))
    assert r_progress == pytest.approx(0.1 * w.progress)
    r_back = m.step(sample(2.0, goal + [0, 1.0, 0], v=(0, 0.1, 0), robot_clearance=0.5))
    assert r_back < 0
    r_contact = m.step(sample(3.0, goal + [0, 1.0, 0], v=(0, 0.1, 0), robot_clearance=0.0,
                              contacts=1))
    assert r_contact == pytest.approx(-w.contact - w.clearance * 1.0)
    r_arrive = m.step(sample(4.0, goal, robot_clearance=0.5))
    assert r_arrive == pytest.approx(1.0 * w.progress)     # progress of 1 m, no bonus yet
    r_goal = m.step(sample(6.0, goal, robot_clearance=0.5))
    assert r_goal == pytest.approx(w.success)  # at rest at the goal for 2 s: the bonus
