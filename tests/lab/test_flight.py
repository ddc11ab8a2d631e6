"""astrobee_lab.flight: a leg flown in-process (simulator + planner + law, no transport)."""
from __future__ import annotations

import math
import sys

import numpy as np
import pytest

from astrobee_lab.flight import Flight, FlightResult

pytest.importorskip("pybullet")

COST_FIELDS = {"wall_time", "real_time_factor", "compute_ms_median", "compute_ms_p99",
               "planning_time"}
ROW_FIELDS = {"scenario", "bag_model", "bag_variant", "bag_mass", "flight_mode", "controller",
              "safety", "realism", "seed", "success", "cause", "rms_position_error",
              "min_robot_clearance", "min_bag_clearance", "contacts", "peak_bag_robot_speed",
              "time_to_goal", "plan_duration", "sim_time", "wall_time", "compute_ms_median",
              "compute_ms_p99"}


def test_pd_flight_with_rigid_bag_reaches_goal_and_row_has_the_fields(rigid_hop):
    with Flight(rigid_hop, seed=0, controller="pd") as f:
        res = f.run()
    assert isinstance(res, FlightResult)
    assert res.success, res.cause
    assert res.cause == "goal reached"
    m = res.metrics
    assert m["contacts"] == 0 and m["final_position_error"] <= 0.2
    assert m["rms_position_error"] < 0.01
    assert m["min_bag_clearance"] > 0 and m["min_robot_clearance"] > 0
    assert 0 < m["time_to_goal"] <= res.sim_time
    assert res.sim_time >= res.plan_duration     # flown to the end of the segment, then settled
    row = res.row()
    assert ROW_FIELDS <= set(row), ROW_FIELDS - set(row)
    assert row["bag_model"] == "rigid" and row["controller"] == "pd" and row["seed"] == 0
    assert all(isinstance(v, (str, int, float, bool)) for v in row.values())


def test_the_lab_loads_no_transport():
    """Importing the flight, the environments and the Task loads neither zenoh nor roszen."""
    import subprocess
    code = ("import sys, astrobee_lab.flight, astrobee_lab.envs, astrobee.task; "
            "bad = [m for m in ('roszen', 'zenoh') if m in sys.modules]; "
            "sys.exit(f'loaded {bad}' if bad else 0)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr


def test_same_arguments_and_seed_give_the_same_flight(make_hop):
    """With the realism knobs on (seeded noise in the estimate and the actuation) two flights of
    the same seed agree to the bit; another seed flies differently."""
    def row(seed):
        with Flight(make_hop(None, goal_y=0.2), seed=seed, realism="astrobee") as f:
            r = f.run().row()
        # nan (no bag) as a string, so that equal rows compare equal
        return {k: repr(v) for k, v in r.items() if k not in COST_FIELDS}
    a, b, c = row(3), row(3), row(4)
    assert a == b
    assert a["rms_position_error"] != c["rms_position_error"]


def test_a_hard_push_into_the_wall_fails_on_contact(make_hop):
    push = {"disturbances": [{"target": "robot", "force": [-30.0, 0.0, 0.0], "time": 1.0,
                              "duration": 1.0}]}
    with Flight(make_hop(None, goal_y=0.2), realism=push, task={"end_on_contact": True}) as f:
        f.reset()
        for _ in range(600):
            f.step()
            if f.monitor.terminated:
                break
        ok, cause = f.monitor.verdict()
        bodies = f.monitor.metrics()["contact_bodies"]
    assert not ok
    assert cause.startswith("fault") is False and "contact samples" in cause
    assert "robot-iss" in bodies


def test_a_goal_outside_the_station_fails_at_planning(make_hop):
    sc = make_hop(None, goal_y=0.2)
    from dataclasses import replace
    sc = replace(sc, goal_position=(10.95, 0.2, 9.0))
    with Flight(sc) as f:
        res = f.run()
    assert not res.success
    assert res.cause.startswith("planning failed (code -29)")
    assert res.ticks == 0 and math.isnan(res.plan_duration)


def test_the_time_limit_ends_a_flight(make_hop):
    with Flight(make_hop(None, goal_y=0.2)) as f:
        res = f.run(max_time=2.0)
    assert not res.success and "time limit of 2 s" in res.cause
    assert res.sim_time == pytest.approx(2.0, abs=0.02)


def test_step_action_adds_to_or_replaces_the_law_wrench(make_hop):
    with Flight(make_hop(None, goal_y=0.2), state_source="truth") as f:
        obs = f.reset()
        nominal = obs.robots[""].nominal.copy()
        f.step(np.array([0.1, 0, 0, 0, 0, 0]))
        assert np.allclose(f._applied[""], nominal + [0.1, 0, 0, 0, 0, 0])
        f.step(np.zeros(6), mode="replace")
        assert np.allclose(f._applied[""], 0.0)


def test_bad_arguments_are_one_line_errors(make_hop):
    from astrobee.scenario import Scenario
    import re

    from astrobee_control import registry
    with pytest.raises(ValueError, match=f"controller must be {re.escape(registry.choices_text())} "
                                         "or a ControlLaw, got 'lqr'"):
        Flight(make_hop(None), controller="lqr").reset()
    with pytest.raises(ValueError, match="one robot, or two"):
        Flight(Scenario.load("node2_to_jem", robots=["", "a", "b"]))
    from astrobee.scenario import ScenarioError
    with pytest.raises(ScenarioError):
        Flight("node2_to_jem", bag_model="nonsense")


def test_two_robots_fly_the_formation_plan_to_their_goals():
    """Two robots holding one bag: one law each, the formation planner's references; the Task
    judges both (each robot named in the metrics)."""
    from dataclasses import replace

    from astrobee.scenario import Scenario
    sc = Scenario.load("two_robots_bag")
    sc = replace(sc, goal_position=(10.95, -1.05, 4.84))        # a 0.6 m hop along the node
    with Flight(sc) as f:
        res = f.run()
        goals = f.task.goals
    assert set(goals) == {"", "bumble"}
    assert res.success, res.cause
    assert res.metrics["final_position_error_bumble"] <= 0.2
    assert res.metrics["final_position_error_robot"] <= 0.2
    assert res.row()["robots"] == 2 and res.metrics["contacts"] == 0


def test_the_simulator_backend_can_be_passed_in(make_hop):
    """Flight(backend=...): the rigid-body backend (no EKF model: the law sees the truth) flies
    the same hop to its goal; a factory and an object are both accepted, and the flight
    drives the one it was given."""
    from astrobee_sim.rigid_backend import RigidSim
    built = []

    def factory(scenario, seed):
        built.append(RigidSim(scenario, seed=seed))
        return built[-1]

    with Flight(make_hop(None), backend=factory) as f:
        res = f.run()
        assert f.sim is built[0]
    assert res.success, res.cause
    sim = RigidSim("node2_to_jem")
    with Flight(make_hop(None), backend=sim) as f:
        f.reset()
        assert f.sim is sim and sim.scenario.name == f.scenario.name
