"""Free robot dynamics against the analytic rigid body; clipping per flight mode; bad commands."""
import numpy as np
import pytest
from scipy.integrate import quad

from astrobee import config, flight_modes
from astrobee import rotations as rot


def test_constant_body_wrench_matches_analytic(make_sim):
    sim = make_sim("node2_to_jem", flight_mode="difficult")
    r = sim.robots[""]
    m, Izz = r.mass, r.inertia[2]
    F, tz = np.array([0.3, 0.1, 0.0]), 0.02           # within the difficult-mode limits
    c0 = r.com().copy()
    _, q0 = r.pose()
    T = 4.0
    for _ in range(int(T * 62.5)):
        sim.command(np.r_[F, 0, 0, tz])
        sim.step(6)
    t = sim.time
    # rotation about the (principal) body z: theta = tz/(2 Izz) t^2; the body force turns with it
    alpha = tz / Izz
    yaw0 = 2 * np.arctan2(q0[2], q0[3])

    def acc(s, k):
        th = yaw0 + 0.5 * alpha * s * s
        a = np.array([np.cos(th) * F[0] - np.sin(th) * F[1], np.sin(th) * F[0] + np.cos(th) * F[1]]) / m
        return a[k]
    # position = int_0^t (t - s) a(s) ds
    expect_xy = [quad(lambda s: (t - s) * acc(s, k), 0, t, limit=200)[0] for k in range(2)]
    got = r.com() - c0
    assert np.allclose(got[:2], expect_xy, atol=2e-3 * np.linalg.norm(expect_xy) + 1e-4), (got, expect_xy)
    assert abs(got[2]) < 1e-3
    _, _, _, w = sim.robot_state()
    assert abs(w[2] - alpha * t) < 0.01 * alpha * t
    assert np.linalg.norm(w[:2]) < 0.01 * alpha * t


@pytest.mark.parametrize("mode", ["quiet", "nominal", "difficult", "precision", "off"])
def test_clipping_per_flight_mode(make_sim, mode):
    sim = make_sim("node2_to_jem")
    sim.set_flight_mode(mode)
    fm = flight_modes.get(mode)
    big = np.array([5.0, -5.0, 5.0, 1.0, -1.0, 1.0])
    assert sim.command(big)
    lim = np.r_[fm.max_force, fm.max_torque]
    assert np.allclose(sim.robots[""].wrench_cmd, big.clip(-lim, lim))
    # and the robot really accelerates at the clipped force
    v0 = sim.robot_state()[2]
    for _ in range(31):
        sim.command(np.r_[big[:3], 0, 0, 0])
        sim.step(6)
    _, q, v, _ = sim.robot_state()
    a_body = rot.rotate_inverse(q, (v - v0) / sim.time)
    assert np.allclose(a_body * sim.robots[""].mass, np.array([1, -1, 1]) * fm.max_force, atol=2e-3)


def test_propulsion_table_from_config():
    prop = config.astrobee()["propulsion"]
    assert np.allclose(flight_modes.get("difficult").max_force, prop[3]["force"])
    assert np.allclose(flight_modes.get("quiet").max_force, [0.452, 0.216, 0.257])


@pytest.mark.parametrize("bad", [[np.nan, 0, 0, 0, 0, 0], [0, np.inf, 0, 0, 0, 0],
                                 [1e6, 0, 0, 0, 0, 0], [0, 0, 0, 0, 0, -1e9], [1, 2, 3]])
def test_bad_wrench_rejected(make_sim, bad):
    sim = make_sim("node2_to_jem")
    assert sim.command([0.1, 0, 0, 0, 0, 0])
    held = sim.robots[""].wrench_cmd.copy()
    assert not sim.command(bad)
    assert sim.rejected == 1
    assert np.array_equal(sim.robots[""].wrench_cmd, held)
    sim.step(350)
    pos, q, v, w = sim.robot_state()
    assert np.all(np.isfinite(np.r_[pos, q, v, w])) and np.linalg.norm(v) < 0.1


def test_watchdog_zeroes_wrench_and_raises_fault(make_sim):
    sim = make_sim("node2_to_jem")
    sim.command([0.3, 0, 0, 0, 0, 0])
    sim.step(int(0.3 * 350))
    assert not sim.fault[""]
    sim.step(int(0.05 * 350))                            # 0.35 s without a command
    assert sim.fault[""]
    v1 = sim.robot_state()[2]
    sim.step(350)
    assert np.allclose(sim.robot_state()[2], v1, atol=1e-6)   # coasting: no thrust
    sim.command([0.3, 0, 0, 0, 0, 0])
    sim.step(1)
    assert not sim.fault[""]


def test_arm_and_gripper_position_control(make_sim):
    sim = make_sim("node2_to_jem")
    r = sim.robots[""]
    arm = config.astrobee()["arm"]
    assert abs(r.joint_positions()["arm_proximal_joint"] - arm["stowed"]["proximal"]) < 1e-6
    r.deploy_arm(True)
    r.gripper(True)
    sim.step(int(20 * 350))                             # 0.12 rad/s: ~13 s for 90 degrees
    j = r.joint_positions()
    assert abs(j["arm_proximal_joint"] - arm["deployed"]["proximal"]) < 0.02
    assert abs(j["finger_left_joint"] - arm["gripper_open"] / 2) < 2e-3


def test_mass_and_inertia_match_config(make_sim):
    import pybullet as p
    sim = make_sim("node2_to_jem")
    r = sim.robots[""]
    masses = [p.getDynamicsInfo(r.id, j, physicsClientId=sim.client)[0]
              for j in range(-1, p.getNumJoints(r.id, physicsClientId=sim.client))]
    assert abs(sum(masses) - config.astrobee()["mass"]) < 1e-6
    # angular acceleration about each axis matches the configured whole-robot inertia
    for ax in range(3):
        sim.reset()
        tau = np.zeros(6)
        tau[3 + ax] = 0.02
        for _ in range(25):
            sim.command(tau)
            sim.step(6)
        w = sim.robot_state()[3]
        _, q, _, _ = sim.robot_state()
        w_body = rot.rotate_inverse(q, w)
        assert abs(w_body[ax] - 0.02 / r.inertia[ax] * sim.time) < 0.03 * 0.02 / r.inertia[ax] * sim.time


def test_optional_drag_slows_the_robot(make_sim):
    speeds = {}
    for drag in (False, True):
        sim = make_sim("node2_to_jem", drag=drag)
        r = sim.robots[""]
        r.set_pose(*sim.robot_state()[:2], velocity=(0, -0.5, 0))
        sim.step(350 * 2)                                  # no command: coasting
        speeds[drag] = np.linalg.norm(sim.robot_state()[2])
    assert abs(speeds[False] - 0.5) < 1e-6
    # quadratic drag: dv/dt = -k v^2 / m  ->  v = v0 / (1 + k v0 t / m)
    cfg = config.astrobee()
    k = 0.5 * cfg["air_density"] * cfg["drag_coefficient"] * cfg["drag_area"]
    expect = 0.5 / (1 + k * 0.5 * 2.0 / cfg["mass"])
    assert abs(speeds[True] - expect) < 2e-3 and speeds[True] < 0.5
