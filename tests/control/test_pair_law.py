"""The pair-aware law (astrobee_control.pair_law): damps a planted swing faster than PD (in
process, the constraint bag on its default grasp, held at the start pose), registered, bad
parameters one line each."""
import numpy as np
import pytest

from astrobee import flight_modes
from astrobee_control import mass as mp
from astrobee_control import registry
from astrobee_control.law import BagObservation
from astrobee_control.pair_law import PairConfig, make_pair_law
from astrobee_control.pd import Reference, State

PUSH = {"disturbances": [{"target": "bag", "force": [5.0, 0.0, 0.0], "duration": 0.2,
                          "time": 1.0}]}


def relative_speed(controller, T=15.0):
    """Bag-robot relative speed (m/s) per tick after a push across the lever at t = 1 s."""
    from astrobee_lab.flight import Flight
    with Flight("node2_to_jem_bag", seed=0, controller=controller, bag_model="constraint",
                state_source="truth", plan=False, realism=PUSH) as f:
        f.reset()
        out = []
        while f.sim.time < T:
            f.step()
            out.append((f.sim.time, float(np.linalg.norm(np.asarray(f._bag.velocity)
                                                         - f._truth[""][2]))))
    return np.array(out)


def test_pair_law_damps_a_planted_swing_faster_than_pd():
    pd, pair = relative_speed("pd"), relative_speed("pair")
    late = lambda r: float(np.sqrt(np.mean(r[r[:, 0] >= 12.0, 1] ** 2)))   # noqa: E731
    early = lambda r: float(np.sqrt(np.mean(  # noqa: E731
        r[(r[:, 0] >= 2) & (r[:, 0] < 5), 1] ** 2)))
    assert early(pd) > 0.02 and early(pair) > 0.02          # the push did swing the bag
    # the swing decays under the pair law (by ~40% from 2-5 s to 12-15 s), not under PD (~7%)
    assert late(pair) / early(pair) < 0.8 * late(pd) / early(pd)
    assert late(pair) < late(pd)


def test_unsaturated_step_is_the_pd_of_the_centre():
    """Small errors: the body force is the pair's mass times the PD acceleration of the
    centre, the torque about the centre the inertia times the PD angular acceleration."""
    fm = flight_modes.get("nominal")
    law = make_pair_law(fm, mp.robot(), {})
    q = np.array([0.0, 0.0, 0.0, 1.0])
    st = State(np.zeros(3), np.zeros(3), q, np.zeros(3))
    bag = BagObservation(np.array([-0.484, 0.0, -0.065]), q, np.zeros(3), np.zeros(3), True,
                         10.0, np.array([0.5, 0.42, 0.25]), "constraint")
    law.observe_bag(bag, st)
    c = law.pd.pair()
    ref = Reference(np.array([0.01, 0.0, 0.0]), orientation=q)
    out = law.pd.step(st, ref, 0.016)
    kp = float(np.asarray(fm.pos_kp, float).ravel()[0])
    np.testing.assert_allclose(out.force, [c.mass * kp * 0.01, 0, 0], atol=1e-9)
    assert np.all(np.abs(out.torque) <= np.asarray(fm.max_torque) + 1e-12)


def test_registered():
    assert {"pair", "wmpc"} <= set(registry.names())
    assert registry.get("pair").make(flight_modes.get("nominal"), mp.robot()).name == "pair"


@pytest.mark.parametrize("params, words", [
    ({"swing_kd": -1.0}, "swing_kd must be >= 0"),
    ({"w_torque": "x"}, "w_torque must be a finite number"),
    ({"brake_share": 0.0}, "brake_share must be in (0, 1]"),
    ({"held": "glued"}, "held must be one of pivot, rigid"),
    ({"grasp": [0.0, 1.0]}, "grasp must be three finite numbers"),
    ({"centre": "yes"}, "centre must be true or false"),
    ({"settle_time": 0.0}, "settle_time must be > 0 s"),
    ({"hold_on_start": 2}, "hold_on_start must be true or false"),
])
def test_bad_parameters_one_line(params, words):
    with pytest.raises(ValueError) as err:
        registry.get("pair").check_params(params)
    assert words in str(err.value) and "\n" not in str(err.value)
    with pytest.raises(ValueError):
        make_pair_law(flight_modes.get("nominal"), mp.robot(), params)


def test_config_defaults_valid():
    PairConfig().validate()
