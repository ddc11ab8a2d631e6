"""The honest verdict: at the goal AND at rest (|v| < 1 cm/s, |w| < 0.02 rad/s, held 2 s) before
the time budget (plan end + settle budget), judged on truth; the same recorded leg judged alike
by the mission's code and by astrobee_lab.recorded."""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from astrobee import msgconv as mc
from astrobee import rotations as rot
from astrobee.leg_samples import LegSamples
from astrobee.task import Goal, Task, TaskSample, judge

GOAL = np.array([10.93, -6.0, 4.85])
Q = np.array([0.0, 0.0, -0.7071067811865476, 0.7071067811865476])
DT = 0.016


def _task(plan: float = 4.0, settle: float = 6.0) -> Task:
    return Task({"": Goal(GOAL, Q)}, 0.2, 0.3491).with_plan(plan, settle)


def _leg(seconds: float, omega: float = 0.0, speed: float = 0.0, ref_tilt: float = 0.0):
    """Samples of a robot sitting at its goal (turning at `omega`, drifting at `speed`)."""
    out = []
    for k in range(int(round(seconds / DT)) + 1):
        ref_q = rot.normalize(rot.multiply(Q, [0.0, math.sin(ref_tilt / 2), 0.0,
                                               math.cos(ref_tilt / 2)]))
        out.append(TaskSample(t=k * DT, poses={"": (GOAL.copy(), Q)},
                              velocities={"": (np.array([speed, 0, 0]), np.array([0, 0, omega]))},
                              reference={"": GOAL.copy()}, reference_attitude={"": ref_q}))
    return out


def test_a_pair_spinning_at_the_goal_fails_on_the_budget():
    m = judge(_task(), _leg(20.0, omega=0.3))
    ok, cause = m.verdict()
    assert not ok and m.truncated and not m.goal_reached
    assert cause.startswith("time budget of 10.0 s (plan 4.0 s + settle 6 s) ran out")
    assert "not at rest: |v| 0.000 m/s, |w| 0.300 rad/s" in cause
    assert m.elapsed == pytest.approx(10.0, abs=DT)        # the leg ends at the budget
    assert math.isnan(m.metrics()["time_to_rest"])


def test_a_pair_at_rest_at_the_goal_succeeds_after_the_hold_and_the_plan():
    m = judge(_task(plan=1.0), _leg(20.0))
    ok, cause = m.verdict()
    assert ok and cause == "goal reached" and m.goal_reached
    met = m.metrics()
    assert met["time_to_rest"] == pytest.approx(0.0)
    assert met["duration"] == pytest.approx(2.0, abs=DT)   # ends once rest held 2 s
    # at rest long before the plan ends: the leg still waits for the plan's end
    m = judge(_task(plan=5.0), _leg(20.0))
    assert m.goal_reached and m.elapsed == pytest.approx(5.0, abs=DT)
    assert m.metrics()["time_budget"] == pytest.approx(11.0)


def test_budget_exhaustion_names_the_budget_for_a_slow_drift():
    m = judge(_task(plan=2.0, settle=3.0), _leg(20.0, speed=0.02))
    ok, cause = m.verdict()
    assert not ok and "time budget of 5.0 s (plan 2.0 s + settle 3 s) ran out" in cause
    assert "|v| 0.020 m/s" in cause


def test_rest_must_hold_unbroken_and_the_attitude_excursion_is_reported():
    samples = _leg(1.5) + [TaskSample(t=1.5 + DT, poses={"": (GOAL.copy(), Q)},
                                      velocities={"": (np.zeros(3), np.array([0, 0, 0.05]))})]
    tail = _leg(3.0, ref_tilt=0.25)
    for s in tail:
        s.t += 1.5 + 2 * DT
    m = judge(_task(plan=0.0), samples + tail)
    assert m.goal_reached
    assert m.metrics()["time_to_rest"] == pytest.approx(1.5 + 2 * DT)   # the clock restarted
    assert m.metrics()["max_attitude_excursion"] == pytest.approx(0.25, abs=1e-6)
    # cut short before the hold: the cause says so
    m = judge(_task(plan=0.0, settle=1.0), _leg(0.5))
    assert not m.verdict()[0] and "at rest for 0.5 s of the 2 s asked" in m.verdict()[1]


# ---- one recorded leg, judged by the mission's code and by astrobee_lab.recorded -----------

TYPES = {"/loc/truth/pose": "geometry_msgs/msg/PoseStamped",
         "/loc/truth/twist": "geometry_msgs/msg/TwistStamped",
         "/gnc/ctl/traj": "astrobee_msgs/msg/ControlState",
         "/gnc/ctl/command": "astrobee_msgs/msg/FamCommand",
         "/sim/contacts": "astrobee_msgs/msg/Contacts",
         "/mob/state": "astrobee_msgs/msg/MotionState",
         "/gnc/ctl/segment": "astrobee_msgs/msg/Segment"}
PLAN = 3.0


def _messages(omega0: float, decay: float):
    """A leg's messages, in publishing order: CONTROLLING, the segment (plan of PLAN s starting
    at t = 0.5 s), then per tick the truth pose and twist, the reference, the command and the
    contacts; the robot arrives at PLAN + 0.5 s, its spin decaying from omega0 (rate 1/s)."""
    from roszen import typestore as ts
    C = {k: ts.message_class(v) for k, v in TYPES.items()}
    out = []
    mob = C["/mob/state"]()
    mob.state, mob.fsm_event = mc.MotionState.CONTROLLING, "segment accepted"
    mc.set_stamp(mob.header.stamp, 0.1)
    out.append(("/mob/state", mob))
    seg = C["/gnc/ctl/segment"]()
    states = []
    for k in range(int(PLAN * 10) + 1):
        cs = ts.message_class("astrobee_msgs/msg/ControlState")()
        mc.set_stamp(cs.when, 0.5 + k * 0.1)
        states.append(cs)
    seg.segment = states
    out.append(("/gnc/ctl/segment", seg))
    start = GOAL + [0.0, 0.6, 0.0]
    for k in range(int(25.0 / DT)):
        t = k * DT
        f = min(1.0, max(0.0, (t - 0.5) / PLAN))
        p = start + (GOAL - start) * f
        v = (GOAL - start) / PLAN if 0.5 < t < 0.5 + PLAN else np.zeros(3)
        w = omega0 * math.exp(-decay * max(0.0, t - 0.5 - PLAN)) if t > 0.5 else 0.0
        pose, tw = C["/loc/truth/pose"](), C["/loc/truth/twist"]()
        for m in (pose, tw):
            mc.set_stamp(m.header.stamp, t)
        pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = p.tolist()
        (pose.pose.orientation.x, pose.pose.orientation.y, pose.pose.orientation.z,
         pose.pose.orientation.w) = Q.tolist()
        tw.twist.linear.x, tw.twist.linear.y, tw.twist.linear.z = v.tolist()
        tw.twist.angular.z = w
        traj = C["/gnc/ctl/traj"]()
        mc.set_stamp(traj.when, t)
        traj.pose = pose.pose
        cmd = C["/gnc/ctl/command"]()
        mc.set_stamp(cmd.header.stamp, t)
        cmd.control_mode = 1
        con = C["/sim/contacts"]()
        mc.set_stamp(con.header.stamp, t)
        con.robot_clearance, con.bag_clearance = 0.4, -1.0
        out += [("/loc/truth/pose", pose), ("/loc/truth/twist", tw), ("/gnc/ctl/traj", traj),
                ("/gnc/ctl/command", cmd), ("/sim/contacts", con)]
    return out


class _Node:
    """Enough of a node for a RobotWatch: subscriptions kept by topic."""

    def __init__(self) -> None:
        self.subs: dict[str, object] = {}

    def create_subscription(self, _type, topic, cb, _qos):
        self.subs[topic] = cb

    def create_publisher(self, *_a):
        return None

    def get_logger(self):
        return SimpleNamespace(warn=lambda *_: None, info=lambda *_: None)


def _mission_verdict(messages, settle: float):
    """The mission's code on the messages: its RobotWatch and client feed a LegSamples, its Leg
    feeds the live Task that ends the leg, finish_leg judges it."""
    from astrobee_bringup.mission import leg as legmod
    from astrobee_bringup.mission.result import LegResult, finish_leg
    from astrobee_bringup.mission.watch import RobotWatch
    node = _Node()
    w = RobotWatch(node, "", None, None)
    client = SimpleNamespace(watches={"": w}, flying=[""], realism={}, _starts={},
                             _goals={"": (GOAL, Q)}, leg=LegSamples([""]), task=None, start_ns=None)
    w.start_leg(client.leg)
    res = LegResult(scenario="t", tolerance_position=0.2, tolerance_attitude=0.3491)
    leg = legmod.Leg(client, "t", None, res, 60.0, 60.0, settle)
    for topic, msg in messages:
        if topic == "/sim/contacts":          # the client's own subscription
            w.series.add_contacts(msg)
            client.leg.add_contacts(msg)
        elif topic in node.subs:
            node.subs[topic](msg)
        if topic == "/gnc/ctl/segment":       # the mission's hand-over: the Task starts
            t_acc = max(w.controlling_since(0), mc.stamp_ns(msg.segment[0].when) * 1e-9)
            client.task = Task({"": Goal(GOAL, Q)}, 0.2, 0.3491).with_plan(PLAN, settle, t_acc)
            client.start_ns, leg.monitor = mc.to_ns(t_acc), client.task.monitor()
        leg._feed()
        if leg.end_ns is not None:
            break
    client.series = w.series
    finish_leg(client, res, leg.end_ns)
    return res, leg.end_ns


def _write_bag(path, messages):
    from roszen import QoSProfile, typestore
    from roszen.bag.writer import BagWriter
    w = BagWriter(path)
    for name, ty in TYPES.items():
        w.add_topic(name, ty, typestore.message_definition(ty), typestore.type_hash(ty),
                    [QoSProfile(depth=10)])
    ser = {n: typestore.serializer(ty) for n, ty in TYPES.items()}
    for i, (topic, msg) in enumerate(messages):
        w.write(topic, ser[topic](msg), 1_000_000_000 + i)
    w.close()


@pytest.mark.parametrize("decay", [1.0, 0.0])
def test_the_same_recorded_leg_is_judged_alike_by_the_mission_and_the_recording(tmp_path, decay):
    """A spin of 0.3 rad/s at the goal: decaying (at rest 2.7 s after the plan, success), or
    not (the budget runs out, failure)."""
    pytest.importorskip("roszen")
    from astrobee_lab.recorded import judge_bag
    messages = _messages(0.3, decay)
    res, end_ns = _mission_verdict(messages, settle=8.0)
    _write_bag(tmp_path / "bag", messages)
    task = Task({"": Goal(GOAL, Q)}, 0.2, 0.3491, settle_budget=8.0)
    m = judge_bag(tmp_path / "bag", task)
    ok, cause = m.verdict()
    assert (ok, cause) == (res.success, res.reason)
    assert mc.to_ns(m.t) == end_ns
    assert m.metrics()["time_to_rest"] == pytest.approx(res.time_to_rest or math.nan,
                                                        nan_ok=True)
    assert ok == (decay > 0), cause
    if not ok:
        assert "time budget of 11.0 s (plan 3.0 s + settle 8 s) ran out" in cause
    assert res.time_budget == pytest.approx(PLAN + 8.0)
