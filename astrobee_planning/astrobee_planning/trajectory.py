"""Trajectory: piecewise Bezier position + piecewise quaternion polynomial attitude, sampled by time.

Position pieces and attitude pieces have their own time breaks (e.g. a reorientation while the
position holds). Angular rates are world frame (see quaternion_poly). Sampling is vectorised:
every piece is turned once into monomial coefficients of its value and time derivatives (for the
attitude, of the polynomials whose ratios give the normalised quaternion and its world rates;
cached), and sorted sample times are evaluated in blocks of BLOCK samples (scratch rows reused),
piece by piece with one matrix product each, straight into one output array.
"""
from __future__ import annotations

import threading
from dataclasses import dataclass, field

import numpy as np

from astrobee import bezier

from .quaternion_poly import (QuaternionPolynomial, rate_coefficients, rates_from_table,
                              time_coefficients_batch)


BLOCK = 3072   # samples evaluated together: the work rows of a block stay in cache, and the
               # matrix products stay below OpenBLAS's threading size (a threaded call on these
               # thin shapes costs 20x more on a busy machine)
_work = threading.local()
MAX_STATES = 100_000   # states a sampling may return for a request from outside (a service
                       # response): 285 s at 350 Hz; a million took 65 s and 2 GB


def sample_count(duration: float, rate: float) -> int:
    """Number of states of `Trajectory.sample_rate(rate)` over `duration` s (end included)."""
    if not (np.isfinite(rate) and rate > 0):
        raise ValueError(f"sample rate must be positive and finite (got {rate})")
    if not (np.isfinite(duration) and duration >= 0):
        raise ValueError(f"duration must be finite and >= 0 (got {duration})")
    n = int(np.floor(duration * rate + 1e-9)) + 1
    return n + 1 if (n - 1) / rate < duration - 1e-9 else n      # the end is always a state


def check_sample_count(duration: float, rate: float, max_states: int = MAX_STATES) -> int:
    """`sample_count`, or ValueError (one line) when it exceeds max_states."""
    n = sample_count(duration, rate)
    if n > max_states:
        raise ValueError(f"{duration:.6g} s at {rate:.6g} Hz is {n} states, more than the "
                         f"{max_states} a request may ask for: lower the sample rate or the duration")
    return n


def _workspace(rows: int) -> np.ndarray:
    """This thread's (rows, BLOCK) scratch rows, kept between calls (fresh pages cost a page
    fault each, ~2 us on a VM: more than the arithmetic)."""
    buf = getattr(_work, "buf", None)
    if buf is None or buf.shape[0] < rows:
        buf = _work.buf = np.empty((rows, BLOCK))
    return buf


def _spans(bounds: np.ndarray, b0: int, b1: int):
    """(piece, lo, hi) of the pieces' sample ranges bounds[k]:bounds[k+1] that meet [b0, b1)."""
    k = int(np.searchsorted(bounds, b0, side="right")) - 1
    lo = b0
    while lo < b1:
        hi = min(int(bounds[k + 1]), b1)
        if hi > lo:
            yield k, lo, hi
        lo = max(lo, hi)
        k += 1


def _evaluate_block(t: np.ndarray, b0: int, b1: int, bounds: np.ndarray, starts: np.ndarray,
                    inv_durs: np.ndarray, coef: np.ndarray, s: np.ndarray, V: np.ndarray,
                    out: np.ndarray) -> None:
    """out[:, :b1-b0] = the piecewise polynomials at t[b0:b1] (sorted), with s (nb,) and V
    (powers, nb) as scratch."""
    nb = b1 - b0
    spans = list(_spans(bounds, b0, b1))
    for k, lo, hi in spans:
        seg = s[lo - b0:hi - b0]
        np.subtract(t[lo:hi], starts[k], out=seg)
        np.multiply(seg, inv_durs[k], out=seg)
    np.clip(s[:nb], 0.0, 1.0, out=s[:nb])
    V[0, :nb] = 1.0
    for j in range(1, coef.shape[1]):
        np.multiply(V[j - 1, :nb], s[:nb], out=V[j, :nb])
    for k, lo, hi in spans:
        np.matmul(coef[k].T, V[:, lo - b0:hi - b0], out=out[:, lo - b0:hi - b0])


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
        """(position starts, durations, coefficients (P, n+1, 9) of [p, v, a]) and the same for
        the attitude (A, 11, 12): `rate_coefficients` of each piece, signs chained so that each
        piece starts on the hemisphere where the previous one ended. Rebuilt when the piece
        lists change."""
        key = (id(self.position), len(self.position), id(self.attitude), len(self.attitude))
        if self._cache is not None and self._cache[0] == key:
            return self._cache[1]
        n = max(len(p.points) for p in self.position) - 1
        pd = np.array([p.duration for p in self.position], dtype=float)
        pc = np.zeros((len(self.position), n + 1, 9))
        if all(len(p.points) == n + 1 for p in self.position):
            pts = np.stack([np.asarray(p.points, dtype=float) for p in self.position])
            for k in range(min(3, n + 1)):
                pc[:, :n + 1 - k, 3 * k:3 * k + 3] = (np.einsum("ij,pjd->pid", bezier.monomial_matrix(n, k), pts)
                                                      / pd[:, None, None] ** k)
        else:
            for i, p in enumerate(self.position):
                pts = np.asarray(p.points, dtype=float)
                m = len(pts) - 1
                for k in range(min(3, m + 1)):
                    pc[i, :m + 1 - k, 3 * k:3 * k + 3] = bezier.monomial_matrix(m, k) @ pts / p.duration ** k
        ad = np.array([a.duration for a in self.attitude], dtype=float)
        tc = time_coefficients_batch(np.stack([a.coefficients for a in self.attitude]), ad)  # (A, 6, 12)
        if len(tc) > 1:      # q(1) of each piece against q(0) of the next: flip to stay continuous
            dots = np.einsum("ak,ak->a", tc[:-1, :, :4].sum(axis=1), tc[1:, 0, :4])
            sign = np.concatenate([[1.0], np.where(np.cumsum(dots < 0) % 2 == 1, -1.0, 1.0)])
            tc = tc * sign[:, None, None]
        ac = rate_coefficients(tc)
        tables = (np.array([p.t0 for p in self.position]), pd, pc,
                  np.array([a.t0 for a in self.attitude]), ad, ac)
        self._cache = (key, tables)
        return tables

    def sample(self, t) -> State:
        """States at times t (seconds from the trajectory start; clipped to [0, duration])."""
        t = np.clip(np.atleast_1d(np.asarray(t, dtype=float)), 0.0, self.duration)
        order = None
        if len(t) > 1 and np.any(t[1:] < t[:-1]):
            order = np.argsort(t, kind="stable")
            t = t[order]
        ps, pd, pc, as_, ad, ac = self._tables()
        M = len(t)
        out = np.empty((19, M))        # rows: p, v, a (9), quaternion (4), w (3), alpha (3)
        pb = np.concatenate([[0], np.searchsorted(t, ps[1:], side="left"), [M]])
        ab = np.concatenate([[0], np.searchsorted(t, as_[1:], side="left"), [M]])
        npw, napw = pc.shape[1], ac.shape[1]
        w = _workspace(2 + npw + napw + ac.shape[2] + 3)
        s, Vp = w[0], w[1:1 + npw]
        Va = w[1 + npw:1 + npw + napw]
        tab = w[1 + npw + napw:1 + npw + napw + ac.shape[2]]
        tmp = w[-4:]
        ipd, iad = 1.0 / pd, 1.0 / ad
        for b0 in range(0, M, BLOCK):
            b1 = min(M, b0 + BLOCK)
            nb = b1 - b0
            o = out[:, b0:b1]
            _evaluate_block(t, b0, b1, pb, ps, ipd, pc, s, Vp, o[:9])
            _evaluate_block(t, b0, b1, ab, as_, iad, ac, s, Va, tab)
            rates_from_table(tab[:, :nb], o[9:13], o[13:16], o[16:19], tmp[:, :nb])
        quat, om, al, p = out[9:13].T, out[13:16].T, out[16:19].T, out[:9].T
        if order is not None:
            inv = np.empty_like(order)
            inv[order] = np.arange(len(order))
            t, p, quat, om, al = t[inv], p[inv], quat[inv], om[inv], al[inv]
        return State(t, p[:, :3], p[:, 3:6], p[:, 6:], quat, om, al)

    def sample_rate(self, rate: float, max_states: int | None = None) -> State:
        """States every 1/rate seconds from 0 to the end (end included); ValueError when that
        is more than max_states (None: no cap)."""
        if not rate > 0:
            raise ValueError("sample rate must be positive")
        if max_states is not None:
            check_sample_count(self.duration, rate, max_states)
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
