"""A sampled reference trajectory (what a Segment carries), evaluated at any time.

Between samples: cubic Hermite on position (from the sampled velocities), linear on velocity,
acceleration, angular velocity and angular acceleration, slerp on orientation. Before the
first sample the first state holds; after the last, the last pose holds at rest.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from astrobee import rotations as rot

from .pd import Reference


@dataclass
class SampledTrajectory:
    """Arrays of N samples: t (s, increasing), position/velocity/accel/omega/alpha (N,3), quat (N,4)."""

    t: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    accel: np.ndarray
    orientation: np.ndarray
    omega: np.ndarray
    alpha: np.ndarray

    def __post_init__(self) -> None:
        self.t = np.asarray(self.t, float)
        n = len(self.t)
        if n == 0:
            raise ValueError("empty trajectory")
        for name in ("position", "velocity", "accel", "omega", "alpha"):
            a = np.asarray(getattr(self, name), float).reshape(n, 3)
            setattr(self, name, a)
        q = np.asarray(self.orientation, float).reshape(n, 4)
        norms = np.linalg.norm(q, axis=1)
        if not (np.all(np.isfinite(q)) and np.all(norms > 1e-6)):
            raise ValueError("trajectory holds a zero or non-finite quaternion")
        q = q / norms[:, None]
        # make consecutive quaternions share a hemisphere so slerp takes the short way
        for i in range(1, n):
            if np.dot(q[i - 1], q[i]) < 0:
                q[i] = -q[i]
        self.orientation = q
        arrays = (self.t, self.position, self.velocity, self.accel, self.omega, self.alpha)
        if not all(np.all(np.isfinite(a)) for a in arrays):
            raise ValueError("trajectory holds non-finite values")
        if n > 1 and np.any(np.diff(self.t) <= 0):
            raise ValueError("trajectory times must increase strictly")

    @property
    def start_time(self) -> float:
        return float(self.t[0])

    @property
    def end_time(self) -> float:
        return float(self.t[-1])

    @property
    def duration(self) -> float:
        return self.end_time - self.start_time

    def shifted(self, dt: float) -> "SampledTrajectory":
        """The same trajectory with every time moved by dt seconds."""
        return SampledTrajectory(self.t + dt, self.position, self.velocity, self.accel,
                                 self.orientation, self.omega, self.alpha)

    def final(self) -> Reference:
        """The last pose, at rest."""
        return Reference.hold(self.position[-1], self.orientation[-1])

    def sample(self, t: float) -> Reference:
        """The reference at time t (same clock as self.t)."""
        if t >= self.t[-1]:
            return self.final()
        if t <= self.t[0] or len(self.t) == 1:
            return Reference(self.position[0].copy(), self.velocity[0].copy(), self.accel[0].copy(),
                             self.orientation[0].copy(), self.omega[0].copy(), self.alpha[0].copy())
        i = int(np.searchsorted(self.t, t, side="right")) - 1
        t0, t1 = self.t[i], self.t[i + 1]
        h = t1 - t0
        s = (t - t0) / h
        p0, p1 = self.position[i], self.position[i + 1]
        v0, v1 = self.velocity[i], self.velocity[i + 1]
        h00 = 2 * s**3 - 3 * s**2 + 1
        h10 = s**3 - 2 * s**2 + s
        h01 = -2 * s**3 + 3 * s**2
        h11 = s**3 - s**2
        pos = h00 * p0 + h10 * h * v0 + h01 * p1 + h11 * h * v1
        lerp = lambda a: (1 - s) * a[i] + s * a[i + 1]  # noqa: E731
        return Reference(pos, lerp(self.velocity), lerp(self.accel),
                         rot.slerp(self.orientation[i], self.orientation[i + 1], s),
                         lerp(self.omega), lerp(self.alpha))


def _vec(v: Any) -> list[float]:
    return [float(v.x), float(v.y), float(v.z)]


def time_of(stamp: Any) -> float:
    """Seconds of a builtin_interfaces/Time-like object (sec, nanosec)."""
    return float(stamp.sec) + 1e-9 * float(stamp.nanosec)


def from_control_states(states: Sequence[Any]) -> SampledTrajectory:
    """Build from astrobee_msgs/ControlState-like objects (attribute access only, no transport)."""
    if len(states) == 0:
        raise ValueError("empty segment")
    t = [time_of(s.when) for s in states]
    pos = [_vec(s.pose.position) for s in states]
    quat = [[float(s.pose.orientation.x), float(s.pose.orientation.y),
             float(s.pose.orientation.z), float(s.pose.orientation.w)] for s in states]
    return SampledTrajectory(t, pos, [_vec(s.twist.linear) for s in states],
                             [_vec(s.accel.linear) for s in states], quat,
                             [_vec(s.twist.angular) for s in states],
                             [_vec(s.accel.angular) for s in states])


def rest_to_rest(p0: np.ndarray, p1: np.ndarray, q0: np.ndarray, q1: np.ndarray,
                 duration: float, rate: float = 10.0) -> SampledTrajectory:
    """A quintic (minimum-jerk) rest-to-rest straight line and slerp: a simple reference for
    tests and fall-backs when no planner is available."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    n = max(2, int(np.ceil(duration * rate)) + 1)
    t = np.linspace(0.0, duration, n)
    s = t / duration
    f = 10 * s**3 - 15 * s**4 + 6 * s**5
    df = (30 * s**2 - 60 * s**3 + 30 * s**4) / duration
    ddf = (60 * s - 180 * s**2 + 120 * s**3) / duration**2
    d = p1 - p0
    q0 = rot.normalize(q0)
    q1 = rot.normalize(q1)
    if np.dot(q0, q1) < 0:
        q1 = -q1
    axis_angle = rot.to_rotvec(rot.multiply(q1, rot.conjugate(q0)))  # world-frame rotation q0->q1
    quats = np.array([rot.multiply(rot.from_rotvec(axis_angle * fi), q0) for fi in f])
    return SampledTrajectory(t, p0 + np.outer(f, d), np.outer(df, d), np.outer(ddf, d), quats,
                             np.outer(df, axis_angle), np.outer(ddf, axis_angle))
