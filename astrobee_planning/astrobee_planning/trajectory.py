"""Trajectory: piecewise Bezier position + piecewise quaternion polynomial attitude, sampled by time.

Position pieces and attitude pieces have their own time breaks (e.g. a reorientation while the
position holds). Angular rates are world frame (see quaternion_poly). Sampling is vectorised:
every piece is turned once into monomial coefficients of its value and time derivatives
(cached), and sorted sample times are evaluated piece by piece with one matrix product each.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import bezier
from .quaternion_poly import QuaternionPolynomial, normalised_rates_columns


def _product(c: np.ndarray, V: np.ndarray) -> np.ndarray:
    """c.T @ V; einsum's own loop for long V (a threaded BLAS call costs 20x more on a busy
    machine at these thin shapes)."""
    return c.T @ V if V.shape[1] <= 1024 else np.einsum("jk,jm->km", c, V)


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

    _cache: tuple | None = field(default=None, init=False, repr=False, compare=False)

    def _tables(self) -> tuple:
        """(position starts, durations, coefficients (P, 8, 9)), same for attitude (A, 6, 12);
        rebuilt when the piece lists change."""
        key = (id(self.position), len(self.position), id(self.attitude), len(self.attitude))
        if self._cache is not None and self._cache[0] == key:
            return self._cache[1]
        n = max(len(p.points) for p in self.position) - 1
        pc = np.zeros((len(self.position), n + 1, 9))
        for i, p in enumerate(self.position):
            pts = np.asarray(p.points, dtype=float)
            m = len(pts) - 1
            for k in range(3):
                if k <= m:
                    pc[i, :m + 1 - k, 3 * k:3 * k + 3] = bezier.monomial_matrix(m, k) @ pts / p.duration ** k
        ac = np.stack([a.time_coefficients() for a in self.attitude])
        tables = (np.array([p.t0 for p in self.position]), np.array([p.duration for p in self.position]), pc,
                  np.array([a.t0 for a in self.attitude]), np.array([a.duration for a in self.attitude]), ac)
        self._cache = (key, tables)
        return tables

    @staticmethod
    def _piecewise(t: np.ndarray, starts: np.ndarray, durs: np.ndarray, coef: np.ndarray) -> np.ndarray:
        """Evaluate the piecewise polynomials at sorted times t, column-stacked: (coef.shape[2], len(t))."""
        if len(starts) == 1:
            cuts = np.array([], dtype=int)
            s = (t - starts[0]) * (1.0 / durs[0])
        else:
            cuts = np.searchsorted(t, starts[1:], side="left")
            idx = np.cumsum(np.bincount(cuts, minlength=len(t) + 1)[:len(t)])
            s = (t - starts[idx]) / durs[idx]
        np.clip(s, 0.0, 1.0, out=s)
        V = np.empty((coef.shape[1], len(t)))
        V[0] = 1.0
        for j in range(1, coef.shape[1]):
            np.multiply(V[j - 1], s, out=V[j])
        if len(starts) == 1:
            return _product(coef[0], V)
        out = np.empty((coef.shape[2], len(t)))
        lo = 0
        for k, hi in enumerate(np.append(cuts, len(t))):
            if hi > lo:
                out[:, lo:hi] = _product(coef[k], V[:, lo:hi])
            lo = max(lo, hi)
        return out

    def sample(self, t) -> State:
        """States at times t (seconds from the trajectory start; clipped to [0, duration])."""
        t = np.clip(np.atleast_1d(np.asarray(t, dtype=float)), 0.0, self.duration)
        order = None
        if len(t) > 1 and np.any(t[1:] < t[:-1]):
            order = np.argsort(t, kind="stable")
            t = t[order]
        ps, pd, pc, as_, ad, ac = self._tables()
        p = self._piecewise(t, ps, pd, pc)
        raw = self._piecewise(t, as_, ad, ac)
        quat, om, al = normalised_rates_columns(raw[:4], raw[4:8], raw[8:])
        if len(as_) > 1:     # keep the quaternion sign continuous from piece to piece
            flip = (quat[:, 1:] * quat[:, :-1]).sum(axis=0) < 0
            if flip.any():
                quat = quat * np.where(np.concatenate([[0], np.cumsum(flip)]) % 2 == 1, -1.0, 1.0)
        p, quat, om, al = p.T, quat.T, om.T, al.T
        if order is not None:
            inv = np.empty_like(order)
            inv[order] = np.arange(len(order))
            t, p, quat, om, al = t[inv], p[inv], quat[inv], om[inv], al[inv]
        return State(t, p[:, :3], p[:, 3:6], p[:, 6:], quat, om, al)

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
