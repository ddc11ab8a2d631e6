"""The corridor fit: where across the route the robot should fly so the pair, as it is now, fits.

After a bump the strap holds the bag folded, below or beside the robot (a 10 N bump drops it
~0.4 m under the robot's x axis and keeps it there), and the pair may be turning. A robot held
on its route then carries the bag into the hatch's edge although the robot itself clears it
(traced: seeds 1 and 3 at 10 N, the bag's first contact on the hatch floor at the entrance with
the robot within 4 cm of its route). The fit moves the robot's reference across the route by the
shift that keeps the pair's points (the bag's corners, the robot's centre less its half-size),
carried along the plan for the next `horizon` seconds and turned on with the pair's angular
rate about its centre of mass, farthest from the keep-in boxes' walls:

    s* = argmax_s  min(margin, min_{k,i} clearance(ref_k + s + x_i(t_k))) - penalty |s|

over a grid of shifts of at most `reach` in the plane across the route. Transport-free; the
pair law (pair_governor, `fit`) calls it at `rate` and moves its shift towards s* at a bounded
speed.
"""
from __future__ import annotations

import numpy as np

from astrobee import rotations as rot

from .clearance import KeepIn, box_corners

GRID = 9            # shifts per axis across the route (odd: the grid holds zero)
PENALTY = 0.05      # m of clearance a metre of shift costs (ties go to the smaller shift)


def rotation(w: np.ndarray, t: float) -> np.ndarray:
    """The rotation matrix of turning at the constant rate w (rad/s, world) for t seconds."""
    return rot.to_matrix(rot.from_rotvec(np.asarray(w, float) * t))


def across(direction: np.ndarray) -> np.ndarray | None:
    """Two unit vectors spanning the plane across `direction` (None for no direction)."""
    d = np.asarray(direction, float)
    n = float(np.linalg.norm(d))
    if n < 1e-9:
        return None
    d = d / n
    a = np.eye(3)[int(np.argmin(np.abs(d)))]
    u = np.cross(d, a)
    u /= float(np.linalg.norm(u))
    return np.stack([u, np.cross(d, u)])


def pair_points(robot: np.ndarray, bag: np.ndarray, bag_rot: np.ndarray, bag_size: np.ndarray
                ) -> np.ndarray:
    """The pair's points relative to the robot's centre (world frame): the robot's centre first,
    then the bag's 8 corners."""
    corners = box_corners(bag, bag_rot, bag_size)
    return np.vstack([np.zeros(3), corners - np.asarray(robot, float)])


def best_shift(keep_in: KeepIn, route: np.ndarray, times: np.ndarray, points: np.ndarray,
               centre: np.ndarray, rate: np.ndarray, robot_half: float, reach: float,
               margin: float) -> tuple[np.ndarray, float]:
    """(the shift across the route, the least clearance it gives) for the pair's `points`
    (relative to the robot, the robot's centre first: its clearance counts less `robot_half`)
    carried along `route` (K x 3 reference positions at `times` s from now), turning at `rate`
    (rad/s, world) about `centre` (relative to the robot)."""
    route = np.asarray(route, float)
    plane = across(route[-1] - route[0])
    if plane is None or reach <= 0:
        return np.zeros(3), float("nan")
    c = np.asarray(centre, float)
    moved = np.stack([c + (np.asarray(points, float) - c) @ rotation(rate, float(t)).T
                      for t in times])                                      # K x P x 3
    steps = np.linspace(-reach, reach, GRID)
    a, b = np.meshgrid(steps, steps, indexing="ij")
    keep = a ** 2 + b ** 2 <= reach ** 2 + 1e-12
    shifts = a[keep][:, None] * plane[0] + b[keep][:, None] * plane[1]      # S x 3
    pts = shifts[:, None, None, :] + (route[:, None, :] + moved)[None]      # S x K x P x 3
    d = keep_in.clearance(pts, reach + 1.0)
    d[..., 0] -= robot_half
    least = d.reshape(len(shifts), -1).min(axis=1)
    score = np.minimum(least, margin) - PENALTY * np.linalg.norm(shifts, axis=1)
    i = int(np.argmax(score))
    return shifts[i], float(least[i])


class CorridorFit:
    """The shift the robot's reference carries across the route, decided at `rate` Hz and
    moved towards that decision at `speed` m/s at most (so its velocity is the reference's)."""

    def __init__(self, keep_in: KeepIn, robot_half: float, reach: float, horizon: float,
                 speed: float, margin: float = 0.1, rate: float = 5.0, samples: int = 6) -> None:
        self.keep_in, self.robot_half = keep_in, robot_half
        self.reach, self.horizon, self.speed, self.margin = reach, horizon, speed, margin
        self.period = 1.0 / rate
        self.times = np.linspace(0.0, horizon, samples)
        self.shift = np.zeros(3)
        self.velocity = np.zeros(3)
        self.target = np.zeros(3)
        self.least = float("nan")       # the least clearance the last decision predicted
        self._decided = -np.inf
        self._last = None

    def due(self, now: float) -> bool:
        """A decision is due (one per period)."""
        return now - self._decided >= self.period

    def decide(self, now: float, route: np.ndarray, points: np.ndarray, centre: np.ndarray,
               rate: np.ndarray) -> None:
        """A new target shift, if a decision is due (route at self.times from now)."""
        if not self.due(now):
            return
        self._decided = now
        self.target, self.least = best_shift(self.keep_in, route, self.times, points, centre,
                                             rate, self.robot_half, self.reach, self.margin)

    def release(self) -> None:
        """No fit wanted (holding at the goal, or no bag): the shift returns to zero."""
        self.target = np.zeros(3)
        self._decided = -np.inf

    def advance(self, now: float) -> tuple[np.ndarray, np.ndarray]:
        """(shift, its velocity) now: moved towards the target at `speed` at most."""
        h = 0.0 if self._last is None else max(0.0, now - self._last)
        self._last = now
        step = self.target - self.shift
        n = float(np.linalg.norm(step))
        cap = self.speed * h
        if n > cap:
            step *= cap / n
        self.velocity = step / h if h > 0 else np.zeros(3)
        self.shift = self.shift + step
        return self.shift.copy(), self.velocity.copy()
