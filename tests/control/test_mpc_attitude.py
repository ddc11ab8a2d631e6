"""The attitude-aware sampling MPC: recovery references, torque limits, the attitude cost,
time scaling, the fallback, and a short in-process flight."""
from __future__ import annotations

import numpy as np
import pytest

from astrobee import flight_modes
from astrobee import rotations as rot
from astrobee_control import mass as mp
from astrobee_control.law import BagObservation
from astrobee_control.attitude_recovery import (attitude_candidates, recovery_profile,
                                                shortest_recovery)
from astrobee_control.mpc import MpcConfig, MpcLaw
from astrobee_control.pd import State
from astrobee_control.handle_models import RigidBodyParams
from astrobee_control.reduced_model import ReducedModel, Rollouts, RolloutStart, compound_inertia
from astrobee_control.reference import rest_to_rest
from astrobee_control.tracking import CONTROLLING

Q = np.array([0.0, 0.0, -0.7071067811865476, 0.7071067811865476])   # facing -y (to the JEM)
RIGID = RigidBodyParams([-0.484, -0.001, -0.064])                   # the FEM bag's turning pair
P0 = np.array([10.95, 0.0, 4.84])
SIZE = np.array([0.5, 0.42, 0.25])


def _spun(tilt: float = 0.3, rate: float = 0.1) -> State:
    """The robot turned `tilt` rad about its body y axis off Q, turning on at `rate` rad/s."""
    return State(P0.copy(), np.zeros(3), rot.multiply(Q, rot.from_rotvec([0.0, tilt, 0.0])),
                 np.array([0.0, rate, 0.0]))


def _law(samples: int = 64, **kw) -> MpcLaw:
    law = MpcLaw(flight_modes.get("nominal"), mp.robot(), ReducedModel(RIGID, {}),
                 MpcConfig(samples=samples, attitude=True, **kw))
    law.follow(rest_to_rest(P0, P0 + [0.0, -2.0, 0.0], Q, Q, 30.0), 0.0)
    return law


def _carry(law: MpcLaw, state: State) -> None:
    law.observe_bag(BagObservation(state.position + rot.rotate(state.orientation,
                                                                RIGID.rest_offset),
                                   state.orientation, np.zeros(3), np.zeros(3), True, 7.0, SIZE,
                                   "fem"), state)


def _inertia() -> np.ndarray:
    start = RolloutStart(P0, np.zeros(3), mp.robot().mass, mp.robot().mass, P0, np.zeros(3), 7.0,
                         SIZE, None, np.eye(3), Q, None, mp.robot().inertia)
    return compound_inertia(start, RIGID.rest_offset)[0]


def test_recovery_profile_leaves_from_the_present_offset_and_rests_at_zero():
    e0, r0 = np.array([0.1, -0.3, 0.2]), np.array([0.0, 0.05, -0.02])
    Tc = np.array([6.0, 12.0])
    t = np.array([0.0, 6.0, 12.0, 20.0])
    x, v, a = recovery_profile(e0, r0, Tc, t)
    np.testing.assert_allclose(x[:, 0], [e0, e0], atol=1e-12)
    np.testing.assert_allclose(v[:, 0], [r0, r0], atol=1e-12)
    np.testing.assert_allclose(x[0, 1:], 0.0, atol=1e-12)           # at rest from Tc on
    np.testing.assert_allclose(v[0, 1:], 0.0, atol=1e-12)
    np.testing.assert_allclose(x[1, 2:], 0.0, atol=1e-12)
    assert np.all(np.abs(x[1, 1]) > 0)                                 # still under way


def test_attitude_candidates_exist_start_at_the_present_attitude_within_torque_limits():
    fm = flight_modes.get("nominal")
    nom = rest_to_rest(P0, P0 + [0.0, -2.0, 0.0], Q, Q, 30.0)
    state = _spun()
    n, m, share, margin = 40, 50, 0.5, 0.7
    t = np.linspace(0.0, 5.0, m + 1)
    scales = np.ones(n)
    tau = scales[:, None] * t[None]
    inertia = _inertia()
    cfg = MpcConfig(samples=n, attitude=True, attitude_share=share, torque_margin=margin)
    plan = attitude_candidates(nom, tau, t, state, scales, inertia, np.asarray(fm.max_torque),
                               cfg, np.random.default_rng(0), n, np.array([-0.2, 0.0, -0.03]))
    recovery = np.isfinite(plan.recovery_time)
    assert recovery.sum() == int(share * n) + 1               # the last half and the warm start
    assert not recovery[0]                                     # candidate 0 is the nominal
    np.testing.assert_allclose(plan.rotation[0], plan.nominal_rotation[0], atol=1e-12)
    np.testing.assert_allclose(plan.shift[~recovery], 0.0)
    R_now = rot.to_matrix(state.orientation)
    for i in np.flatnonzero(recovery):
        np.testing.assert_allclose(plan.rotation[i, 0], R_now, atol=1e-9)
        assert np.all(plan.peak_torque[i] <= margin * np.asarray(fm.max_torque) + 1e-9), i
        np.testing.assert_allclose(plan.shift[i, 0], 0.0, atol=1e-12)   # leaves from here
    # the shortest recovery is the shortest feasible one: a quicker one breaks the limits
    e0 = np.array([0.0, 0.3, 0.0])
    r0 = np.array([0.0, 0.1, 0.0])
    T0 = shortest_recovery(e0, r0, inertia, np.asarray(fm.max_torque), margin)
    _, _, a = recovery_profile(e0, r0, np.array([0.8 * T0]), np.linspace(0, 0.8 * T0, 41))
    assert np.any(np.abs(a[0] @ inertia.T).max(axis=0) > margin * np.asarray(fm.max_torque))


def test_the_cost_prefers_the_candidate_that_takes_the_attitude_back():
    law = _law(8)
    state = _spun()
    _carry(law, state)
    m = 50
    n = 2
    nom_R = np.broadcast_to(rot.to_matrix(Q), (n, m + 1, 3, 3)).copy()
    tilt = rot.to_matrix(rot.multiply(Q, rot.from_rotvec([0.0, 0.4, 0.0])))
    back = rot.to_matrix(rot.multiply(Q, rot.from_rotvec([0.0, 0.05, 0.0])))
    rotation = np.stack([np.broadcast_to(tilt, (m, 3, 3)), np.broadcast_to(back, (m, 3, 3))])
    omega = np.zeros((n, m, 3))
    omega[0, -1] = [0.0, 0.1, 0.0]                 # still turning away at the end
    pos = np.broadcast_to(P0, (n, m, 3)).copy()
    out = Rollouts(pos, np.zeros_like(pos), pos + [-0.48, 0, 0], np.zeros_like(pos),
                   np.zeros_like(pos), np.zeros((n, m, 3)), rotation, omega, _inertia())
    plan = type("Plan", (), {"nominal_rotation": nom_R})()
    tau = np.broadcast_to(np.linspace(0.1, 5.0, m), (n, m)).copy()
    costs, _, att_end = law._score_attitude(out, law.nominal, tau, plan, law._start(state),
                                            np.ones(n), 5.0)
    assert att_end[0] == pytest.approx(0.4, abs=1e-6) and att_end[1] == pytest.approx(0.05, abs=1e-6)
    assert costs[1] < costs[0]


def test_a_decision_on_a_spun_pair_ends_nearer_the_nominal_attitude_than_the_nominal():
    law = _law(128, w_attitude=100.0)
    state = _spun()
    _carry(law, state)
    d = law.decide(state, 0.0)
    assert d.attitude_error.min() < 0.5 * d.attitude_error[0]      # candidates that turn back
    assert d is not None and d.attitude_error is not None
    assert d.attitude_error[d.best] < d.attitude_error[0]
    assert d.costs[d.best] <= d.costs[0]
    # the executed plan starts on the chosen candidate and ends on the nominal's final pose
    assert d.executed.end_time >= law.nominal.end_time
    assert rot.angle_between(d.executed.orientation[-1], Q) < 1e-9


def test_time_scaling_books_the_delay_and_never_exceeds_max_delay():
    law = _law(32, w_delay=0.0, w_track=0.0, time_scale_min=0.0, max_delay=2.5)
    state = _spun(0.6, 0.15)
    _carry(law, state)
    delays = []
    for k in range(6):
        d = law.decide(state, float(k))
        delays.append(law._delay)
        assert d.delay.min() == 0.0 and d.delay[0] == 0.0        # the nominal never waits
        assert law._delay <= 2.5 + 1e-9
        assert d.executed.end_time == pytest.approx(law.nominal.end_time + law._delay, abs=0.11) \
            or d.executed.end_time >= law.nominal.end_time
    assert np.all(np.diff(delays) >= 0)


def test_at_the_segment_end_a_turning_pair_is_held_longer_within_max_delay():
    law = _law(16, max_delay=2.0, replan_period=1.0)
    law.follow(rest_to_rest(P0, P0 + [0.0, -0.1, 0.0], Q, Q, 3.0), 0.0)
    state = _spun(0.4, 0.1)
    _carry(law, state)
    law._next_replan = 1e9                          # no decisions: the end-of-segment hold alone
    end = law.tracker.traj.end_time
    law.update(state, end - 0.01, 0.016)            # about to end, still turning: held 1 s more
    assert law.tracker.traj.end_time == pytest.approx(end + 1.0) and law._delay == 1.0
    np.testing.assert_allclose(law.tracker.traj.position[-1], P0 + [0.0, -0.1, 0.0], atol=1e-9)
    law.update(state, end + 0.995, 0.016)
    assert law.tracker.traj.end_time == pytest.approx(end + 2.0) and law._delay == 2.0
    law.update(state, end + 1.995, 0.016)           # max_delay spent: the segment ends
    assert law._delay == 2.0
    law.update(state, end + 2.01, 0.016)
    assert law.state != CONTROLLING
    # at rest at the final attitude: not held
    calm = _law(16)
    calm.follow(rest_to_rest(P0, P0 + [0.0, -0.1, 0.0], Q, Q, 3.0), 0.0)
    still = State(P0 + [0.0, -0.1, 0.0], np.zeros(3), Q, np.zeros(3))
    _carry(calm, still)
    calm._next_replan = 1e9
    calm.update(still, calm.tracker.traj.end_time - 0.01, 0.016)
    assert calm._delay == 0.0


def test_the_hold_about_the_centre_of_mass_aims_where_the_centre_sits_at_the_goal():
    law = _law(16, hold_about_centre=True)
    law.follow(rest_to_rest(P0, P0 + [0.0, -0.1, 0.0], Q, Q, 3.0), 0.0)
    state = _spun(0.4, 0.1)
    _carry(law, state)
    law._next_replan = 1e9
    end = law.tracker.traj.end_time
    law.update(state, end - 0.01, 0.016)
    assert law._delay == 1.0
    goal = P0 + [0.0, -0.1, 0.0]
    c = law._centre
    assert np.linalg.norm(c) > 0.15
    want = goal + rot.rotate(Q, c) - rot.rotate(state.orientation, c)
    np.testing.assert_allclose(law.tracker.traj.position[0], want, atol=1e-9)
    assert rot.angle_between(law.tracker.traj.orientation[0], Q) < 1e-9


def test_without_a_bag_the_attitude_mode_makes_the_translation_only_decision():
    state = State(P0.copy(), np.zeros(3), Q, np.zeros(3))
    a, b = _law(32), _law(32)
    b.config.attitude = False
    da, db = a.decide(state, 0.0), b.decide(state, 0.0)
    np.testing.assert_array_equal(da.costs, db.costs)
    assert da.attitude_error is None


def test_attitude_parameters_are_checked():
    with pytest.raises(ValueError, match="torque_margin"):
        MpcConfig(torque_margin=0.0).validate()
    with pytest.raises(ValueError, match="time_scale_min"):
        MpcConfig(time_scale_min=1.5).validate()


def test_the_attitude_mpc_flies_a_short_hop_with_a_rigid_bag():
    pytest.importorskip("pybullet")
    from astrobee.scenario import Scenario
    from astrobee_lab.flight import Flight
    hop = Scenario.from_dict({
        "description": "short hop (attitude MPC test)", "flight_mode": "nominal",
        "robots": [{"name": "", "position": [10.95, 0.6, 4.84], "orientation": Q.tolist()}],
        "bag": {"model": "rigid", "variant": "front", "mass": 10.0},
        "goal": {"position": [10.95, 0.2, 4.84], "orientation": Q.tolist()}}, "hop")
    laws = []

    def factory(fm, mass, params):
        law = MpcLaw(fm, mass, ReducedModel(RIGID, {}),     # the turning model on this bag too
                     MpcConfig(samples=32, attitude=True))
        laws.append(law)
        return law

    with Flight(hop, seed=0, controller=factory) as f:
        res = f.run()
    assert res.success, res.cause
    assert res.metrics["contacts"] == 0
    assert laws[-1].last is not None and laws[-1].last.attitude_error is not None  # it decided
