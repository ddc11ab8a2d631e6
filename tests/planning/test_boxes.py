import itertools

import numpy as np
import pytest

from astrobee import config, station
from astrobee_planning import boxes
from conftest import module_waypoints


def _in_keep_in(pts, raw):
    return np.any(np.all((pts[:, None, :] >= raw[None, :, :3] - 1e-9)
                         & (pts[:, None, :] <= raw[None, :, 3:] + 1e-9), axis=2), axis=1)


def test_robot_ball_stays_in_keep_in_set(safe):
    """Points of every safe box, with the robot's sphere around them, lie in the keep-in union."""
    raw = config.keep_in_boxes()
    r = station.robot_radius()
    rng = np.random.default_rng(0)
    dirs = rng.normal(size=(200, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    corners = np.array(list(itertools.product([0, 1], repeat=3)))
    for b in safe.boxes:
        pts = b[:3] + corners * (b[3:] - b[:3])
        pts = np.vstack([pts, b[:3] + rng.random((20, 3)) * (b[3:] - b[:3])])
        ball = (pts[:, None, :] + r * 0.999 * dirs[None]).reshape(-1, 3)
        assert _in_keep_in(ball, raw).all()


def test_hatches_connect_every_module(safe):
    wps = module_waypoints()
    assert {"node_1", "us_lab", "node_2", "eu_lab", "jem", "node_3", "cupola"} <= set(wps)
    for a, b in itertools.combinations(wps, 2):
        route = safe.route(wps[a], wps[b])
        assert safe.contains(wps[a]) and route[0] in safe.containing(wps[a])
        assert route[-1] in safe.containing(wps[b])
        for i, j in zip(route, route[1:]):
            assert j in safe.edges[i]


def test_carry_extent_shrinks_and_drops_boxes():
    s0, s1 = boxes.safe_set(), boxes.safe_set(0.5)
    assert len(s1.boxes) < len(s0.boxes)
    assert np.all(s1.boxes[:, 3:] - s1.boxes[:, :3] > 0)


def test_outside_point_and_unreachable():
    ss = boxes.safe_set()
    with pytest.raises(boxes.OutsideSafeSet):
        ss.route(np.array([0.0, 0.0, 0.0]), config.waypoint("jem"))
    two = np.array([[0, 0, 0, 2, 2, 2], [5, 5, 5, 7, 7, 7]], float)
    iso = boxes.safe_set(radius=0.2, keep_in=two)
    with pytest.raises(boxes.NoRoute):
        iso.route(np.array([1.0, 1, 1]), np.array([6.0, 6, 6]))
