"""The robot's sphere stays inside the station on every planned route: every ordered pair of the
module waypoints of config/iss.yaml, sampled densely (<= 2 cm apart), checked two ways against
the raw keep-in boxes (not the planner's own safe set):
- exactly, per sample: the sphere lies inside one keep-in box, or inside the span of two
  touching boxes through their shared opening (astrobee.station.passage_boxes), each shrunk by the radius;
- by points: 122 points of the sphere's surface, each inside some keep-in box."""
import itertools

import numpy as np
import pytest

from astrobee import config
from astrobee import rotations as rot
from astrobee.station import passage_boxes, robot_radius, shrink
from astrobee_planning import planner
from conftest import fibonacci_sphere, module_waypoints

WPS = module_waypoints()
ORDERED = list(itertools.permutations(sorted(WPS), 2))
SPACING = 0.02     # m between samples along the path


SURFACE = np.vstack([fibonacci_sphere(116), np.eye(3), -np.eye(3)])


@pytest.fixture(scope="module")
def station():
    raw = config.keep_in_boxes()
    r = robot_radius()
    spans = np.vstack([raw, passage_boxes(raw)])
    return raw, shrink(spans, r), r, planner.cached_safe_set(0.0)


def _in_any(pts: np.ndarray, bx: np.ndarray, tol: float = 1e-7) -> np.ndarray:
    out = np.zeros(len(pts), dtype=bool)
    for b in bx:
        out |= np.all((pts >= b[:3] - tol) & (pts <= b[3:] + tol), axis=1)
    return out


@pytest.mark.parametrize("a,b", ORDERED, ids=[f"{a}-{b}" for a, b in ORDERED])
def test_robot_sphere_inside_keep_in(a, b, station):
    raw, shrunk_spans, r, safe = station
    plan = planner.plan_global(WPS[a], rot.IDENTITY, WPS[b], rot.IDENTITY, "nominal", safe=safe)
    assert plan.code == planner.SUCCESS
    tr = plan.trajectory
    coarse = tr.sample(np.linspace(0.0, tr.duration, 2000)).pos
    length = float(np.linalg.norm(np.diff(coarse, axis=0), axis=1).sum())
    pos = tr.sample(np.linspace(0.0, tr.duration, max(500, int(length / SPACING) * 2))).pos
    assert np.linalg.norm(np.diff(pos, axis=0), axis=1).max() <= SPACING
    inside = _in_any(pos, shrunk_spans)
    assert inside.all(), f"sphere leaves the keep-in boxes at {pos[~inside][0].round(3).tolist()}"
    surface = (pos[::2, None, :] + r * SURFACE[None]).reshape(-1, 3)
    assert _in_any(surface, raw).all()
    np.testing.assert_allclose(pos[[0, -1]], [WPS[a], WPS[b]], atol=1e-7)
