"""Trajectory: piecewise Bezier position + piecewise quaternion polynomial attitude, sampled by time.

Position pieces and attitude pieces have their own time breaks (e.g. a reorientation while the
position holds). Angular rates are world frame (see quaternion_poly).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import bezier
from .quaternion_poly import QuaternionPolynomial


@dataclass
class BezierPiece:
    """p(t) = sum_i B_{i,n}((t - t0)/duration) points[i] on [t0, t0 + duration]."""
    points: np.ndarray     # (n+1, 3)
    t0: float
    duration: float


@dataclass
class State:
    """Sampled states, each array with a leading time axis."""
    t: np.ndarray
    pos: np.ndarray
    vel: np.ndarray
    acc: np.ndarray
    quat: np.ndarray
    omega: np.ndarray
    alpha: np.ndarray

    def __getitem__(self, i) -> "State":
        return State(*(getattr(self, f)[i] for f in ("t", "pos", "vel", "acc", "quat", "omega", "alpha")))

    def __len__(self) -> int:
        return len(self.t)


@dataclass
class Trajectory:
    """A full reference: position pieces and attitude pieces covering [0, duration]."""
    position: list[BezierPiece]
    attitude: list[QuaternionPolynomial]
    t_offset: float = 0.0                       # time of the trajectory's start (for messages)
    info: dict = field(default_factory=dict)

    @property
    def duration(self) -> float:
        end_p = max(p.t0 + p.duration for p in self.position)
        end_a = max(a.t0 + a.duration for a in self.attitude)
        return float(max(end_p, end_a))

    @staticmethod
    def _index(t: np.ndarray, starts: np.ndarray) -> np.ndarray:
        return np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(starts) - 1)

    def sample(self, t) -> State:
        """States at times t (seconds from the trajectory start; clipped to [0, duration])."""
        t = np.clip(np.atleast_1d(np.asarray(t, dtype=float)), 0.0, self.duration)
        n = len(t)
        pos, vel, acc = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3))
        ip = self._index(t, np.array([p.t0 for p in self.position]))
        for k in np.unique(ip):
            piece = self.position[k]
            m = ip == k
            s = np.clip((t[m] - piece.t0) / piece.duration, 0.0, 1.0)
            pos[m] = bezier.evaluate(piece.points, s)
            vel[m] = bezier.evaluate_derivative(piece.points, piece.duration, s, 1)
            acc[m] = bezier.evaluate_derivative(piece.points, piece.duration, s, 2)
        quat, om, al = np.zeros((n, 4)), np.zeros((n, 3)), np.zeros((n, 3))
        ia = self._index(t, np.array([a.t0 for a in self.attitude]))
        for k in np.unique(ia):
            m = ia == k
            quat[m], om[m], al[m] = self.attitude[k].evaluate(t[m])
        # keep the quaternion sign continuous from piece to piece
        flip = np.concatenate([[False], np.sum(quat[1:] * quat[:-1], axis=1) < 0])
        sign = np.where(np.cumsum(flip) % 2 == 1, -1.0, 1.0)
        return State(t, pos, vel, acc, quat * sign[:, None], om, al)

    def sample_rate(self, rate: float) -> State:
        """States every 1/rate seconds from 0 to the end (end included)."""
        if not rate > 0:
            raise ValueError("sample rate must be positive")
        n = int(np.floor(self.duration * rate + 1e-9)) + 1
        t = np.arange(n) / rate
        if t[-1] < self.duration - 1e-9:
            t = np.append(t, self.duration)
        return self.sample(t)

    def peaks(self, rate: float = 10.0) -> dict[str, float]:
        """Largest |v|, |a|, |w|, |alpha| over a dense sampling."""
        st = self.sample(np.linspace(0.0, self.duration, max(200, int(self.duration * rate))))
        return {k: float(np.max(np.linalg.norm(getattr(st, k), axis=1)))
                for k in ("vel", "acc", "omega", "alpha")}
