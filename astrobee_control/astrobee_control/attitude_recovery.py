"""Recovery attitude references of the MPC's attitude mode: a quintic offset from the present
attitude back to the nominal in a torque-feasible time, per candidate (AttitudePlan)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from astrobee import rotations as rot

from .mpc_config import MpcConfig
from .mpc_paths import interp
from .pd import State
from .reduced_model import _exp_so3, _log_so3
from .reference import SampledTrajectory


@dataclass
class AttitudePlan:
    """Per-candidate attitude references on the rollout grid (m+1 points): body -> world
    rotations, world-frame rate and acceleration; the time-scaled nominal's rotations; each
    candidate's recovery time (inf: nominal attitude); the recovery's start offset and rate
    and the pair's inertia, from which `peak_torque` is derived on demand (not per decision)."""

    rotation: np.ndarray          # (N, m+1, 3, 3)
    omega: np.ndarray             # (N, m+1, 3) rad/s, world
    alpha: np.ndarray             # (N, m+1, 3) rad/s^2, world
    nominal_rotation: np.ndarray  # (N, m+1, 3, 3)
    recovery_time: np.ndarray     # (N,) s
    shift: np.ndarray             # (N, m+1, 3) m, position reference shift (world)
    shift_velocity: np.ndarray    # (N, m+1, 3)
    shift_accel: np.ndarray       # (N, m+1, 3)
    offset: np.ndarray            # (3,) rad, the present attitude offset to the nominal
    offset_rate: np.ndarray       # (3,) rad/s, the recovery's starting rate
    inertia: np.ndarray           # (3, 3) kg m^2, the pair about its centre of mass

    @property
    def peak_torque(self) -> np.ndarray:
        """(N, 3) N m, body axes: each recovery's peak feed-forward torque I delta'' (0 for the
        candidates that keep the nominal attitude)."""
        peak = np.zeros((len(self.recovery_time), 3))
        grid = np.linspace(0.0, 1.0, 21)
        for i in np.flatnonzero(np.isfinite(self.recovery_time)):
            Tc = self.recovery_time[i:i + 1]
            _, _, ap = recovery_profile(self.offset, self.offset_rate, Tc, grid * Tc[0])
            peak[i] = np.abs(ap[0] @ np.asarray(self.inertia).T).max(axis=0)
        return peak


RECOVERY_TIMES = np.geomspace(0.5, 40.0, 24)   # s, the recovery durations tried


def recovery_profile(e0: np.ndarray, r0: np.ndarray, Tc: np.ndarray, t: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Quintic offset delta(t) (and its first two derivatives) from (e0, r0, 0) at t = 0 to
    rest at zero at t = Tc, zero after; e0, r0 (3,), Tc (N,), t (M,) -> (N, M, 3) each."""
    Tc = np.asarray(Tc, float)[:, None]
    u = np.clip(t[None, :] / Tc, 0.0, 1.0)[..., None]          # (N, M, 1)
    inside = (t[None, :] < Tc)[..., None]
    T = Tc[..., None]
    h0 = 1 - 10 * u ** 3 + 15 * u ** 4 - 6 * u ** 5
    h1 = u - 6 * u ** 3 + 8 * u ** 4 - 3 * u ** 5
    d0 = -30 * u ** 2 + 60 * u ** 3 - 30 * u ** 4
    d1 = 1 - 18 * u ** 2 + 32 * u ** 3 - 15 * u ** 4
    dd0 = -60 * u + 180 * u ** 2 - 120 * u ** 3
    dd1 = -36 * u + 96 * u ** 2 - 60 * u ** 3
    x = e0 * h0 + r0 * T * h1
    v = (e0 * d0 + r0 * T * d1) / T * inside
    a = (e0 * dd0 + r0 * T * dd1) / (T * T) * inside
    return x, v, a


def shortest_recovery(e0: np.ndarray, r0: np.ndarray, inertia: np.ndarray,
                      max_torque: np.ndarray, margin: float) -> float:
    """The shortest of RECOVERY_TIMES whose feed-forward torque I delta'' stays within
    margin x the torque limits on every body axis (the longest when none does)."""
    t = np.linspace(0.0, 1.0, 21)
    ok = []
    for Tc in RECOVERY_TIMES:
        _, _, a = recovery_profile(e0, r0, np.array([Tc]), t * Tc)
        tq = np.abs(a[0] @ np.asarray(inertia).T).max(axis=0)
        ok.append(bool(np.all(tq <= margin * max_torque + 1e-12)))
    return float(RECOVERY_TIMES[ok.index(True)] if any(ok) else RECOVERY_TIMES[-1])


def attitude_candidates(nom: SampledTrajectory, tau: np.ndarray, t: np.ndarray, state: State,
                        scales: np.ndarray, inertia: np.ndarray, max_torque: np.ndarray,
                        config: MpcConfig, rng: np.random.Generator, n: int,
                        centre: np.ndarray | None = None) -> AttitudePlan:
    """The candidates' attitude references (AttitudePlan) on the rollout grid: the time-scaled
    nominal's attitude for the first ones (candidate 0 is the nominal), and for the last
    `attitude_share` (the warm start, candidate 1, among them) a torque-feasible recovery
    from the present attitude offset and rate (recovery_profile, shortest_recovery). A
    recovery candidate's position reference is shifted by (R_nom - R_ref) c (c: robot ->
    pair's centre of mass, body; `centre`): the pair turns about its centre of mass, where the
    position loop does not fight the turn with an off-centre force (blended in from zero at
    the start, where the candidate leaves from the robot's present position)."""
    q_nom = interp(nom.t, nom.orientation, tau.ravel())
    Rn = rot.to_matrix(q_nom / np.linalg.norm(q_nom, axis=-1, keepdims=True)).reshape(
        tau.shape + (3, 3))
    w_nom = interp(nom.t, nom.omega, tau.ravel()).reshape(tau.shape + (3,)) * scales[:, None, None]
    a_nom = interp(nom.t, nom.alpha, tau.ravel()).reshape(tau.shape + (3,)) * \
        (scales ** 2)[:, None, None]
    R_now = rot.to_matrix(np.asarray(state.orientation, float))
    R0 = Rn[0, 0]
    e0 = _log_so3((R0.T @ R_now)[None])[0]                     # R_now = R0 exp(e0)
    # the recovery leaves from the present attitude at the nominal's rate, not the present
    # rate: re-anchored every replan at the measured rate, it would let a spin run on
    r0 = np.zeros(3)
    k = int(round(config.attitude_share * n))
    first = max(2, n - k) if k > 0 else n
    Tc = np.full(n, np.inf)
    rotation, omega, alpha = Rn.copy(), w_nom.copy(), a_nom.copy()
    if first < n:
        T0 = shortest_recovery(e0, r0, inertia, max_torque, config.torque_margin)
        Tc[first:] = T0 * rng.uniform(1.0, 2.5, n - first)
        Tc[first] = T0
        Tc[1] = T0 * 1.25
        sel = np.r_[1, np.arange(first, n)]
        x, v, a = recovery_profile(e0, r0, Tc[sel], t)
        E = _exp_so3(x.reshape(-1, 3)).reshape(x.shape + (3,))
        rotation[sel] = Rn[sel] @ E
        omega[sel] = w_nom[sel] + np.einsum("nmij,nmj->nmi", rotation[sel], v)
        alpha[sel] = a_nom[sel] + np.einsum("nmij,nmj->nmi", rotation[sel], a)
    shift = np.zeros(tau.shape + (3,))
    if centre is not None and first < n:
        c = np.asarray(centre, float)
        shift = (Rn - rotation) @ c                                  # (N, m+1, 3)
        u = t / max(float(t[-1]), 1e-9)
        fade = (1 - 10 * u ** 3 + 15 * u ** 4 - 6 * u ** 5)[None, :, None]
        shift = shift - shift[:, :1] * fade
    dt = float(t[1] - t[0]) if len(t) > 1 else 1.0
    sv = np.gradient(shift, dt, axis=1)
    return AttitudePlan(rotation, omega, alpha, Rn, Tc, shift, sv, np.gradient(sv, dt, axis=1),
                        e0, r0, np.asarray(inertia, float))
