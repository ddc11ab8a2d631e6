"""Robot-wall contact in the batched FEM rollouts (fem_rollout + rigid_walls), against pybullet.

A robot carrying the FEM bag is driven into Node 2's ceiling at full thrust in the single-copy
simulation (pybullet robot and walls, fast FEM bag) and in FemRollout from the same state: both
stop at the wall (penetration <= 1 cm, finite), at the same place (stated tolerance 5 mm).
"""
from __future__ import annotations

import numpy as np
import pytest

from astrobee import rotations as rot
from astrobee_sim.bags.fem_fast import quat_matrices, robot_box_half
from astrobee_sim.bags.fem_rollout import FemRollout
from astrobee_sim.bags.rigid_walls import box_surface_points
from astrobee_sim.simulation import Simulation

UP = np.array([0.0, 0.0, 0.486, 0.0, 0.0, 0.0])    # full thrust (difficult), body +z = world +z
STOP_TOL = 0.005                                    # m, rollout vs pybullet stop position
PEN_MAX = 0.01                                      # m
BOX = box_surface_points(robot_box_half(), 9)


def penetration(world, centre: np.ndarray, R: np.ndarray) -> float:
    """Depth (m, >= 0) of the robot box (centre, rotation) into the nearest wall slab."""
    return max(0.0, -float(world.wall_distance(centre + BOX @ R.T).min()))


def rollout_boxes(ro: FemRollout) -> tuple[np.ndarray, np.ndarray]:
    """(K, 3) box centres and (K, 3, 3) rotations of a rollout's robots."""
    R = quat_matrices(ro.q)
    return ro.pos + np.einsum("kij,j->ki", R, ro.box_offset), R


def lifted(lift: float = 1.1, speed: float = 0.0) -> Simulation:
    """The bag scenario with robot + bag lifted (1.1 m: 6 cm below Node 2's ceiling), moving up
    at `speed`, after one step under full thrust."""
    sim = Simulation("node2_to_jem_bag", bag_model="fem", bag_resolution=200, fem_solver="fast",
                     flight_mode="difficult")
    r = sim.robots[""]
    pos, q, _, _ = r.state()
    up = np.array([0.0, 0.0, lift])
    r.set_pose(pos + up, q, velocity=(0.0, 0.0, speed))
    sim.bag.x += up
    sim.bag.v[...] = [0.0, 0.0, speed]
    sim.command(UP)
    sim.step(1)
    return sim


@pytest.fixture
def near_ceiling():
    sim = lifted()
    try:
        yield sim
    finally:
        sim.close()


def drive_both(sim, ro: FemRollout, ticks: int, free: FemRollout | None = None) -> dict:
    """Full thrust up in pybullet and in the rollout (copy 0) for `ticks` 16 ms ticks: box
    heights, deepest penetrations (after each tick; the rollout's also before its corrections)."""
    r, w = sim.robots[""], sim.world
    out = {"pen_pb": 0.0, "pen_ro": 0.0, "depth": 0.0, "z_pb": [], "z_ro": []}
    for _ in range(ticks):
        sim.command(UP)
        sim.step(6)
        ro.step(UP, 6)
        if free is not None:
            free.step(UP, 6)
        p, q, _, _ = r.state()
        out["pen_pb"] = max(out["pen_pb"], penetration(w, p, rot.to_matrix(q)))
        c, R = rollout_boxes(ro)
        out["pen_ro"] = max(out["pen_ro"], penetration(w, c[0], R[0]))
        out["depth"] = max(out["depth"], ro.wall_depth.max())
        out["z_pb"].append(p[2])
        out["z_ro"].append(c[0, 2])
    out["z_pb"], out["z_ro"] = np.array(out["z_pb"]), np.array(out["z_ro"])
    print(f"\nstop z pybullet {out['z_pb'].max():.4f} rollout {out['z_ro'].max():.4f} m, "
          f"end {out['z_pb'][-1]:.4f} / {out['z_ro'][-1]:.4f}; penetration pybullet "
          f"{out['pen_pb'] * 1e3:.2f} rollout {out['pen_ro'] * 1e3:.2f} mm (before correction "
          f"{out['depth'] * 1e3:.2f}); max |dz| "
          f"{np.abs(out['z_pb'] - out['z_ro']).max() * 1e3:.2f} mm")
    return out


def test_full_thrust_into_the_ceiling_stops_like_pybullet(near_ceiling):
    """From rest 6 cm below the ceiling: both rise, stop and rest on it, the same way."""
    sim = near_ceiling
    r, w = sim.robots[""], sim.world
    ro = FemRollout.from_bag(sim.bag, r, 2, sim.dt)
    free = FemRollout.from_bag(sim.bag, r, 1, sim.dt, robot_walls=False)
    z0 = ro.pos[0, 2]
    o = drive_both(sim, ro, 175, free)                    # 2.8 s
    assert np.all(np.isfinite(ro.x)) and np.all(np.isfinite(ro.pos))
    assert np.array_equal(ro.pos[0], ro.pos[1])          # same input, same copy
    assert ro.pos[0, 2] - z0 > 0.04                       # it did fly up to the ceiling ...
    assert free.pos[0, 2] - ro.pos[0, 2] > 0.05           # ... and without the contact, through it
    assert o["pen_pb"] <= PEN_MAX and o["pen_ro"] <= PEN_MAX and o["depth"] <= PEN_MAX
    assert abs(o["z_pb"][-1] - o["z_ro"][-1]) <= STOP_TOL
    assert np.abs(o["z_pb"] - o["z_ro"]).max() <= STOP_TOL
    # both end resting on the ceiling: the box within 2 mm of it
    p, q, _, _ = r.state()
    c, R = rollout_boxes(ro)
    assert w.wall_distance(p + BOX @ rot.to_matrix(q).T).min() < 0.002
    assert w.wall_distance(c[0] + BOX @ R[0].T).min() < 0.002


def test_impact_at_the_speed_limit_stops_like_pybullet():
    """At difficult mode's 0.4 m/s from 25 cm below the ceiling: the same stop height (the
    rebound after it, driven by the bag flying on, is chaotic and not compared)."""
    sim = lifted(0.9, 0.4)
    try:
        ro = FemRollout.from_bag(sim.bag, sim.robots[""], 1, sim.dt)
        o = drive_both(sim, ro, 60)                       # ~1 s, the impact at ~0.65 s
        assert np.all(np.isfinite(ro.x)) and np.all(np.isfinite(ro.pos))
        assert o["pen_pb"] <= PEN_MAX and o["pen_ro"] <= PEN_MAX and o["depth"] <= PEN_MAX
        assert o["z_ro"].max() - o["z_ro"][0] > 0.2       # it did fly up to the ceiling
        assert abs(o["z_pb"].max() - o["z_ro"].max()) <= STOP_TOL
    finally:
        sim.close()


@pytest.mark.parametrize("speed", [2.0, 10.0])
def test_no_tunnelling_at_any_speed(near_ceiling, speed):
    """Copies thrown at the ceiling (straight, and tilted and spinning) stay in the station."""
    sim = near_ceiling
    ro = FemRollout.from_bag(sim.bag, sim.robots[""], 3, sim.dt)
    ro.vel[:] = [0.0, 0.0, speed]
    ro.v[:] = [0.0, 0.0, speed]
    tilt = rot.from_axis_angle(np.array([1.0, 1.0, 0.0]) / np.sqrt(2), 0.5)   # a corner first
    ro.q[1] = rot.normalize(rot.multiply(tilt, ro.q[1]))
    ro.omega[2] = [0.5, -0.3, 0.2]
    snap = ro.snapshot()
    worst, touched = 0.0, np.zeros(3, bool)
    for _ in range(60):
        ro.step(UP, 6)
        touched |= ro.wall_depth > 0
        c, R = rollout_boxes(ro)
        for k in range(3):
            worst = max(worst, penetration(sim.world, c[k], R[k]))
    assert touched.all()                                  # every copy hit the ceiling
    assert np.all(np.isfinite(ro.pos)) and np.all(np.isfinite(ro.x))
    assert sim.world.in_free_space(ro.pos).all()
    assert worst <= PEN_MAX
    assert (ro.pos[:, 2] < 6.2).all()                    # below the ceiling (its face ~6.16 m)
    # the contact keeps no state of its own: a restored batch replays exactly
    end = ro.snapshot()
    ro.restore(snap)
    ro.step(UP, 360)
    assert np.array_equal(ro.pos, end["pos"]) and np.array_equal(ro.x, end["x"])


def test_open_space_is_unchanged(near_ceiling):
    """Far from walls the contact changes nothing: the same floats with and without it."""
    sim = near_ceiling
    r = sim.robots[""]
    pos, q, _, _ = r.state()
    drop = np.array([0.0, 0.0, -1.1])
    r.set_pose(pos + drop, q)
    sim.bag.x += drop
    a = FemRollout.from_bag(sim.bag, r, 2, sim.dt)
    b = FemRollout.from_bag(sim.bag, r, 2, sim.dt, robot_walls=False)
    wr = np.array([[0.3, 0.0, 0.0, 0.0, 0.0, 0.02], [0.0, -0.2, 0.1, 0.01, 0.0, 0.0]])
    a.step(wr, 175)
    b.step(wr, 175)
    assert np.array_equal(a.pos, b.pos) and np.array_equal(a.x, b.x)
    assert not a.wall_depth.any()
