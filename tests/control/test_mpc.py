"""The sampling MPC law: wall avoidance, the reduced model against a simulated bag, bad params."""
from __future__ import annotations

import numpy as np
import pytest

from astrobee import flight_modes
from astrobee import rotations as rot
from astrobee_control import mass as mp
from astrobee_control import sysid
from astrobee_control.handle_models import HandleParams, RigidBodyParams, identified_handles
from astrobee_control.law import BagObservation, ControlLaw
from astrobee_control.mpc import MpcConfig, MpcLaw
from astrobee_control.mpc import make_mpc_law
from astrobee_control.pd import State
from astrobee_control.reduced_model import ReducedModel
from astrobee_control.reference import rest_to_rest
from astrobee_control.tracking import CONTROLLING

Q = np.array([0.0, 0.0, -0.7071067811865476, 0.7071067811865476])   # facing -y (to the JEM)
HANDLE = HandleParams([29.4, 1e5, 1.46], [20.8, 0.01, 1.05], [-0.477, -0.005, -0.047])
RIGID = RigidBodyParams([-0.484, -0.001, -0.064])     # the FEM bag's model (turning pair)


def _law(samples: int = 64, handle=HANDLE) -> MpcLaw:
    return MpcLaw(flight_modes.get("nominal"), mp.robot(), ReducedModel(handle),
                  MpcConfig(samples=samples))


def test_mpc_is_a_control_law():
    assert isinstance(_law(), ControlLaw)


@pytest.mark.parametrize("handle", [HANDLE, RIGID], ids=["spring", "rigid_body"])
def test_mpc_picks_a_collision_free_candidate_where_the_nominal_hits_the_ceiling(handle):
    # Node 2 ceiling at z = 6.058; the nominal reference rises 0.3 m in 8 s into it (a planted
    # offset) while a bump sends robot and bag up at 2 cm/s
    p0 = np.array([10.95, 0.0, 5.7])
    law = _law(128, handle)
    nominal = rest_to_rest(p0, p0 + [0, 0, 0.3], Q, Q, 8.0)
    state = State(p0, np.array([0, 0, 0.02]), Q, np.zeros(3))
    bag = BagObservation(p0 + rot.rotate(Q, handle.rest_offset), Q, np.array([0, 0, 0.02]),
                         np.zeros(3), True, 10.0, np.array([0.5, 0.42, 0.25]))
    law.observe_bag(bag, state)
    law.follow(nominal, 0.0)
    step = law.update(state, 0.0, 0.016)
    d = law.last
    assert d is not None and step.state == CONTROLLING
    assert d.clearance[0] < 0, "the nominal candidate should hit the ceiling"
    assert d.best != 0 and d.clearance[d.best] > 0
    assert d.targets[d.best][2] < d.targets[0][2]          # it aims lower than the nominal
    assert step.candidates.shape[0] == 128 and step.chosen.shape == step.candidates.shape[1:]
    # the Tracker now follows the chosen plan, ending with the nominal's end
    assert law.tracker.traj is d.executed
    assert d.executed.end_time == pytest.approx(nominal.end_time)
    # no replan on the next tick; the state machine is the PD's
    assert law.update(state, 0.016, 0.016).candidates is None


def test_mpc_flies_a_short_segment_in_the_simulator():
    from astrobee_sim.simulation import Simulation
    with Simulation("node2_to_jem_bag", bag_model="constraint") as sim:
        p, q, _, _ = sim.robot_state()
        law = MpcLaw(sim.flight_mode, mp.robot(), ReducedModel(HANDLE),
                     MpcConfig(samples=32, horizon=4.0, replan_period=1.0))
        traj = rest_to_rest(p, p + [0.0, -0.3, 0.1], q, q, 8.0)
        law.follow(traj, 0.0)
        dt = 1 / 62.5
        while sim.time < 16.0 and law.segment_result == "":
            p, q, v, w = sim.robot_state()
            b = sim.bag_state()
            st = State(p, v, q, rot.rotate_inverse(q, w))
            law.observe_bag(BagObservation(b.position, b.orientation, b.velocity, b.omega, True,
                                           sim.bag.mass, sim.bag.size, "constraint"), st)
            out = law.update(st, sim.time, dt).output
            sim.command(np.concatenate([out.force, out.torque]))
            sim.advance(dt)
        assert law.segment_result == "GOAL_REACHED"
        assert sim.clearance()[1] > 0


def test_reduced_model_matches_the_constraint_bag_on_a_held_out_motion():
    handles = identified_handles()
    if "constraint" not in handles:
        pytest.skip("config/reduced_models.yaml has no constraint handle (run bench/sysid_bag.py)")
    from astrobee import config
    reported = config.load_yaml("reduced_models.yaml")["handles"]["constraint"]["identification"]
    from astrobee_sim.simulation import Simulation
    # the handle was identified on the constraint bag's five-point hold (grasp clamp)
    with Simulation("node2_to_jem_bag", bag_model="constraint", grasp="clamp") as sim:
        rec = sysid.record(sim, mp.robot(), sysid.excitation(2, moves=2))   # unseen seed
    err = sysid.error(handles["constraint"], rec)
    assert err["rms"] <= 2.0 * reported["held_out_rms"] + 1e-3


@pytest.mark.parametrize("params, word", [
    ({"samples": 0}, "samples"), ({"samples": -3}, "samples"), ({"horizon": 0.0}, "horizon"),
    ({"horizon": -1.0}, "horizon"), ({"model": "quantum"}, "model"),
    ({"replan_period": 9.0, "horizon": 5.0}, "replan_period"), ({"w_track": -1.0}, "w_track"),
])
def test_bad_parameters_are_one_line_value_errors(params, word):
    with pytest.raises(ValueError) as exc:
        make_mpc_law(flight_modes.get("nominal"), mp.robot(), {"model": "reduced", **params})
    msg = str(exc.value)
    assert word in msg and "\n" not in msg
