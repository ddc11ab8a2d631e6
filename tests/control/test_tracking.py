"""Segment-following state machine on the numpy rigid body."""
import numpy as np

from astrobee import flight_modes
from astrobee import rotations as rot
from astrobee_control import mass as mp
from astrobee_control import tracking as tk
from astrobee_control.reference import rest_to_rest
from astrobee_control.rigid_body import RigidBody

DT = 1.0 / 62.5


def run(tracker, body, t0, t1, on_tick=None):
    t, states = t0, []
    while t < t1:
        step = tracker.update(body.state(), t, DT)
        if on_tick:
            on_tick(t, step)
        states.append((t, step.state, step.event))
        for _ in range(2):
            body.step(step.output.force, step.output.torque, DT / 2)
        t += DT
    return states


def test_life_cycle_follow_then_stop_at_goal():
    fm = flight_modes.get("nominal")
    q = rot.from_axis_angle([0, 0, 1], -np.pi / 2)
    body = RigidBody(mp.robot(), [0, 0, 0], q)
    tr = tk.Tracker(fm, mp.robot(), settle_time=10.0)
    assert tr.state == tk.IDLE
    states = run(tr, body, 0.0, 1.0)
    assert states[0][1] == tk.STOPPED and "start" in states[0][2]
    traj = rest_to_rest([0, 0, 0], [1.0, 0.5, 0], q, q, 15.0).shifted(0.0)  # starts in the past
    tr.follow(traj, 1.0)
    assert tr.state == tk.CONTROLLING and tr.traj.start_time == 1.0
    states = run(tr, body, 1.0, 30.0)
    seq = [s for _, s, e in states if e]
    assert seq[:3] == [tk.CONTROLLING, tk.STOPPING, tk.STOPPED]
    t_stopping = next(t for t, s, e in states if s == tk.STOPPING)
    assert t_stopping >= 16.0 - DT
    assert tr.segment_result == "GOAL_REACHED"
    assert np.linalg.norm(body.state().position - [1.0, 0.5, 0]) < fm.tolerance_pos


def test_stop_request_holds_where_it_came():
    fm = flight_modes.get("nominal")
    body = RigidBody(mp.robot(), [0, 0, 0], rot.IDENTITY)
    tr = tk.Tracker(fm, mp.robot(), settle_time=30.0)
    tr.follow(rest_to_rest([0, 0, 0], [3.0, 0, 0], rot.IDENTITY, rot.IDENTITY, 30.0), 0.0)
    run(tr, body, 0.0, 10.0)
    stop_at = body.state().position.copy()
    assert np.linalg.norm(body.state().velocity) > 0.05
    tr.stop(body.state(), 10.0)
    assert tr.state == tk.STOPPING and tr.segment_result == "STOPPED"
    run(tr, body, 10.0, 40.0)
    assert tr.state == tk.STOPPED
    assert np.linalg.norm(body.state().position - stop_at) < 0.02
    assert body.state().position[0] < 2.0  # did not continue to the segment's end


def test_idle_without_hold_outputs_zero():
    tr = tk.Tracker(flight_modes.get("nominal"), mp.robot(), hold_on_start=False)
    body = RigidBody(mp.robot(), [1, 2, 3], rot.IDENTITY)
    body.v = np.array([0.05, 0, 0])
    step = tr.update(body.state(), 0.0, DT)
    assert step.state == tk.IDLE and step.control_mode == 0
    assert np.allclose(step.output.force, 0) and np.allclose(step.output.torque, 0)
