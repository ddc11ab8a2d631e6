"""The per-robot verdict of a leg (astrobee.task judging the leg's samples, as the mission's
finish_leg does) and of a run (summary.run_verdict), and the plot of a failed two-robot leg,
without any process."""
from __future__ import annotations

from dataclasses import asdict
from types import SimpleNamespace

import numpy as np

from astrobee import config
from astrobee.task import Goal, Task, TaskSample, judge
from astrobee_bringup import leg_plot
from astrobee_bringup import summary as sm
from astrobee_bringup.series import Series

TOL_P, TOL_A = 0.2, 0.35
Q = np.array([0.0, 0.0, 0.0, 1.0])
GOALS = {"": np.array([10.93, -6.0, 4.85]), "bumble": np.array([10.93, -5.05, 4.85])}


def _robot(name: str, **kw) -> sm.RobotResult:
    base = dict(final_position_error=0.01, final_attitude_error=0.01)
    base.update(kw)
    return sm.RobotResult(name=name, **base)


def _judge(off: dict | None = None, touching=(), faults=None, aborted="", seconds=3.0):
    """Two robots held at their goals (offset by `off`) for `seconds`, at rest; contacts of
    the bodies `touching` at every tick, faults per robot."""
    off = off or {}
    task = Task({n: Goal(g, Q) for n, g in GOALS.items()}, TOL_P, TOL_A).with_plan(0.0, 10.0)
    samples = [TaskSample(t=k * 0.1, poses={n: (g + off.get(n, 0.0), Q) for n, g in GOALS.items()},
                          velocities={n: (np.zeros(3), np.zeros(3)) for n in GOALS},
                          contacts=len(touching), touching=tuple(touching),
                          contact_bodies=tuple(f"{b}-iss" for b in touching),
                          faults=faults or {})
               for k in range(int(seconds / 0.1) + 1)]
    return judge(task, samples, aborted)


def test_every_robot_at_its_goal_and_at_rest_is_a_success():
    m = _judge()
    assert m.verdict() == (True, "goal reached")
    assert m.robot_problems("") == [] and m.robot_problems("bumble") == []


def test_one_robot_off_its_goal_fails_the_leg_naming_it():
    m = _judge(off={"bumble": np.array([0.5, 0.0, 0.0])})
    ok, why = m.verdict()
    assert not ok and why.startswith("robot bumble: final position error 0.500 m")
    assert m.robot_problems("") == []        # at rest at its goal: not the cause


def test_a_fault_or_a_contact_fails_even_at_the_goal():
    m = _judge(touching=("robot",), faults={"bumble": ("sim/propulsion_watchdog: x",)})
    ok, why = m.verdict()
    assert not ok
    assert "the default robot: 21 contact samples" in why
    assert "robot bumble: fault: sim/propulsion_watchdog" in why


def test_cargo_bag_contact_and_no_robot_fail():
    ok, why = _judge(touching=("bag",)).verdict()
    assert not ok and why == "cargo bag: 21 contact samples"   # the leg ends at rest, t = 2 s
    ok, why = judge(Task({}, TOL_P, TOL_A), []).verdict()
    assert not ok and why == "no robot flown"


def test_an_aborted_leg_keeps_its_cause_as_the_reason():
    m = _judge(off={"": np.array([3.0, 0, 0])}, aborted="flight aborted on a fault of robot bumble")
    assert m.verdict() == (False, "flight aborted on a fault of robot bumble")


def test_finish_leg_fills_each_robot_from_the_tasks_judgement():
    """The mission's finish_leg: a robot with no pose is 'unknown (no pose)', its result says
    it did not reach its goal; the leg's reason is the abort."""
    from astrobee_bringup.mission.result import LegResult, finish_leg
    w = SimpleNamespace(name="", named="the default robot", series=Series(), pose=None,
                        faults=[], sim_time=float("nan"), position_at=lambda t: None)
    client = SimpleNamespace(watches={"": w}, flying=[""], series=w.series, realism={},
                             _starts={}, _goals={"": (GOALS[""], Q)}, leg=None, task=None,
                             start_ns=None)
    res = LegResult(scenario="x", reason="planning failed (code -1): no", tolerance_position=TOL_P,
                    tolerance_attitude=TOL_A)
    finish_leg(client, res)
    assert (res.success, res.reason) == (False, "planning failed (code -1): no")
    r = res.robots[0]
    assert not r["success"] and not r["reached_goal"] and "unknown (no pose)" in r["reason"]


def test_any_fault_in_any_leg_fails_the_run_with_the_robot_named():
    good = {"scenario": "a", "success": True, "reason": "goal reached",
            "robots": [asdict(_robot(""))]}
    ok, why = sm.run_verdict([good])
    assert ok
    # a leg marked successful that still carries a fault (e.g. written by an older client)
    faulty = {"scenario": "b", "success": True, "reason": "goal reached",
              "robots": [asdict(_robot("")), asdict(_robot("bumble", faults=["watchdog"]))]}
    ok, why = sm.run_verdict([good, faulty])
    assert not ok and "b:" in why and "robot bumble: watchdog" in why
    ok, why = sm.run_verdict([])
    assert not ok


def test_plot_of_a_failed_two_robot_leg(tmp_path):
    """Every robot's path and the failure mark render; millimetres for small errors."""
    per = {}
    for name, y0 in (("", -0.45), ("bumble", 0.5)):
        s = Series()
        for k in range(200):
            t = 0.016 * k
            s.pose_t.append(t)
            s.position.append([10.95, y0 - 0.01 * k, 4.84])
            s.orientation.append([0, 0, 0, 1])
            s.ref_t.append(t)
            s.ref_position.append([10.95, y0 - 0.01 * k, 4.84])
            s.err_t.append(t)
            s.pos_error.append(0.002 + 0.0005 * np.sin(k))
            s.att_error.append(0.001)
        per[name] = s
    robots = [asdict(_robot("", start=[10.95, -0.45, 4.84], goal=[10.93, -6.0, 4.85])),
              asdict(_robot("bumble", start=[10.95, 0.5, 4.84], goal=[10.93, -5.05, 4.85],
                            failed_at={"t": 1.0, "position": [10.95, 0.4, 4.84], "why": "fault: x"}))]
    out = leg_plot.plot(per, tmp_path / "plot.png", config.keep_in_boxes(), title="t: FAILED",
                  robots=robots, t0=0.0, success=False)
    assert out.stat().st_size > 20_000
    assert leg_plot._unit(0.0025) == (1000.0, "mm") and leg_plot._unit(0.5) == (1.0, "m")
    labels = [n for n, _, _ in leg_plot._module_labels((1, 0), np.array([10, -7, 4]), np.array([12, 1, 6]))]
    assert "JEM" in labels and "node 2" in labels and "node 1" not in labels


def test_launch_starts_a_controller_and_filter_per_robot_in_its_namespace(tmp_path):
    """No process: the launch description of two_robots_bag with safety:=node lists one
    controller and one safety filter per robot, each in the robot's namespace, the controller's
    command remapped (relative, so inside the namespace), each with half the bag's mass; with
    safety:=true the filter runs inside each controller (its safety parameter): no filter
    process, no remap."""
    import pytest

    from astrobee_bringup.launch import cargo_transport
    from astrobee_bringup.launcher import LaunchContext, find_config_dir
    from astrobee_bringup.process_group import LaunchError, Launcher
    ctx = LaunchContext({"scenario": "two_robots_bag", "safety": "node", "controller": "mpc"},
                        find_config_dir(), tmp_path, False, 7447)
    specs = {s.name: s for s in cargo_transport.generate_nodes(ctx)}
    for name, ns in (("", ""), ("bumble/", "bumble")):
        ctl, safe = specs[f"{name}mpc_controller_node"], specs[f"{name}safety_filter_node"]
        assert ctl.namespace == ns and safe.namespace == ns and not ctl.required
        assert ctl.ros_args == ["-r", "gnc/ctl/command:=gnc/ctl/command_nominal"]
        assert {"use_sim_time": True, "bag_mass": 5.0} in ctl.parameters
        argv = Launcher(list(specs.values()), astrobee_cmd=["astrobee"]).argv_for(ctl)
        assert (f"__ns:={ns}" in argv) == bool(ns)
    inproc = LaunchContext({"scenario": "two_robots_bag", "safety": "true", "controller": "mpc"},
                           find_config_dir(), tmp_path, False, 7447)
    specs = {s.name: s for s in cargo_transport.generate_nodes(inproc)}
    assert not any("safety_filter" in n for n in specs)
    for name in ("", "bumble/"):
        ctl = specs[f"{name}mpc_controller_node"]
        assert ctl.ros_args == [] and {"use_sim_time": True, "bag_mass": 5.0, "safety": True} \
            in ctl.parameters
    off = LaunchContext({"scenario": "node2_to_jem", "safety": "false"}, find_config_dir(),
                        tmp_path, False, 7447)
    specs = cargo_transport.generate_nodes(off)
    assert not any("safety" in p for s in specs for p in s.parameters if isinstance(p, dict))
    default = LaunchContext({"scenario": "node2_to_jem"}, find_config_dir(), tmp_path, False, 7447)
    ctl = {s.name: s for s in cargo_transport.generate_nodes(default)}["pd_controller_node"]
    assert any(p.get("safety") is True for p in ctl.parameters if isinstance(p, dict))
    with pytest.raises(LaunchError, match="safety must be"):
        cargo_transport.generate_nodes(LaunchContext({"safety": "maybe"}, find_config_dir(),
                                                     tmp_path, False, 7447))
    one = LaunchContext({"scenario": "node2_to_jem_bag"}, find_config_dir(), tmp_path, False, 7447)
    ctls = [s for s in cargo_transport.generate_nodes(one) if s.name.endswith("controller_node")]
    assert [(s.name, s.namespace) for s in ctls] == [("pd_controller_node", "")]
    assert all("bag_mass" not in p for p in ctls[0].parameters if isinstance(p, dict))
