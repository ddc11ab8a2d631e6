"""Bag models: grasp at the gripper, follow the robot, two-handle variants with two robots."""
import numpy as np
import pytest

from astrobee import rotations as rot
from astrobee_sim.bags import MODELS, VARIANTS, BagError, make_bag
from astrobee.errors import ScenarioError


def drive(sim, wrench, seconds):
    for _ in range(int(seconds * 62.5)):
        for name in sim.robots:
            sim.command(wrench, name)
        sim.step(6)


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("variant", ["front", "right", "top"])
def test_bag_grasped_and_carried(make_sim, model, variant):
    sim = make_sim("node2_to_jem_bag", bag_model=model, bag_variant=variant, bag_resolution=200)
    bag = sim.bag
    tip, _ = sim.robots[""].gripper_tip()
    assert np.linalg.norm(bag.handle_world(0) - tip) < 0.01
    st0 = bag.state()
    assert st0.attached == [True]
    assert np.linalg.norm(st0.velocity) < 1e-3 and st0.deformation < 1e-3
    drive(sim, [0.68, 0, 0, 0, 0, 0], 3.0)               # forward: world -y, toward the JEM
    st = bag.state()
    v_r = sim.robot_state()[2]
    assert st.position[1] < st0.position[1] - 0.1        # the bag came along
    assert v_r[1] < -0.05 and st.velocity[1] < -0.05
    assert np.linalg.norm(st.position - sim.robot_state()[0]) < 1.0
    assert abs(np.linalg.norm(st.orientation) - 1) < 1e-9


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("variant", ["front_back", "right_left", "top_bottom"])
def test_two_handle_bag_two_robots(make_sim, model, variant):
    sim = make_sim("two_robots_bag", bag_model=model, bag_variant=variant, bag_resolution=200)
    bag = sim.bag
    assert bag.state().attached == [True, True]
    for k, name in enumerate(["", "bumble"]):
        tip, _ = sim.robots[name].gripper_tip()
        assert np.linalg.norm(bag.handle_world(k) - tip) < 0.01
    # the two robots face each other across the bag
    x0 = rot.rotate(sim.robot_state("")[1], [1, 0, 0])
    x1 = rot.rotate(sim.robot_state("bumble")[1], [1, 0, 0])
    assert np.dot(x0, x1) < -0.99
    # both pull their own way gently: the bag stays between them, stretched but held
    p0 = bag.state().position
    drive(sim, [0.0, 0, 0.2, 0, 0, 0], 2.0)               # both push body +z (world up)
    st = bag.state()
    assert st.position[2] > p0[2] + 0.01                 # rigid estimate: 0.028 m
    assert np.all(np.isfinite(bag.points()))


def test_unknown_model_or_variant(make_sim):
    import pybullet as p
    c = p.connect(p.DIRECT)
    try:
        with pytest.raises(BagError):
            make_bag("jelly", c)
        with pytest.raises(BagError):
            make_bag("rigid", c, "sideways")
    finally:
        p.disconnect(c)
    with pytest.raises(ScenarioError):
        make_sim("node2_to_jem_bag", bag_variant="sideways")
    with pytest.raises(ScenarioError):
        make_sim("no_such_scenario")
    assert set(VARIANTS) == {"front", "right", "top", "front_back", "right_left", "top_bottom"}


def test_robot_list_override(make_sim):
    sim = make_sim("node2_to_jem", robots=["", "honey"])
    assert list(sim.robots) == ["", "honey"]
    a, b = sim.robot_state("")[0], sim.robot_state("honey")[0]
    assert np.linalg.norm(a - b) > 0.5
    assert sim.world.in_free_space(np.array([a, b])).all()
    assert sim.command([0.1, 0, 0, 0, 0, 0], "honey") and not sim.command([0.1] * 6, "nobody")
