"""The wrench MPC hands the pair law the plan's own wrench as feed-forward (astrobee_control.
wrench_mpc.WrenchMpcLaw._executed): within each plan step the reference's acceleration is the
step's planned force over the pair's mass, and the law's output follows the planned wrench.
Before, the feed-forward was a central difference of the predicted velocities: it blended
adjacent steps (zero for a bang-bang plan) and after a 5 N bump the applied torque agreed in
sign with the planned one on ~50% of the decisions (FEM strap, seed 0)."""
import numpy as np

from astrobee import rotations as rot
from astrobee_control.pd import State

from test_wrench_mpc import Q, WALL, nominal, planned


def test_reference_feed_forward_is_the_planned_wrench_step_by_step():
    law, _ = planned(nominal(), np.array([[-1.0, -1.0, -1.0, 5.0, WALL, 1.0]]))
    plan, pair = law.plan, law.pd.pair()
    R = rot.to_matrix(Q)
    dt = plan.t[1] - plan.t[0]
    for k in range(4):
        for frac in (0.1, 0.5, 0.9):
            ref = law.traj.sample(plan.t[k] + frac * dt)
            np.testing.assert_allclose(ref.accel, R @ plan.u[k, :3] / pair.mass, atol=2e-3)


def test_the_law_applies_the_planned_force_on_its_plan():
    law, _ = planned(nominal(), np.array([[-1.0, -1.0, -1.0, 5.0, WALL, 1.0]]))
    plan = law.plan
    ref = law.traj.sample(plan.t[0] + 0.05)
    st = State(ref.position, ref.velocity, ref.orientation, ref.omega)
    step = law.update(st, plan.t[0] + 0.05, 0.016)
    np.testing.assert_allclose(step.output.force, plan.u[0, :3], atol=0.05)
