"""The corridor fit (astrobee_control.corridor_fit) and pair_gov's `fit`: a bag folded below the
robot, carried on the route into the Node 2 -> JEM hatch, would strike the hatch's floor; the
fit lifts the robot's reference so the pair as it is clears it, and leaves the route alone where
nothing is near. Synthetic states on the station's real keep-in boxes (milliseconds)."""
import numpy as np
import pytest

from astrobee import config as cfg_files
from astrobee import flight_modes
from astrobee import rotations as rot
from astrobee_control import mass as mp
from astrobee_control.clearance import KeepIn
from astrobee_control.corridor_fit import CorridorFit, best_shift, pair_points, rotation
from astrobee_control.law import BagObservation
from astrobee_control.pair_governor import make_gov_law
from astrobee_control.pd import State
from astrobee_control.reference import rest_to_rest

FM = flight_modes.get("nominal")
SIZE = np.array([0.5, 0.42, 0.25])
FACE = np.array([0.0, 0.0, -0.7071067811865476, 0.7071067811865476])   # facing -y (the route)
HALF = 0.5 * float(cfg_files.astrobee()["envelope"])
TIMES = np.linspace(0.0, 4.0, 6)
# a bumped flight's fold (traced, seed 3 at 10 N): the bag 0.25 m behind and 0.43 m below,
# turned 0.5 rad about the route's cross axis
FOLDED = np.array([0.0, 0.25, -0.43])
FOLD_ROT = rot.to_matrix(rot.from_rotvec(np.array([0.5, 0.0, 0.0])))


@pytest.fixture(scope="module")
def walls() -> KeepIn:
    return KeepIn(cfg_files.keep_in_boxes())


def into_hatch(y0: float = -1.0) -> np.ndarray:
    """The plan's next 4 s on the Node 2 -> JEM centre line at 0.2 m/s, from y0."""
    return np.array([[10.945, y0 - 0.2 * t, 4.84] for t in TIMES])


def least(walls: KeepIn, route: np.ndarray, points: np.ndarray) -> float:
    d = walls.clearance(route[:, None, :] + points[None], 1.5)
    d[:, 0] -= HALF
    return float(d.min())


def folded_points(robot: np.ndarray) -> np.ndarray:
    return pair_points(robot, robot + FOLDED, FOLD_ROT, SIZE)


def test_the_fit_lifts_a_folded_bag_over_the_hatch_floor(walls):
    route = into_hatch()
    pts = folded_points(route[0])
    assert least(walls, route, pts) < 0.0          # held on its route the bag hits the floor
    shift, d = best_shift(walls, route, TIMES, pts, np.zeros(3), np.zeros(3), HALF, 0.3, 0.1)
    assert shift[2] > 0.1 and abs(shift[1]) < 1e-9    # up, across the route only
    assert d > 0.0 and d == pytest.approx(least(walls, route + shift, pts))


def test_no_shift_where_the_pair_clears_everything(walls):
    """In line and in the middle of the JEM the fit keeps the route (a shift costs clearance)."""
    route = np.array([[10.93, -5.0 - 0.2 * t, 4.85] for t in TIMES])
    pts = pair_points(route[0], route[0] + np.array([0.0, 0.48, -0.07]), np.eye(3), SIZE)
    shift, d = best_shift(walls, route, TIMES, pts, np.zeros(3), np.zeros(3), HALF, 0.3, 0.1)
    np.testing.assert_allclose(shift, 0.0)
    assert d > 0.1


def test_the_turning_pair_is_carried_on_by_its_rate(walls):
    """A pair turning about its centre: the fit judges the points where the turn takes them, so a
    bag in line now but rolling down into the floor within the horizon reads less clearance."""
    route = into_hatch()
    pts = pair_points(route[0], route[0] + np.array([0.0, 0.48, -0.07]), np.eye(3), SIZE)
    centre = 0.5 * pts[1:].mean(axis=0)
    still = best_shift(walls, route, TIMES, pts, centre, np.zeros(3), HALF, 0.0, 0.1)
    assert np.isnan(still[1])                               # reach 0: no fit
    calm = least(walls, route, pts)
    turning = np.array([-0.25, 0.0, 0.0])                   # rad/s about x: the bag swings down
    moved = np.stack([centre + (pts - centre) @ rotation(turning, t).T for t in TIMES])
    d = walls.clearance(route[:, None, :] + moved, 1.5)
    d[:, 0] -= HALF
    assert float(d.min()) < calm
    # wanting 0.3 m of clearance, the turning pair is lifted higher than the still one
    lift = [best_shift(walls, route, TIMES, pts, centre, w, HALF, 0.3, 0.3)[0][2]
            for w in (np.zeros(3), turning)]
    assert lift[1] > lift[0] + 0.05


def test_rotation_is_a_rotation():
    r = rotation(np.array([0.1, -0.2, 0.3]), 2.0)
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(r) == pytest.approx(1.0)
    # 0.1 rad/s about z for 2 s takes x to (cos 0.2, sin 0.2, 0)
    np.testing.assert_allclose(rotation(np.array([0.0, 0.0, 0.1]), 2.0) @ [1.0, 0.0, 0.0],
                               [np.cos(0.2), np.sin(0.2), 0.0], atol=1e-12)


def test_the_shift_moves_at_its_speed_and_returns_when_released(walls):
    fit = CorridorFit(walls, HALF, reach=0.3, horizon=4.0, speed=0.05)
    route = into_hatch()
    fit.decide(0.0, route, folded_points(route[0]), np.zeros(3), np.zeros(3))
    assert fit.target[2] > 0.1
    fit.advance(0.0)
    s, v = fit.advance(1.0)
    assert float(np.linalg.norm(s)) == pytest.approx(0.05) and v @ fit.target > 0
    for k in range(2, 20):
        s, v = fit.advance(float(k))
    np.testing.assert_allclose(s, fit.target)
    np.testing.assert_allclose(v, 0.0)
    fit.release()
    back, v = fit.advance(20.0)
    np.testing.assert_allclose(back, s * (1 - 0.05 / float(np.linalg.norm(s))))
    assert v[2] == pytest.approx(-0.05)


def test_pair_gov_with_fit_tracks_the_lifted_reference():
    """pair_gov `fit`: following the leg into the hatch with the folded bag, the law's position
    error grows upwards by the shift (the reference rises); without `fit` it stays on the
    route."""
    p = np.array([10.945, -1.2, 4.84])
    errors = {}
    for fit in (0.0, 0.3):
        law = make_gov_law(FM, mp.robot(), {"fit": fit})
        st = State(p, np.zeros(3), FACE, np.zeros(3))
        law.observe_bag(BagObservation(p + FOLDED, rot.from_matrix(FOLD_ROT), np.zeros(3),
                                       np.zeros(3), True, 10.0, SIZE, "fem"), st)
        law.update(st, 0.0, 0.016)
        law.follow(rest_to_rest(p, p + np.array([0.0, -2.0, 0.0]), FACE, FACE, 20.0), 0.0)
        out = None
        for k in range(1, 63):                       # 1 s, the robot held where it is
            out = law.update(st, k * 0.016, 0.016).output
        errors[fit] = np.asarray(out.position_error)
    assert abs(errors[0.0][2]) < 1e-6
    assert errors[0.3][2] == pytest.approx(0.05 * 62 * 0.016, rel=0.05)   # rising at 0.05 m/s
