"""Rollout model A against the FEM bag: the identified model predicts a held-out motion of the
fast FEM bag within the reported identification error; the rigid-body rollout turns the pair."""
from __future__ import annotations

import numpy as np
import pytest

from astrobee import config, flight_modes
from astrobee import rotations as rot
from astrobee_control import mass as mp
from astrobee_control import sysid
from astrobee_control.handle_models import RigidBodyParams, identified_handles, rotate_by
from astrobee_control.reduced_model import ReducedModel


@pytest.fixture(scope="module")
def held_out():
    """A held-out motion (unseen seed, 2 moves, ~10 s) of the fast FEM bag at 200 nodes, held
    by the clamp: reduced_models.yaml's identification was made on the clamped bag (the strap,
    the default grasp since, swings: 0.156 m held-out RMS against the clamp's 0.055)."""
    from astrobee_sim.simulation import Simulation
    with Simulation("node2_to_jem_bag", bag_model="fem", bag_resolution=200,
                    fem_solver="fast", grasp="clamp") as sim:
        return sysid.record(sim, mp.robot(), sysid.excitation(2, moves=2))


def test_fem_handle_is_the_rigid_body_model():
    assert isinstance(identified_handles()["fem"], RigidBodyParams)


def test_reduced_model_matches_the_fem_bag_within_the_reported_error(held_out):
    handle = identified_handles()["fem"]
    reported = config.load_yaml("reduced_models.yaml")["handles"]["fem"]["identification"]
    fm = flight_modes.get("nominal")
    err = sysid.horizon_error(handle, held_out, fm)          # 5 s closed-loop rollouts
    assert err["bag_rms"] <= 1.5 * reported["horizon_held_out_rms"] + 0.01
    assert err["bag_max"] <= 1.5 * reported["horizon_held_out_max"] + 0.01
    assert err["robot_rms"] <= 1.5 * reported["horizon_robot_held_out_rms"] + 0.01


def test_rigid_body_rollout_turns_the_pair_under_an_off_centre_force():
    # a sideways reference step: the force at the robot's centre, off the pair's centre of
    # mass, turns robot and bag; the corners' turn is reported per step
    from astrobee_control.reduced_model import CandidateReferences, Gains, RolloutStart
    model = ReducedModel(RigidBodyParams([-0.48, 0.0, -0.06]))
    m = 50
    pos = np.zeros((2, m, 3))
    pos[1, :, 1] = 0.3
    refs = CandidateReferences(pos, np.zeros_like(pos), np.zeros_like(pos),
                               np.repeat(np.eye(3)[None], m, 0), 0.04)
    start = RolloutStart(np.zeros(3), np.zeros(3), 9.6, 19.6, np.array([-0.48, 0.0, -0.06]),
                         np.zeros(3), 10.0, np.array([0.5, 0.42, 0.25]),
                         robot_orientation=np.array([0.0, 0.0, 0.0, 1.0]))
    out = model.rollout(start, refs, Gains.from_flight_mode(flight_modes.get("nominal")))
    assert np.allclose(out.bag_turn[0], 0.0, atol=1e-9) and np.allclose(out.robot_position[0], 0)
    yaw = out.bag_turn[1, -1, 2]
    assert abs(yaw) > np.radians(2)            # the pair turned about z
    # the bag stays rigidly at its offset, turned with the pair
    rel = out.bag_position[1, -1] - out.robot_position[1, -1]
    assert np.allclose(rel, rotate_by(out.bag_turn[1, -1], np.array([-0.48, 0.0, -0.06])),
                       atol=1e-6)


# ---- _log_so3 near pi and the pair model with the swing --------------------------------------
def test_log_so3_is_right_at_and_near_pi():
    from astrobee_control.reduced_model import _exp_so3, _log_so3
    rng = np.random.default_rng(3)
    k = rng.normal(size=(8, 3))
    k /= np.linalg.norm(k, axis=1)[:, None]
    for ang in (np.pi, np.pi - 1e-6, np.pi - 1e-3, 2.0):
        v = k * ang
        got = _log_so3(_exp_so3(v))
        assert np.allclose(np.linalg.norm(got, axis=1), ang, atol=1e-6)
        assert np.allclose(_exp_so3(got), _exp_so3(v), atol=1e-6)


def _random_pair_state(rng, pm):
    def q():
        v = rng.normal(size=4)
        return v / np.linalg.norm(v)
    return pm.state(rng.normal(size=3), 0.05 * rng.normal(size=3), q(), 0.2 * rng.normal(size=3),
                    q(), 0.3 * rng.normal(size=3), 0.1 * rng.normal(size=6))


def test_pair_model_conserves_momentum_without_input():
    from astrobee_control import pair_model as pm
    p = pm.PairParams().with_(lag=0.0)
    x = _random_pair_state(np.random.default_rng(0), pm)
    lin0, ang0 = pm.momentum(x, p)
    xs = pm.rollout(x, np.zeros((625, 6)), 0.016, p)        # 10 s, joint spring working
    lin1, ang1 = pm.momentum(xs[-1], p)
    assert np.allclose(lin1, lin0, atol=1e-9)
    assert np.allclose(ang1, ang0, atol=1e-6)
    assert np.linalg.norm(xs[-1, pm.W_B] - xs[0, pm.W_B]) > 1e-3    # something did move


@pytest.mark.parametrize("name", ["defaults", "fem_bumped"])
def test_pair_model_coarse_steps_match_a_350_hz_integration(name):
    from astrobee_control import pair_model as pm
    rng = np.random.default_rng(1)
    # fem_bumped: the joint's damping was bounded in its fit so the oracle's steps stay exact
    p = (pm.PairParams() if name == "defaults" else pm.load(name)).with_(lag=0.2, bag_drag=0.5)
    x = _random_pair_state(rng, pm)
    lim = (np.array([0.68, 0.33, 0.39]), np.array([0.068, 0.033, 0.039]))
    us = rng.uniform(-1, 1, (10, 6)) * np.concatenate(lim)          # 5 s of 0.5 s commands
    coarse = pm.rollout(x, us, 0.5, p, limits=lim, substeps=2)[-1]     # the oracle's 0.25 s RK4
    fine = pm.rollout(x, np.repeat(us, 175, axis=0), 1 / 350, p, limits=lim)[-1]
    bc, _ = pm.bag_centre(coarse, p)
    bf, _ = pm.bag_centre(fine, p)
    assert np.linalg.norm(coarse[:3] - fine[:3]) < 1.5e-3       # measured 0.7 mm
    assert np.linalg.norm(bc - bf) < 3e-3                        # measured 1.6 mm


def test_pair_fit_with_a_free_bag_grasp_finds_a_planted_pendulum_length():
    """Swinging windows of a pair whose bag hangs 0.25 m from the grasp: the fit that frees the
    bag's grasp point finds the length; tied to the start's rest offset it cannot."""
    from astrobee_control import pair_model as pm
    rng = np.random.default_rng(3)
    true = pm.PairParams().with_(grasp_bag=(0.25, 0.0, 0.0), stiffness=(0.2, 0.03, 0.08),
                                 damping=(0.1, 0.05, 0.1), lag=0.0)
    start = true.with_(grasp_bag=(0.17, 0.0, 0.0))
    dt, k = 0.1, 10                                    # 1 s windows
    x0 = np.array([_random_pair_state(rng, pm) for _ in range(8)])
    x0[:, pm.A] = 0.0
    us = rng.uniform(-1, 1, (8, k, 6)) * np.array([0.3, 0.3, 0.3, 0.02, 0.02, 0.02])
    x0[:, pm.A] = us[:, 0]
    xs = pm.rollout(x0, us, dt, true, substeps=2)[:, 1:]
    bag, _ = pm.bag_centre(xs, true)
    windows = (x0, us, xs[..., :3], bag, dt)
    free = sysid.fit_pair(start, windows, max_nfev=6, free_bag=True)
    tied = sysid.fit_pair(start, windows, max_nfev=6)
    assert np.linalg.norm(np.subtract(free.grasp_bag, true.grasp_bag)) < 0.01
    e_free = sysid.pair_errors(free, windows, horizons=(1.0,))["bag_1s"]
    e_tied = sysid.pair_errors(tied, windows, horizons=(1.0,))["bag_1s"]
    assert e_free < 1e-3 and e_tied > 0.02        # measured 0.01 mm and 52 mm
    with pytest.raises(ValueError, match="damping_max must be"):
        sysid.fit_pair(start, windows, max_nfev=1, damping_max=0.0)


def test_pair_parameters_are_read_from_one_file():
    from astrobee_control import pair_model as pm
    p = pm.load("fem")
    assert p.bag_mass > 0 and min(p.bag_inertia) > 0
    assert pm.PairParams.from_dict(p.to_dict()) == p
    with pytest.raises(ValueError, match="unknown key"):
        pm.PairParams.from_dict({"stifness": [1, 1, 1]})
    with pytest.raises(ValueError, match="recorded: fem, fem_bumped"):
        pm.load("fem_bumpd")              # a misspelled name does not fly on the defaults


def _percussion_point(x, p, pm):
    """The bag's centre of percussion about the grasp (world): the point a force at the grasp
    across the strap does not move, I_grasp / (m_b L) from the grasp along it (lateral axis y)."""
    pb, _ = pm.bag_centre(x, p)
    grasp = x[pm.P_R] + pm.rotation(x[pm.Q_R]) @ np.asarray(p.grasp_robot)
    L = float(np.linalg.norm(pb - grasp))
    lq = (p.bag_inertia[2] + p.bag_mass * L * L) / (p.bag_mass * L)
    return grasp + lq * (pb - grasp) / L


def test_a_force_across_the_strap_swings_the_bag_about_its_percussion_point():
    """Why a strap-held bag's fold is not taken back by the robot's lateral force (the inline
    reference of pair_gov): on a ball joint in free fall, pushing the robot across the strap
    moves it and swings the bag but leaves the bag's centre of percussion where it was; only the
    strap's tension (a push or pull along the strap, which is across the route once it is
    folded) moves that point."""
    from astrobee_control import pair_model as pm
    p = pm.load("fem_bumped").with_(stiffness=(0.0, 0.0, 0.0), damping=(0.0, 0.0, 0.0))

    def moved(fold: float, force: np.ndarray) -> tuple[float, float]:
        """(robot's distance moved, percussion point's) after 1 s of `force` (N, world =
        body) on the robot and 1 s coasting, the bag turned `fold` rad about z."""
        x = pm.state(np.zeros(3), np.zeros(3), [0, 0, 0, 1.0], np.zeros(3),
                     rot.from_rotvec(np.array([0.0, 0.0, fold])), np.zeros(3))
        u = np.zeros((125, 6))
        u[:63, :3] = force
        xs = pm.rollout(x, u, 0.016, p)
        return (float(np.linalg.norm(xs[-1, :3])),
                float(np.linalg.norm(_percussion_point(xs[-1], p, pm)
                                     - _percussion_point(x, p, pm))))

    robot, q = moved(0.0, np.array([0.0, 0.3, 0.0]))        # across the straight strap
    assert robot > 0.03 and q < 0.02 * robot, (robot, q)     # measured 41 mm, 0.5 mm
    pb, _ = pm.bag_centre(pm.state(np.zeros(3), np.zeros(3), [0, 0, 0, 1.0], np.zeros(3),
                                   rot.from_rotvec(np.array([0.0, 0.0, 0.3])), np.zeros(3)), p)
    n = (pb - np.asarray(p.grasp_robot)) / np.linalg.norm(pb - np.asarray(p.grasp_robot))
    _, q_pushed = moved(0.3, -0.3 * n)                      # along the folded strap
    assert q_pushed > 10 * q and q_pushed > 0.005, (q_pushed, q)   # measured 20 mm


def test_pair_entry_is_stored_in_place(tmp_path):
    """bench/oracle_sysid.py's one writer: an entry's text is replaced where it stands, a new one
    appended to the section, and every other line (comments, other entries) stays."""
    import yaml
    from astrobee_control import pair_model as pm
    text = ("# the reduced models\nhandles:\n  fem: {kind: rigid}\n"
            "pair:\n  # the pushed fit\n  fem:\n    bag_mass: 9.0\n    identification: {a: 1}\n"
            "  # the bumped fit\n  fem_bumped:\n    bag_mass: 8.0\n\n# trailing words\nafter: 1\n")
    path = tmp_path / "reduced_models.yaml"
    path.write_text(text)
    p = pm.PairParams(bag_mass=11.0)
    pm.store("fem", p, {"seeds": [0, 1]}, path)
    pm.store("new", pm.PairParams(bag_mass=12.0), {}, path)
    out = path.read_text()
    for kept in ("# the reduced models", "# the pushed fit", "# the bumped fit",
                 "  fem_bumped:\n    bag_mass: 8.0", "# trailing words\nafter: 1"):
        assert kept in out, kept
    data = yaml.safe_load(out)
    assert list(data["pair"]) == ["fem", "fem_bumped", "new"]
    assert pm.PairParams.from_dict(data["pair"]["fem"]) == p
    assert data["pair"]["fem"]["identification"] == {"seeds": [0, 1]}
    assert data["pair"]["new"]["bag_mass"] == 12.0 and data["after"] == 1
