"""The wrench MPC's corridor boxes (astrobee_control.wrench_qp.corridor): a body passing a hatch
from one keep-in box to the next is held in a convex box inside their union, so the nominal
itself is feasible (one module's box alone, shrunk by the bag's half size, is not: the plan
then paid corridor slack on a fault-free leg)."""
import numpy as np

from astrobee_control.reference import SampledTrajectory
from astrobee_control.wrench_qp import corridor, junction_boxes

from test_wrench_mpc import planned

MODULE = [-1.5, -1.0, -1.0, 1.0, 1.0, 1.0]
HATCH = [1.0, -0.5, -0.5, 4.0, 0.5, 0.5]
IDENTITY = np.array([0.0, 0.0, 0.0, 1.0])


def straight(T=6.0, L=2.0):
    """A quintic rest-to-rest leg along +x (the bag trails behind the robot, towards -x)."""
    t = np.linspace(0.0, T, 61)
    s = t / T
    h, dh, ddh = (10 * s**3 - 15 * s**4 + 6 * s**5, (30 * s**2 - 60 * s**3 + 30 * s**4) / T,
                  (60 * s - 180 * s**2 + 120 * s**3) / T**2)
    d = np.array([L, 0.0, 0.0])
    z = np.zeros((len(t), 3))
    return SampledTrajectory(t, h[:, None] * d, dh[:, None] * d, ddh[:, None] * d,
                             np.tile(IDENTITY, (len(t), 1)), z, z)


def test_junction_boxes_lie_inside_the_union():
    boxes = np.array([MODULE, HATCH, [3.0, -2.0, -0.3, 3.5, 2.0, 0.3]])
    rng = np.random.default_rng(0)
    for b in junction_boxes(boxes):
        pts = b[:3] + rng.random((400, 3)) * (b[3:] - b[:3])
        inside = np.any(np.all((pts[:, None] >= boxes[None, :, :3] - 1e-9)
                               & (pts[:, None] <= boxes[None, :, 3:] + 1e-9), axis=2), axis=1)
        assert inside.all()


def test_a_bag_passing_a_hatch_stays_in_its_corridor():
    boxes = np.array([MODULE, HATCH])
    bag = np.array([[x, 0.0, -0.065] for x in np.linspace(-0.5, 1.6, 43)])
    half = np.array([0.25, 0.21, 0.125]) + 0.03
    box = corridor(junction_boxes(boxes), bag, half)
    assert np.all(box[:, :3] <= bag + 1e-9) and np.all(bag <= box[:, 3:] + 1e-9)
    # where neither box alone, shrunk, holds the bag
    assert np.any((bag[:, 0] > MODULE[3] - half[0]) & (bag[:, 0] < HATCH[0] + half[0]))


def test_the_plan_through_a_hatch_needs_no_slack():
    # the robot starts 0.15 m into the hatch, the bag 0.33 m before it (the world shifted so
    # the robot starts at the origin)
    boxes = np.array([MODULE, HATCH]) - np.array([1.15, 0, 0, 1.15, 0, 0])
    law, _ = planned(straight(T=15.0, L=1.5), boxes, orientation=IDENTITY)
    assert law.plan.bag[:, 0].max() > -0.1          # the bag is carried into the hatch
    assert law.plan.slack < 0.01
