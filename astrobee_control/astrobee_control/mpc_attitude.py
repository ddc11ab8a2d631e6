"""The sampling MPC's attitude mode: the decisions of MpcLaw with `attitude: true`.

Attitude-aware mode (`attitude: true`; the controller study found the translation-only MPC fails
where PD does: a bump on the bag spins robot + bag, and the flight mode's torque limits, fought
by the position loop's off-centre force, do not take the spin back before the segment ends).
With the turning rollout model (robot + bag one rigid body, ReducedModel.turns) each decision
also varies, per candidate:
- the translation's progress (time scaling): a candidate follows the nominal at rate s in
  {1, (1 + time_scale_min)/2, time_scale_min} (0: pause), so the position loop stops asking
  for the off-centre force that turns the pair while the attitude is being recovered; the
  delay is booked (at most `max_delay` s in all: the task allows plan + settle + 10 s) and the
  rest of the nominal is shifted by it. At the segment's end a pair still turning or off the
  final attitude is held at the goal one replan period more (the pause candidate, by rule,
  within the same budget): the torque-limited attitude gets that time before the settle time;
- the attitude reference: `attitude_share` of the candidates get a recovery profile instead of
  the nominal attitude, q_ref(t) = q_nom(t) exp(delta(t)), delta a quintic (per body axis) from
  the present attitude offset (at the nominal's rate: re-anchored each replan at the measured
  rate it let a spin run on) to zero in Tc seconds; Tc is drawn between the shortest recovery
  whose feed-forward torque I_c delta'' (I_c: the pair's inertia about its centre of mass)
  stays within `torque_margin` of the flight mode's torque limits and 2.5x it; its position
  reference is shifted by (R_nom - R_ref) c so the pair turns about its centre of mass.
The cost adds, from the rollout's own attitude dynamics: the mean squared attitude error to
the (time-scaled) nominal attitude (`w_attitude`), the squared angular momentum of the pair
about its centre at the horizon's end (`w_momentum`), the delay (`w_delay`, per s) and the
collision weight for a candidate more than `max_deviation` from the nominal path; the nominal
candidate is left only for `min_gain` less cost (the model is coarse: its choices among
candidates it scores alike are noise). Without a bag or with a model that does not turn, the
decision is the translation-only one. Measured (studies/mpc_attitude_study.yaml): see README.
"""
from __future__ import annotations

import math

import numpy as np

from astrobee import rotations as rot
from astrobee.bezier import control_points

from .attitude_recovery import AttitudePlan, attitude_candidates
from .mpc_config import Decision
from .mpc_paths import append_hold, bezier_states, interp, joined
from .pd import State
from .reduced_model import (CandidateReferences, Gains, RolloutStart, _log_so3,
                            compound_inertia)
from .reference import SampledTrajectory
from .tracking import CONTROLLING

HOLD_OMEGA = 0.02    # rad/s: below it (and near the final attitude) the pair is not held longer


class AttitudeMode:
    """MpcLaw's attitude-mode decisions (module docstring); a mixin: it uses the law's config,
    nominal, tracker, model, rng, delay and its translation scoring (_score, _start)."""

    def _hold_at_goal(self, state: State, now: float, dt: float) -> None:
        """Attitude mode: the pause candidate at the segment's end. While the pair is still
        turning or off the final attitude when the plan is about to end, hold the final pose
        one replan period more (booked as delay, at most max_delay in all): the torque-limited
        attitude gets that time before the PD law's settle time starts (the MPC keeps
        deciding meanwhile). With `hold_about_centre` (off: measured worse, see README) the
        held position is instead where the robot is when the pair's centre of mass sits at the
        goal's, re-aimed every tick, so the pair turns about its centre of mass (inertia I_c,
        about half the pair's inertia about the robot) instead of about a pinned robot."""
        c, traj = self.config, self.tracker.traj
        if not (c.attitude and self.tracker.state == CONTROLLING and traj is not None
                and self.nominal is not None and self.bag is not None):
            self._goal = None
            return
        goal = traj.final()
        ends = self._hold_end if (c.hold_about_centre and self._goal is not None) else \
            traj.end_time
        if now + dt >= ends and self._delay + c.replan_period <= c.max_delay + 1e-9:
            off = rot.angle_between(state.orientation, goal.orientation)
            if off > 0.5 * self.flight_mode.tolerance_att or \
                    float(np.linalg.norm(state.omega)) > HOLD_OMEGA:
                self._delay += c.replan_period
                if not c.hold_about_centre:
                    self.tracker.traj = append_hold(traj, traj.end_time + c.replan_period)
                    return
                if self._goal is None:
                    self._goal, self._hold_end = goal, traj.end_time
                    self._centre = compound_inertia(self._start(state), self._handle_offset())[1]
                self._hold_end += c.replan_period
        if self._goal is None or not c.hold_about_centre or now >= self._hold_end:
            return
        goal = self._goal
        R_now, R_goal = rot.to_matrix(state.orientation), rot.to_matrix(goal.orientation)
        arm = R_now @ self._centre                                  # robot -> centre, world
        p = goal.position + R_goal @ self._centre - arm
        v = -np.cross(R_now @ np.asarray(state.omega, float), arm)
        z = np.zeros(3)
        self.tracker.traj = SampledTrajectory(
            np.array([now, max(self._hold_end, now + 1e-3)]), np.stack([p, p]), np.stack([v, v]),
            np.stack([z, z]), np.stack([goal.orientation, goal.orientation]), np.stack([z, z]),
            np.stack([z, z]))

    # ---- the MPC proper --------------------------------------------------------------------

    def _decide_attitude(self, state: State, now: float) -> Decision | None:
        """The attitude-aware decision (module docstring): time-scaled translation candidates,
        recovery attitude references, the attitude and angular-momentum cost."""
        c, nom = self.config, self.nominal
        t0n = now - self._delay                              # the nominal's clock now
        T = min(c.horizon, nom.end_time - t0n)
        m = int(math.ceil(T / c.rollout_dt)) if T > 0 else 0
        if m < max(2, c.cost_stride):
            return None
        dt_r, n = T / m, c.samples
        times = now + np.arange(m + 1) * dt_r
        scales = self._time_scales(n)
        tau = t0n + scales[:, None] * (times - now)          # (N, m+1) nominal times
        tau_h = np.minimum(tau[:, -1], nom.end_time)
        pscale = np.clip((nom.end_time - tau_h) / c.horizon, 0.0, 1.0)
        dz = self._perturbations(n, 1.0) * pscale[:, None]
        p_h, v_h, a_h = (interp(nom.t, x, tau_h) for x in (nom.position, nom.velocity, nom.accel))
        p1 = p_h + dz[:, :3]
        v1 = scales[:, None] * v_h + dz[:, 3:]
        vmax = self.flight_mode.hard_limit_vel
        speed = np.linalg.norm(v1, axis=1, keepdims=True)
        v1 = np.where(speed > vmax, v1 * (vmax / np.maximum(speed, 1e-12)), v1)
        a0 = self.tracker.traj.sample(now).accel if self.tracker.traj is not None else \
            nom.sample(now).accel
        pts = control_points(state.position, state.velocity, a0, p1, v1,
                             scales[:, None] ** 2 * a_h, T)
        ref_p, ref_v, ref_a = bezier_states(pts, T, np.arange(m) / m)
        start = self._start(state)
        I_c, centre = compound_inertia(start, self._handle_offset())
        plan = attitude_candidates(nom, tau, times - now, state, scales, I_c,
                                   np.asarray(self.flight_mode.max_torque, float), c,
                                   self.rng, n, centre)
        ref_p = ref_p + plan.shift[:, :m]
        ref_v = ref_v + plan.shift_velocity[:, :m]
        ref_a = ref_a + plan.shift_accel[:, :m]
        refs = CandidateReferences(ref_p, ref_v, ref_a, plan.rotation[:, :m], dt_r,
                                   plan.omega[:, :m], plan.alpha[:, :m])
        out = self.model.rollout(start, refs, Gains.from_flight_mode(self.flight_mode))
        costs, clearance, att_end = self._score_attitude(out, nom, tau[:, 1:], plan, start,
                                                         scales, T)
        best = int(np.argmin(costs))
        if costs[best] > (1.0 - c.min_gain) * costs[0]:
            best = 0                     # not worth leaving the nominal (the model is coarse)
        if pscale[best] > 1e-6:          # warm start, kept within 2 sigma (no random walk)
            sig = np.r_[np.full(3, c.sigma_position), np.full(3, c.sigma_velocity)]
            self._warm = np.clip(dz[best] / pscale[best], -2.0 * sig, 2.0 * sig)
        self._delay += (1.0 - scales[best]) * min(c.replan_period, T)
        stride = c.cost_stride
        executed = self._executed_attitude(pts[best], now, T, plan, best, tau_h[best])
        return Decision(now, p1, costs, clearance, best, out.robot_position[:, ::stride],
                        out.robot_position[best, ::stride], executed, att_end,
                        (1.0 - scales) * T)

    def _time_scales(self, n: int) -> np.ndarray:
        """Per candidate, the rate the translation follows the nominal at (candidates 0 and 1,
        the nominal and the warm start, at 1); none may push the delay past max_delay."""
        c = self.config
        out = np.ones(n)
        room = c.max_delay - self._delay
        if n > 2 and room > 1e-6 and c.time_scale_min < 1.0:
            levels = np.array([1.0, 0.5 * (1.0 + c.time_scale_min), c.time_scale_min])
            out[2:] = self.rng.choice(levels, n - 2)
            out = np.maximum(out, 1.0 - room / c.replan_period)
        return out

    def _score_attitude(self, out, nom: SampledTrajectory, tau: np.ndarray,
                        plan: AttitudePlan, start: RolloutStart, scales: np.ndarray,
                        T: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """_score's terms against the time-scaled nominal, plus attitude error, the pair's
        angular momentum at the end and the delay: (costs, clearance, final attitude error)."""
        c = self.config
        costs, clr = self._score(out, nom, tau[0], plan.nominal_rotation[0, 1:], start)
        # tracking against each candidate's own (time-scaled) nominal instead of candidate 0's
        p_nom0 = interp(nom.t, nom.position, tau[0])
        p_nom = interp(nom.t, nom.position, tau.ravel()).reshape(tau.shape + (3,))
        dev = np.sum((out.robot_position - p_nom) ** 2, -1)
        costs = costs + c.w_track * (
            np.mean(dev, axis=1) - np.mean(np.sum((out.robot_position - p_nom0) ** 2, -1), axis=1))
        costs = costs + c.w_collision * (np.sqrt(dev.max(axis=1)) > c.max_deviation)
        sl = slice(c.cost_stride - 1, None, c.cost_stride)
        Rn = plan.nominal_rotation[:, 1:][:, sl]                       # (N, K, 3, 3)
        Rr = out.rotation[:, sl]
        e = _log_so3(np.swapaxes(Rn, -1, -2).reshape(-1, 3, 3) @ Rr.reshape(-1, 3, 3))
        e2 = np.sum(e.reshape(Rn.shape[:2] + (3,)) ** 2, -1)           # (N, K) rad^2
        L = out.omega[:, -1] @ out.inertia.T                            # body frame, N m s
        return (costs + c.w_attitude * np.mean(e2, axis=1) + c.w_momentum * np.sum(L * L, -1)
                + c.w_delay * (1.0 - scales) * T), clr, np.sqrt(e2[:, -1])

    def _executed_attitude(self, points: np.ndarray, now: float, T: float,
                           plan: AttitudePlan, best: int, tau_h: float) -> SampledTrajectory:
        """The chosen candidate (position, its attitude reference) at ~10 Hz, then the rest
        of the nominal, shifted by the candidate's delay."""
        nom = self.nominal
        k = max(2, int(math.ceil(T * 10.0)) + 1)
        s = np.linspace(0.0, 1.0, k)
        p, v, a = (x[0] for x in bezier_states(points[None], T, s))
        t = now + s * T
        u = s * (plan.rotation.shape[1] - 1)                            # rollout grid index
        idx = np.minimum(np.round(u).astype(int), plan.rotation.shape[1] - 1)
        p = p + plan.shift[best, idx]
        v = v + plan.shift_velocity[best, idx]
        a = a + plan.shift_accel[best, idx]
        q = rot.from_matrix(plan.rotation[best, idx])
        w = plan.omega[best, idx]
        al = plan.alpha[best, idx]
        shift = (now + T) - tau_h
        tail = nom.t > tau_h + 1e-6
        return joined((t, p, v, a, q, w, al), nom, tail, shift)
