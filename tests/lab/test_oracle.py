"""The oracle (astrobee_lab.oracle): its CasADi model is the numeric pair model, and a tiny
planted problem answers feasible without a bump and infeasible with an impossible budget."""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("casadi")

from astrobee import flight_modes  # noqa: E402
from astrobee_control import pair_model as pm  # noqa: E402
from astrobee_lab.oracle import model, solve as so  # noqa: E402

Q = np.array([0.0, 0.0, -0.7071067811865476, 0.7071067811865476])     # facing -y (Node 2 -> JEM)
START = np.array([10.95, 0.0, 4.84])


def _random_states(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 2, 4))
    q /= np.linalg.norm(q, axis=2, keepdims=True)
    return np.concatenate([rng.normal(size=(n, 3)), 0.1 * rng.normal(size=(n, 3)), q[:, 0],
                           0.2 * rng.normal(size=(n, 3)), q[:, 1], 0.3 * rng.normal(size=(n, 3)),
                           0.2 * rng.normal(size=(n, 6))], 1)


def test_casadi_form_is_the_numeric_form():
    p = pm.PairParams().with_(lag=0.3, bag_drag=0.7, stiffness=(0.5, 0.1, 0.2), damping=(0.1, 0.05, 0.0))
    f = model.casadi_derivative(p)
    F = model.casadi_step(p, substeps=2)
    rng = np.random.default_rng(1)
    xs = _random_states(6)
    us, bs = rng.normal(size=(6, 6)), rng.normal(size=(6, 3))
    num = pm.xdot(xs, us, bs, p)
    step = pm.rk4(xs, us, bs, p, 0.5, substeps=2)
    for i in range(6):
        assert np.allclose(np.asarray(f(xs[i], us[i], bs[i])).ravel(), num[i], rtol=1e-10, atol=1e-12)
        assert np.allclose(np.asarray(F(xs[i], us[i], bs[i], 0.5)).ravel(), step[i], atol=1e-10)


def _leg(offset: np.ndarray) -> so.Leg:
    goal = START + offset
    return so.Leg(np.array([0.0]), goal[None], np.zeros((1, 3)), np.zeros((1, 3)), Q[None], goal, Q,
                  flight_modes.get("nominal"), np.array([0.50, 0.42, 0.25]))


def _start(p: pm.PairParams) -> np.ndarray:
    return pm.state(START, np.zeros(3), Q, np.zeros(3), Q, np.zeros(3))


def test_oracle_finds_a_planted_move_feasible_without_a_bump():
    p = pm.PairParams()
    r = so.solve(_leg(np.array([0.0, -0.35, 0.0])), p, None, budget=12.0, x0=_start(p), jit=False)
    assert r.feasible, r.row()
    assert r.violation["goal"] <= 0.2 and r.violation["rest_speed"] < 0.01


def test_oracle_margin_leaves_room_inside_the_terminal_set():
    """The effort cost ends a plan on the edge of what the NLP asks; a plan to be flown asks
    for a smaller share of the thresholds (margin) and ends inside it."""
    p = pm.PairParams()
    r = so.solve(_leg(np.array([0.0, -0.35, 0.0])), p, None, budget=12.0, x0=_start(p), jit=False,
                 margin=0.2)
    assert r.feasible, r.row()
    assert r.violation["goal"] <= 0.2 * 0.2 + 1e-3
    assert r.violation["rest_speed"] <= 0.2 * so.REST_SPEED + 1e-4   # default margin: 0.0048


def test_oracle_calls_an_impossible_budget_infeasible():
    p = pm.PairParams()
    r = so.solve(_leg(np.array([0.0, -1.5, 0.0])), p, None, budget=4.0, x0=_start(p), jit=False)
    assert not r.feasible
    assert r.violation["goal"] > 0.2


def test_bump_of_seed_is_the_simulators_draw():
    b = so.bump_of_seed(3, 5.0)
    assert 10.0 <= b.time <= 30.0 and b.duration == pytest.approx(0.2, abs=1e-9)
    assert np.linalg.norm(b.force) == pytest.approx(5.0)
    assert so.bump_of_seed(3, 10.0).time == b.time            # the seed alone draws time, direction
    assert np.allclose(np.asarray(so.bump_of_seed(3, 10.0).force), 2 * np.asarray(b.force))


def test_a_replan_from_a_mid_state_warm_starts_and_stays_feasible():
    p = pm.PairParams()
    leg = _leg(np.array([0.0, -0.35, 0.0]))
    first = so.solve(leg, p, None, budget=12.0, x0=_start(p), jit=False)
    k = len(first.t) // 3
    again = so.solve(leg, p, None, budget=12.0, t0=float(first.t[k]), x0=first.x[k], guess=first, jit=False)
    assert again.feasible, again.row()
    assert again.t[0] == first.t[k] and np.allclose(again.x[0], first.x[k])


def test_mode_limits_bound_the_robots_speed_and_rate():
    """mode_limits: the robot's speed and rate stay within the flight mode's hard limits at
    every node (after the bump). A start already faster than the mode allows (0.25 m/s towards
    a goal 1 m away, 0.2 m/s allowed) cannot get under it by the next node: infeasible with
    the limits, feasible without; a planted move within them is feasible with them too."""
    p = pm.PairParams()
    mode = flight_modes.get("nominal")
    x0 = pm.state(START, np.array([0.0, -0.25, 0.0]), Q, np.zeros(3), Q, np.zeros(3))
    leg = _leg(np.array([0.0, -1.0, 0.0]))
    free = so.solve(leg, p, None, budget=14.0, x0=x0, jit=False)
    held = so.solve(leg, p, None, budget=14.0, x0=x0, jit=False, mode_limits=True)
    assert free.feasible, free.row()
    assert not held.feasible
    assert held.violation["speed_max"] > mode.hard_limit_vel * (1 + so.LIMIT_TOL)
    calm = so.solve(_leg(np.array([0.0, -0.35, 0.0])), p, None, budget=12.0, x0=_start(p),
                    jit=False, mode_limits=True)
    assert calm.feasible, calm.row()
    assert calm.violation["speed_max"] <= mode.hard_limit_vel * (1 + so.LIMIT_TOL)
    assert calm.violation["rate_max"] <= mode.hard_limit_omega * (1 + so.LIMIT_TOL)
