"""The predictive controller over the wrench (astrobee_control.wrench_mpc), in process: it picks
a plan that keeps the bag off a wall the unchanged plan hits (slowing down to do it), plans to
rest at the goal, bad parameters one line each."""
import numpy as np
import pytest

from astrobee import flight_modes
from astrobee import rotations as rot
from astrobee_control import mass as mp
from astrobee_control import registry
from astrobee_control.law import BagObservation
from astrobee_control.pd import State
from astrobee_control.reference import SampledTrajectory
from astrobee_control.wrench_mpc import make_wrench_mpc_law

Q = np.array([0.0, 0.0, -0.7071067811865476, 0.7071067811865476])   # body x -> world -y
SIZE = np.array([0.50, 0.42, 0.25])
OFFSET = np.array([-0.484, 0.0, -0.065])          # bag centre, robot body frame (behind)
WALL = 0.80                                        # the box's +y face


def nominal(T=6.0, L=2.0, drift=0.15):
    """A quintic rest-to-rest leg along +x drifting `drift` m towards +y (the wall)."""
    t = np.linspace(0.0, T, 61)
    s = t / T
    h, dh, ddh = (10 * s**3 - 15 * s**4 + 6 * s**5, (30 * s**2 - 60 * s**3 + 30 * s**4) / T,
                  (60 * s - 180 * s**2 + 120 * s**3) / T**2)
    d = np.array([L, drift, 0.0])
    z = np.zeros((len(t), 3))
    return SampledTrajectory(t, h[:, None] * d, dh[:, None] * d, ddh[:, None] * d,
                             np.tile(Q, (len(t), 1)), z, z)


def planned(nom, boxes, params=None, orientation=Q):
    law = make_wrench_mpc_law(flight_modes.get("nominal"), mp.robot(), params or {})
    law.mpc.boxes = boxes
    st = State(np.zeros(3), np.zeros(3), orientation, np.zeros(3))
    bag = BagObservation(rot.rotate(orientation, OFFSET), orientation, np.zeros(3), np.zeros(3),
                         True, 10.0, SIZE, "constraint")
    law.update(st, 0.0, 0.016)
    law.observe_bag(bag, st)
    law.follow(nom, 0.0)
    step = law.update(st, 0.0, 0.016)
    return law, step


def test_keeps_the_bag_off_a_wall_the_unchanged_plan_hits():
    nom = nominal()
    box = np.array([[-1.0, -1.0, -1.0, 5.0, WALL, 1.0]])
    half_y = SIZE[0] / 2                     # the bag's long side lies along world y
    nominal_bag = nom.position[:, 1] + rot.rotate(Q, OFFSET)[1] + half_y
    assert nominal_bag.max() > WALL + 0.05   # the unchanged plan puts the bag through the wall
    law, step = planned(nom, box)
    plan = law.plan
    assert plan.bag[:, 1].max() + half_y <= WALL + 0.01
    assert plan.slack < 0.01
    # it still moves on, slower than the clock (the progress variable re-times the leg)
    assert plan.robot[-1, 0] > 0.05
    assert plan.x[-1, 18] < nom.end_time - 0.5
    # the pair law's reference is the plan, and the node sees its predicted path
    assert law.predicted_path() is plan.robot
    np.testing.assert_allclose(law.traj.sample(plan.t[3]).position, plan.robot[3], atol=0.02)


def test_plans_to_rest_at_the_goal():
    nom = nominal(T=4.0, L=0.3, drift=0.0)
    law, _ = planned(nom, np.array([[-5.0, -5.0, -5.0, 5.0, 5.0, 5.0]]),
                     {"horizon": 10.0, "steps": 25})
    plan = law.plan
    assert plan.x[-1, 18] == pytest.approx(nom.end_time, abs=0.05)
    assert np.linalg.norm(plan.x[-1, 3:6]) < 0.01 and np.linalg.norm(plan.x[-1, 9:12]) < 0.02
    fin = law.traj.final()
    np.testing.assert_allclose(fin.position, nom.position[-1], atol=1e-9)


def test_wrench_within_limits():
    law, _ = planned(nominal(), np.array([[-1.0, -1.0, -1.0, 5.0, WALL, 1.0]]))
    fm = flight_modes.get("nominal")
    lim = np.concatenate([fm.max_force, fm.max_torque])
    assert np.all(np.abs(law.plan.u[:, :6]) <= lim + 1e-9)
    assert np.all((law.plan.u[:, 6] >= 0) & (law.plan.u[:, 6] <= 1))


@pytest.mark.parametrize("params, words", [
    ({"horizon": 0.0}, "horizon must be > 0 s"),
    ({"steps": 1}, "steps must be an integer in [2, 200]"),
    ({"replan_period": 10.0}, "must not exceed horizon"),
    ({"w_slack": -1.0}, "w_slack must be a finite number >= 0"),
    ({"swing_stiffness": [1.0, 2.0]}, "swing_stiffness must be three finite numbers"),
    ({"retime": "no"}, "retime must be true or false"),
    ({"lag": float("nan")}, "lag must be a finite number"),
    ({"swing_kd": -2.0}, "swing_kd must be >= 0"),
])
def test_bad_parameters_one_line(params, words):
    with pytest.raises(ValueError) as err:
        registry.get("wmpc").check_params(params)
    assert words in str(err.value) and "\n" not in str(err.value)



def test_progress_runs_at_full_rate_into_the_end():
    # 2 s of the nominal left, a 6 s horizon: the plan reaches the end at the clock's rate and
    # rests there (it used to spread the rest over the horizon, sigma = 2 / 6, and so approach
    # the end exponentially without arriving)
    nom = nominal(T=8.0, L=0.05, drift=0.0)
    law = make_wrench_mpc_law(flight_modes.get("nominal"), mp.robot(), {})
    law.mpc.boxes = np.array([[-5.0, -5.0, -5.0, 5.0, 5.0, 5.0]])
    ref = nom.sample(6.0)
    st = State(ref.position, ref.velocity, Q, np.zeros(3))
    law.observe_bag(BagObservation(ref.position + rot.rotate(Q, OFFSET), Q, ref.velocity,
                                   np.zeros(3), True, 10.0, SIZE, "constraint"), st)
    law.nominal = nom                       # on the nominal's clock at t = 6 s
    x0, fig = law.state_vector(st, 6.0)
    assert x0[18] == pytest.approx(6.0)
    plan = law.mpc.decide(6.0, x0, rot.to_matrix(Q), fig, nom, SIZE / 2)
    assert plan.u[0, 6] > 0.8
    assert plan.x[len(plan.t) // 2, 18] == pytest.approx(nom.end_time, abs=0.05)
