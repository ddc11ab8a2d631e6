"""The oracle's tracker (astrobee_lab.oracle.tracking): error coordinates invert, and the
time-varying LQR on the pair model brings a perturbed pair back onto a resting plan."""
from __future__ import annotations

import numpy as np
import pytest

from astrobee import flight_modes
from astrobee_control import pair_model as pm
from astrobee_lab.oracle import fly, solve as so, tracking

Q = np.array([0.0, 0.0, -0.7071067811865476, 0.7071067811865476])
X0 = pm.state(np.array([10.95, -1.0, 4.84]), np.zeros(3), Q, np.zeros(3), Q, np.zeros(3))
MODE = flight_modes.get("nominal")
LIM = np.concatenate([MODE.max_force, MODE.max_torque])


def _resting(duration: float) -> so.OracleResult:
    ts = np.arange(0.0, duration + 1e-9, 0.5)
    return so.OracleResult(True, "solved", 0.0, ts, np.repeat(X0[None], len(ts), 0), np.zeros((len(ts) - 1, 6)))


def test_error_and_perturb_are_inverse():
    d = np.random.default_rng(0).normal(scale=0.05, size=(4, 18))
    x = tracking.perturb(X0, d, False)
    assert np.allclose(tracking.error(x, X0[None], False), d, atol=1e-9)


def test_lqr_brings_a_perturbed_pair_back_to_the_plan():
    p = pm.load("fem")
    dt = 0.05
    tp = tracking.plan(_resting(12.0), p, LIM, dt)
    d0 = np.array([0.03, -0.02, 0.02, 0.0, 0.0, 0.0, 0.05, 0.0, -0.05, 0.0, 0.0, 0.0, 0.05, 0.0, 0.0, 0.0, 0.0, 0.0])
    x = tracking.perturb(X0, d0, False)
    for t in tp.t:
        x = pm.rk4(x, tp.command(x, t, LIM), None, p, dt)
    e = tracking.error(x, X0, False)
    assert np.linalg.norm(e[0:3]) < 0.4 * np.linalg.norm(d0[0:3])
    assert np.linalg.norm(e[6:9]) < 0.4 * np.linalg.norm(d0[6:9])
    assert np.linalg.norm(e[3:6]) < 0.01 and np.linalg.norm(e[15:18]) < 0.02


def test_fly_refuses_an_unknown_feedback():
    with pytest.raises(ValueError, match="feedback"):
        fly.fly(_resting(1.0), so.plan_leg(), pm.load("fem"), 0, 0.0, feedback="mpc")
    with pytest.raises(ValueError, match="lqr"):
        fly.fly(_resting(1.0), so.plan_leg(), pm.load("fem"), 0, 5.0, feedback="pd", react=0.5)


def test_a_ball_jointed_bags_swing_is_not_reachable_at_first_order():
    """With the grasp a ball joint (twist spring only), the robot's wrench reaches 14 of the 18
    error directions of the pair at rest: the bag's swing about the two free pivot axes
    (angle and rate) only moves through large-angle (nonlinear) manoeuvres."""
    A, B = tracking.linearise(X0[None], np.zeros((1, 6)), np.zeros((1, 3)), pm.PairParams(), 0.1, False)
    blocks = [B[0]]
    for _ in range(30):
        blocks.append(A[0] @ blocks[-1])
    s = np.linalg.svd(np.hstack(blocks), compute_uv=False)
    assert int((s > s[0] * 1e-9).sum()) == 14
