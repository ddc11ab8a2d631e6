"""PD tracker: frames, convergence on a numpy rigid body, saturation/anti-windup, bag mass."""
import numpy as np
import pytest

from astrobee import flight_modes
from astrobee import rotations as rot
from astrobee_control import mass as mp
from astrobee_control.pd import PdTracker, Reference, State
from astrobee_control.reference import rest_to_rest
from astrobee_control.rigid_body import RigidBody

DT = 1.0 / 62.5
SUB = 3  # physics substeps per control tick (~190 Hz)


def fly(tracker, body, traj, t_end):
    """Closed loop: control at 62.5 Hz, physics at 5x; returns position errors over time."""
    errs, att = [], []
    t = traj.start_time
    while t < t_end:
        ref = traj.sample(t)
        out = tracker.step(body.state(), ref, DT)
        for _ in range(SUB):
            body.step(out.force, out.torque, DT / SUB)
        t += DT
        errs.append(np.linalg.norm(body.state().position - traj.sample(t).position))
        att.append(rot.angle_between(body.state().orientation, traj.sample(t).orientation))
    return np.array(errs), np.array(att)


def test_zero_error_gives_zero_wrench():
    tr = PdTracker(flight_modes.get("nominal"), mp.robot())
    q = rot.from_euler(0.1, -0.2, 0.7)
    s = State(np.array([1.0, 2, 3]), np.zeros(3), q, np.zeros(3))
    out = tr.step(s, Reference.hold([1.0, 2, 3], q), DT)
    assert np.allclose(out.force, 0) and np.allclose(out.torque, 0)
    assert out.attitude_error_mag == pytest.approx(0, abs=1e-9)


def test_wrench_is_in_body_frame():
    """The same world-frame position error gives a force rotated into the robot's body frame."""
    fm = flight_modes.get("nominal")
    err = np.array([0.05, 0.0, 0.0])
    out_id = PdTracker(fm, mp.robot()).step(
        State(np.zeros(3), np.zeros(3), rot.IDENTITY, np.zeros(3)), Reference.hold(err, rot.IDENTITY), DT)
    q = rot.from_axis_angle([0, 0, 1], np.pi / 2)  # body x = world y
    out_rot = PdTracker(fm, mp.robot()).step(
        State(np.zeros(3), np.zeros(3), q, np.zeros(3)), Reference.hold(err, q), DT)
    assert out_id.force[0] > 0 and abs(out_id.force[1]) < 1e-12
    # world +x is body -y for a robot yawed +90 deg
    assert out_rot.force[1] == pytest.approx(-out_id.force[0])
    assert abs(out_rot.force[0]) < 1e-12
    assert np.allclose(rot.rotate(q, out_rot.force), rot.rotate(rot.IDENTITY, out_id.force))


def test_attitude_error_torque_axis_in_body_frame():
    """A robot yawed by 90 deg and pitched by a small reference offset about world x gets a
    torque about its own body axis that corresponds to world x."""
    fm = flight_modes.get("nominal")
    q = rot.from_axis_angle([0, 0, 1], np.pi / 2)
    q_ref = rot.multiply(rot.from_axis_angle([1, 0, 0], 0.05), q)  # small world-x rotation
    out = PdTracker(fm, mp.robot()).step(State(np.zeros(3), np.zeros(3), q, np.zeros(3)),
                                         Reference.hold(np.zeros(3), q_ref), DT)
    world_x_in_body = rot.rotate_inverse(q, [1, 0, 0])
    assert np.dot(out.attitude_error, world_x_in_body) == pytest.approx(0.05, rel=1e-6)
    torque_dir = out.torque / np.linalg.norm(out.torque)
    assert np.dot(torque_dir, world_x_in_body) > 0.99
    assert out.attitude_error_mag == pytest.approx(0.05, rel=1e-6)


def test_force_feedforward_is_mass_times_reference_accel():
    fm = flight_modes.get("nominal")
    tr = PdTracker(fm, mp.robot())
    ref = Reference(np.zeros(3), accel=np.array([0.01, -0.005, 0.0]))
    out = tr.step(State(np.zeros(3), np.zeros(3), rot.IDENTITY, np.zeros(3)), ref, DT)
    assert np.allclose(out.force, mp.robot().mass * ref.accel)


def test_gyroscopic_term():
    fm = flight_modes.get("nominal")
    m = mp.robot()
    tr = PdTracker(fm, m)
    w = np.array([0.1, 0.05, -0.08])
    # reference spins with the robot (same body rate, expressed in world = body at identity)
    out = tr.step(State(np.zeros(3), np.zeros(3), rot.IDENTITY, w),
                  Reference(np.zeros(3), omega=w.copy()), DT)
    assert np.allclose(out.torque, np.cross(w, m.inertia @ w))


def test_per_axis_clipping_and_anti_windup():
    fm = flight_modes.get("nominal")
    tr = PdTracker(fm, mp.robot())
    far = Reference.hold(np.array([0.0, 5.0, 0.0]), rot.IDENTITY)
    s = State(np.zeros(3), np.zeros(3), rot.IDENTITY, np.zeros(3))
    for _ in range(100):
        out = tr.step(s, far, DT)
    assert out.saturated
    assert abs(out.force[1]) == pytest.approx(fm.max_force[1])
    assert np.all(np.abs(out.force) <= fm.max_force + 1e-12)
    assert np.allclose(out.position_error_integrated, 0)  # frozen while saturated


def test_integrator_accumulates_when_not_saturated():
    fm = flight_modes.get("nominal")
    tr = PdTracker(fm, mp.robot())
    s = State(np.zeros(3), np.zeros(3), rot.IDENTITY, np.zeros(3))
    ref = Reference.hold(np.array([0.01, 0, 0]), rot.IDENTITY)
    for _ in range(10):
        out = tr.step(s, ref, DT)
    assert out.position_error_integrated[0] == pytest.approx(0.01 * 10 * DT)
    tr.reset()
    assert np.allclose(tr.step(s, ref, DT).position_error_integrated, [0.01 * DT, 0, 0])


def test_off_mode_outputs_nothing():
    tr = PdTracker(flight_modes.get("off"), mp.robot())
    out = tr.step(State(np.zeros(3), np.zeros(3), rot.IDENTITY, np.zeros(3)),
                  Reference.hold([1.0, 0, 0], rot.IDENTITY), DT)
    assert np.allclose(out.force, 0) and np.allclose(out.torque, 0)


def test_regulates_from_offset_pose():
    fm = flight_modes.get("nominal")
    q_goal = rot.from_axis_angle([0, 0, 1], -np.pi / 2)
    body = RigidBody(mp.robot(), [0.3, -0.2, 0.1], rot.multiply(rot.from_rotvec([0.2, 0.1, 0.25]), q_goal))
    tr = PdTracker(fm, mp.robot())
    traj = rest_to_rest(np.zeros(3), np.zeros(3), q_goal, q_goal, 1.0)
    errs, att = fly(tr, body, traj, 40.0)
    assert errs[0] > 0.3
    assert errs[-1] < 0.01 and att[-1] < 0.01
    assert np.linalg.norm(body.state().velocity) < 1e-3


def test_tracks_trajectory_node2_to_jem_like():
    """A 6 m, 60 s rest-to-rest move with a quarter turn: small tracking error, ends on target."""
    fm = flight_modes.get("nominal")
    p0, p1 = np.array([10.95, 0.0, 4.84]), np.array([10.93, -6.0, 4.85])
    q0 = rot.from_axis_angle([0, 0, 1], -np.pi / 2)
    q1 = rot.from_axis_angle([0, 0, 1], -np.pi / 4)
    traj = rest_to_rest(p0, p1, q0, q1, 60.0, rate=10.0)
    ref_v = np.max(np.linalg.norm(traj.velocity, axis=1))
    assert ref_v <= fm.hard_limit_vel
    body = RigidBody(mp.robot(), p0, q0)
    errs, att = fly(PdTracker(fm, mp.robot()), body, traj, 75.0)
    assert np.sqrt(np.mean(errs**2)) < 0.01
    assert np.linalg.norm(body.state().position - p1) < 0.01
    assert rot.angle_between(body.state().orientation, q1) < 0.01


def test_bag_mass_update_improves_tracking():
    """Carrying a rigid payload: the tracker told about the bag tracks better than one that is not."""
    fm = flight_modes.get("nominal")
    robot = mp.robot()
    offset = np.array([-0.45, 0.0, 0.0])  # bag behind the robot, body frame
    size = np.array([0.50, 0.42, 0.25])
    bag_m = 10.0
    combined_about_robot = mp.with_bag(robot, bag_m, size, offset)
    # plant: inertia about the combined COM
    com = bag_m * offset / (robot.mass + bag_m)
    i_com = (robot.inertia + robot.mass * (com @ com * np.eye(3) - np.outer(com, com))
             + mp.box_inertia(bag_m, size)
             + bag_m * ((offset - com) @ (offset - com) * np.eye(3) - np.outer(offset - com, offset - com)))
    plant_mass = mp.MassProperties(robot.mass + bag_m, i_com)
    p0, p1 = np.array([10.95, 0.0, 4.84]), np.array([10.93, -3.0, 4.85])
    q0 = rot.from_axis_angle([0, 0, 1], -np.pi / 2)
    traj = rest_to_rest(p0, p1, q0, q0, 40.0)
    results = {}
    for name, model in (("informed", combined_about_robot), ("naive", robot)):
        body = RigidBody(plant_mass, p0, q0, com_offset_body=com)
        errs, _ = fly(PdTracker(fm, model), body, traj, 55.0)
        results[name] = np.sqrt(np.mean(errs**2))
        assert np.linalg.norm(body.state().position - p1) < fm.tolerance_pos
    assert results["informed"] < results["naive"]


def test_with_bag_parallel_axis():
    robot = mp.robot()
    m = mp.with_bag(robot, 10.0, [0.5, 0.42, 0.25], [0.0, 0.0, 0.0])
    assert m.mass == pytest.approx(robot.mass + 10.0)
    d = mp.with_bag(robot, 10.0, [0.5, 0.42, 0.25], [-0.5, 0.0, 0.0])
    # offset along x adds m d^2 about y and z only
    diff = d.inertia - m.inertia
    assert np.allclose(np.diag(diff), [0.0, 2.5, 2.5])
    with pytest.raises(ValueError):
        mp.MassProperties(-1.0, np.ones(3))
