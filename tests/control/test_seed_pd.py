"""pd_seed: the PD tuned as the seed tunes it, registered beside the project's laws."""
from __future__ import annotations

import numpy as np
import pytest

from astrobee import flight_modes
from astrobee import rotations as rot
from astrobee_control import mass as mp
from astrobee_control import registry
from astrobee_control.law import BagObservation
from astrobee_control.pd import Reference, State

Q = rot.normalize(np.array([0.0, 0.0, -0.7071067811865476, 0.7071067811865476]))


def _law(**params):
    return registry.get("pd_seed").make(flight_modes.get("nominal"), mp.robot(), params)


def test_registered_with_the_seeds_gains_and_clipping():
    assert "pd_seed" in registry.names()
    p = registry.get("pd_seed").params()
    assert (p["kp"], p["kv"], p["kq"], p["kw"]) == (20.0, 5.0, 1.0, 0.1)
    assert (p["max_force"], p["max_torque"]) == (0.849, 0.0849)
    with pytest.raises(ValueError, match="kp must be a finite number >= 0"):
        registry.get("pd_seed").check_params({"kp": -1.0})


def test_the_wrench_is_the_seeds_pd_clipped_by_norm_in_the_body_frame():
    law = _law()
    state = State(np.zeros(3), np.zeros(3), Q, np.zeros(3))
    out = law.pd.step(state, Reference(np.array([0.01, 0.0, 0.0]), orientation=Q), 0.016)
    # 20 N/m x 1 cm = 0.2 N along world x, below the 0.849 N clip; body frame = R^T
    assert np.allclose(rot.rotate(Q, out.force), [0.2, 0.0, 0.0], atol=1e-12)
    far = law.pd.step(state, Reference(np.array([1.0, 1.0, 0.0]), orientation=Q), 0.016)
    assert np.linalg.norm(far.force) == pytest.approx(0.849)
    assert np.allclose(rot.rotate(Q, far.force) / 0.849, [2 ** -0.5, 2 ** -0.5, 0.0])
    turned = rot.normalize(rot.multiply([0.0, 0.0, np.sin(0.05), np.cos(0.05)], Q))
    tq = law.pd.step(State(np.zeros(3), np.zeros(3), turned, np.zeros(3)),
                     Reference(np.zeros(3), orientation=Q), 0.016)
    # 0.1 rad about world z, kq 1: ~-0.1 N m, clipped by norm to 0.0849 N m, against the turn
    assert np.linalg.norm(tq.torque) == pytest.approx(0.0849)
    assert rot.rotate(turned, tq.torque)[2] < 0


def test_the_bag_is_not_fed_forward():
    law = _law()
    robot = State(np.zeros(3), np.zeros(3), Q, np.zeros(3))
    bag = BagObservation(np.array([0.0, -0.5, 0.0]), Q, np.zeros(3), np.zeros(3), True, 10.0,
                         np.array([0.5, 0.42, 0.25]), "rigid")
    law.observe_bag(bag, robot)
    assert law.carrying and law.pd.mass.mass == pytest.approx(mp.robot().mass)
