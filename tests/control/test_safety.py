"""CBF safety filter (astrobee_control.safety): a broken controller at full thrust toward a wall
in every flight mode, with and without a carried bag, on the numpy rigid body at 62.5 Hz;
transparency far from walls; infeasible starts reported, not crashed on."""
from __future__ import annotations

import numpy as np
import pytest

from astrobee import flight_modes
from astrobee import rotations as rot
from astrobee_control import mass as mp
from astrobee_control.pd import PdTracker, Reference, State
from astrobee_control.rigid_body import RigidBody
from astrobee_control.safety import (SafetyFilter, box_corners, carried_load, corridor_boxes,
                                     robot_sphere)
from astrobee_sim.world import World

DT = 1.0 / 62.5
SUBSTEPS = 4                      # the body integrates at 250 Hz under a zero-order-held wrench
MARGIN = 0.05                     # filter boundary: keep-in boxes grown by 5 cm
BAG_OFFSET = np.array([0.45, 0.0, 0.0])    # bag centre ahead of the robot (body +x)
BAG_SIZE = np.array([0.25, 0.42, 0.50])
BAG_MASS = 10.0
JEM = np.array([10.93, -6.0, 4.85])


@pytest.fixture(scope="module")
def world() -> World:
    return World.from_config()


def wall_clearance(world: World, state: State, bag: bool) -> float:
    """Smallest distance (m) from the robot's sphere / the bag's corners to a wall slab."""
    c = world.nearest(state.position[None, :])[0] - robot_sphere().radius
    if bag:
        r = rot.to_matrix(state.orientation)
        pts = state.position + np.array([s.offset for s in box_corners(BAG_OFFSET, BAG_SIZE)]) @ r.T
        c = min(c, world.nearest(pts)[0])
    return c


def make(mode_name: str, bag: bool, yaw: float, start: np.ndarray, v0: np.ndarray):
    mode = flight_modes.get(mode_name)
    q = rot.from_axis_angle(np.array([0.0, 0.0, 1.0]), yaw)
    if bag:
        mprops, com = carried_load(mp.robot(), BAG_MASS, BAG_SIZE, BAG_OFFSET)
        extent = box_corners(BAG_OFFSET, BAG_SIZE)
    else:
        mprops, com, extent = mp.robot(), np.zeros(3), []
    body = RigidBody(mprops, start, q, com_offset_body=com)
    body.v = np.asarray(v0, float).copy()
    filt = SafetyFilter(mode, mprops, com_offset=com, margin=MARGIN)
    return mode, body, filt, extent


CASES = [(m, b) for m in ("nominal", "difficult", "quiet", "precision") for b in (False, True)]


def fly_broken(world, mode_name: str, bag: bool, direction: np.ndarray, t_end: float,
               spin: bool) -> dict:
    """A broken controller driving at a wall from the middle of the JEM. Not spinning: the PD
    law tracking a goal 3 m beyond the wall (its force saturates: full thrust at the wall; its
    attitude loop still holds the attitude). Spinning: a stuck output, full body thrust toward
    the wall and full yaw torque every tick."""
    mode, body, filt, extent = make(mode_name, bag, yaw=-0.6, start=JEM, v0=np.zeros(3))
    q0 = body.state().orientation
    pd_mass = mp.with_bag(mp.robot(), BAG_MASS, BAG_SIZE, BAG_OFFSET) if bag else mp.robot()
    pd = PdTracker(mode, pd_mass)
    goal = Reference.hold(JEM + 3.0 * direction, q0)
    f_stuck = mode.max_force * np.sign(rot.to_matrix(q0).T @ direction)
    t_stuck = mode.max_torque * np.array([0.0, 0.0, 1.0])
    out = {"min_clear": np.inf, "active": 0, "fallback": 0, "speeds": []}
    for _ in range(int(t_end / DT)):
        st = body.state()
        if spin:
            f_nom, t_nom = f_stuck, t_stuck
        else:
            o = pd.step(st, goal, DT)
            f_nom, t_nom = o.force, o.torque
        res = filt.filter(f_nom, t_nom, st, extent=extent)
        assert np.all(np.abs(res.force) <= mode.max_force + 1e-9)
        assert np.all(np.abs(res.torque) <= mode.max_torque + 1e-9)
        out["active"] += res.active
        out["fallback"] += res.fallback
        for _ in range(SUBSTEPS):
            body.step(res.force, res.torque, DT / SUBSTEPS)
        out["min_clear"] = min(out["min_clear"], wall_clearance(world, body.state(), bag))
        out["speeds"].append(float(np.linalg.norm(body.state().velocity)))
    return out


@pytest.mark.parametrize("mode_name,bag", CASES)
def test_full_thrust_at_a_wall_is_stopped(world, mode_name, bag):
    # in the JEM, full thrust toward the +x/+z edge
    direction = np.array([1.0, 0.0, 0.6]) / np.linalg.norm([1.0, 0.0, 0.6])
    out = fly_broken(world, mode_name, bag, direction, 50.0, spin=False)
    assert out["min_clear"] > 0.0, "wall contact"
    assert out["min_clear"] >= world.margin - MARGIN - 1e-3, \
        f"clearance {out['min_clear']:.4f} below the margin {world.margin - MARGIN}"
    assert out["active"] > 0 and out["fallback"] == 0
    if (mode_name, bag) == ("quiet", True):
        # quiet mode's torque limit (0.026 N m) is below the torque the broken PD's own full
        # thrust makes about the robot + bag centre of mass (0.23 m x 0.22 N): its attitude
        # loop cannot hold the yaw, the rate barrier keeps the spin at 1 deg/s, and the
        # saturated body-frame force keeps sliding the robot along the wall (never into it)
        assert max(out["speeds"]) < 0.25
        return
    assert max(out["speeds"][-int(5.0 / DT):]) < 1e-3, f"not at rest: {out['speeds'][-1]:.5f} m/s"


@pytest.mark.parametrize("mode_name,bag", [("nominal", True), ("difficult", True),
                                           ("difficult", False)])
def test_spinning_full_thrust_keeps_clear(world, mode_name, bag):
    # stuck full yaw torque as well: the bag's corners swing toward the walls
    direction = np.array([1.0, 0.2, 0.6]) / np.linalg.norm([1.0, 0.2, 0.6])
    out = fly_broken(world, mode_name, bag, direction, 25.0, spin=True)
    assert out["min_clear"] >= world.margin - MARGIN - 1e-3, f"clearance {out['min_clear']:.4f}"


def test_transparent_far_from_walls():
    mode, body, filt, extent = make("nominal", True, yaw=-np.pi / 2, start=JEM, v0=np.zeros(3))
    rng = np.random.default_rng(3)
    for _ in range(50):
        f = rng.uniform(-1, 1, 3) * mode.max_force
        t = rng.uniform(-1, 1, 3) * mode.max_torque
        st = State(JEM + rng.uniform(-0.1, 0.1, 3), rng.uniform(-0.03, 0.03, 3),
                   rot.from_axis_angle(np.array([0, 0, 1.0]), -np.pi / 2 + rng.uniform(-0.1, 0.1)),
                   rng.uniform(-0.02, 0.02, 3))
        res = filt.filter(f, t, st, extent=extent)
        assert not res.active and not res.fallback and res.feasible
        assert np.all(res.barriers_h1 > 0)
        np.testing.assert_allclose(res.force, f, atol=1e-6)
        np.testing.assert_allclose(res.torque, t, atol=1e-6)
        assert res.delta_norm <= 1e-6 and res.slack == 0.0


def test_filter_changes_only_what_it_must():
    """Near a wall with a wall-ward command the result differs, is within limits and reports
    the change; a command away from the same wall passes unchanged."""
    mode = flight_modes.get("nominal")
    filt = SafetyFilter(mode, mp.robot(), margin=MARGIN)
    box = corridor_boxes(margin=MARGIN)
    st = State(np.array([11.6, -6.0, 4.85]), np.array([0.05, 0, 0]), rot.IDENTITY.copy(), np.zeros(3))
    res = filt.filter(np.array([0.68, 0.1, 0.0]), np.zeros(3), st)
    assert res.active and res.feasible and not res.fallback
    assert res.force[0] < 0.68 and res.delta_norm > 0.0
    assert res.delta_norm == pytest.approx(np.linalg.norm(res.force - [0.68, 0.1, 0.0]), abs=1e-9)
    assert box.shape[1] == 6
    away = filt.filter(np.array([-0.68, 0.1, 0.0]), np.zeros(3), st)
    assert not away.active
    np.testing.assert_allclose(away.force, [-0.68, 0.1, 0.0], atol=1e-12)


@pytest.mark.parametrize("where", ["outside", "fast_at_wall"])
def test_infeasible_start_is_reported(where):
    mode = flight_modes.get("nominal")
    filt = SafetyFilter(mode, mp.robot(), margin=MARGIN)
    if where == "outside":      # centre 0.1 m beyond the JEM's +x keep-in face
        st = State(np.array([12.1, -6.0, 4.85]), np.array([0.02, 0.0, 0.0]), rot.IDENTITY.copy(),
                   np.zeros(3))
    else:                       # 0.3 m/s toward a wall 5 cm away
        st = State(np.array([11.65, -6.0, 4.85]), np.array([0.3, 0.0, 0.0]), rot.IDENTITY.copy(),
                   np.array([0.0, 0.0, 0.1]))
    res = filt.filter(np.array([0.68, 0.0, 0.0]), np.zeros(3), st)
    assert res.fallback and not res.feasible and res.active
    assert "braking" in res.reason
    assert res.force[0] < 0 and abs(res.force[0]) == pytest.approx(mode.max_force[0])
    assert np.all(np.abs(res.force) <= mode.max_force + 1e-12)
    if where == "fast_at_wall":
        assert res.torque[2] < 0
    # the filter keeps working afterwards
    ok = filt.filter(np.zeros(3), np.zeros(3),
                     State(JEM, np.zeros(3), rot.IDENTITY.copy(), np.zeros(3)))
    assert not ok.active and ok.feasible


def test_bad_input_raises_value_error():
    filt = SafetyFilter(flight_modes.get("nominal"), mp.robot())
    st = State(JEM, np.array([np.nan, 0, 0]), rot.IDENTITY.copy(), np.zeros(3))
    with pytest.raises(ValueError):
        filt.filter(np.zeros(3), np.zeros(3), st)


def test_flight_mode_off_brakes_nothing_and_stays_within_zero_limits():
    filt = SafetyFilter(flight_modes.get("off"), mp.robot())
    st = State(JEM, np.array([0.01, 0, 0]), rot.IDENTITY.copy(), np.zeros(3))
    res = filt.filter(np.array([0.5, 0, 0]), np.zeros(3), st)
    np.testing.assert_allclose(res.force, 0.0)


def test_caller_boxes_restrict_the_candidates():
    """At the JEM hatch moving toward Node 2 the default corridor boxes (the union goes on)
    leave the command alone; given only the JEM's own keep-in box, the filter brakes."""
    filt = SafetyFilter(flight_modes.get("nominal"), mp.robot(), margin=MARGIN)
    st = State(np.array([10.93, -3.1, 4.85]), np.array([0.0, 0.1, 0.0]), rot.IDENTITY.copy(),
               np.zeros(3))
    f = np.array([0.0, 0.3, 0.0])
    assert not filt.filter(f, np.zeros(3), st).active
    jem_only = np.array([[9.85948, -9.23647, 3.78313, 11.99500, -2.75320, 5.91805]])
    res = filt.filter(f, np.zeros(3), st, boxes=jem_only + np.array([-MARGIN] * 3 + [MARGIN] * 3))
    assert res.active and res.force[1] < 0.3


def fly_stuck_torque(world, mode_name: str, bag: bool, t_end: float) -> dict:
    """A broken controller whose output is stuck at full torque about a tilted axis and full
    thrust toward the JEM's +x/+z edge: the angular rate and the walls both bind."""
    mode, body, filt, extent = make(mode_name, bag, yaw=-0.6, start=JEM, v0=np.zeros(3))
    q0 = body.state().orientation
    direction = np.array([1.0, 0.0, 0.6]) / np.linalg.norm([1.0, 0.0, 0.6])
    f_stuck = mode.max_force * np.sign(rot.to_matrix(q0).T @ direction)
    t_stuck = mode.max_torque * np.array([0.3, -0.5, 1.0])
    out = {"max_omega": 0.0, "min_clear": np.inf, "fallback": 0}
    for _ in range(int(t_end / DT)):
        res = filt.filter(f_stuck, t_stuck, body.state(), extent=extent)
        out["fallback"] += res.fallback
        for _ in range(SUBSTEPS):
            body.step(res.force, res.torque, DT / SUBSTEPS)
        st = body.state()
        out["max_omega"] = max(out["max_omega"], float(np.linalg.norm(st.omega)))
        out["min_clear"] = min(out["min_clear"], wall_clearance(world, st, bag))
    return out


@pytest.mark.parametrize("mode_name,bag", CASES)
def test_stuck_full_torque_keeps_the_angular_rate_limit(world, mode_name, bag):
    out = fly_stuck_torque(world, mode_name, bag, 15.0)
    limit = flight_modes.get(mode_name).hard_limit_omega
    # the ZOH over a 16 ms tick lets |w| pass the limit by at most alpha_max * dt: 2% here
    assert out["max_omega"] <= 1.02 * limit, f"|w| {out['max_omega']:.4f} > {limit}"
    # the stuck torque did spin the robot up (to the limit in every case but difficult with
    # the bag: 0.21 of 0.52 rad/s in 15 s, the wall barriers turning the bag's corners away)
    assert out["max_omega"] >= 0.4 * limit
    assert out["min_clear"] >= world.margin - MARGIN - 1e-3, f"clearance {out['min_clear']:.4f}"
    assert out["fallback"] == 0


def test_rate_barrier_lets_a_braking_torque_through():
    """Above the limit (a bump), a torque that slows the spin passes unchanged; one that speeds
    it up is cut."""
    mode = flight_modes.get("nominal")
    filt = SafetyFilter(mode, mp.robot(), margin=MARGIN)
    w = np.array([0.0, 0.0, 1.1 * mode.hard_limit_omega])
    st = State(JEM, np.zeros(3), rot.IDENTITY.copy(), w)
    slow = filt.filter(np.zeros(3), -mode.max_torque * np.array([0, 0, 1.0]), st)
    assert not slow.active
    fast = filt.filter(np.zeros(3), mode.max_torque * np.array([0, 0, 1.0]), st)
    assert fast.active and fast.torque[2] < 0
    assert fast.omega_barrier == pytest.approx(mode.hard_limit_omega ** 2 * (1 - 1.1 ** 2))
