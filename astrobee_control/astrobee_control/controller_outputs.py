"""Outputs of controller_node: a law's Step turned into its messages (FamCommand, the reference
ControlState, the candidates' MarkerArray, the predicted nav_msgs/Path, the MotionState).

A mixin of ControllerNode: it uses the message classes, publishers, rates and last stamps the
node sets up in its __init__.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from astrobee import msgconv as mc


class ControllerOutputs:
    """The publishing half of ControllerNode (see the module docstring)."""

    def _publish_command(self, step: Any, stamp: Any, wrench: Any = None) -> None:
        """The law's command; `wrench` (force, torque), when given, replaces its wrench."""
        out = step.output
        force, torque = (out.force, out.torque) if wrench is None else wrench
        m = self.FamCommand()
        m.header.stamp = stamp
        m.header.frame_id = "body"
        mc.set_vec(m.wrench.force, force)
        mc.set_vec(m.wrench.torque, torque)
        mc.set_vec(m.accel, out.accel)
        mc.set_vec(m.alpha, out.alpha)
        m.status = 3 if out.saturated else 0
        mc.set_vec(m.position_error, out.position_error)
        mc.set_vec(m.position_error_integrated, out.position_error_integrated)
        mc.set_vec(m.attitude_error, out.attitude_error)
        mc.set_vec(m.attitude_error_integrated, out.attitude_error_integrated)
        m.attitude_error_mag = out.attitude_error_mag
        m.control_mode = step.control_mode
        self.pub_cmd.publish(m)

    def _publish_traj(self, step: Any, stamp: Any) -> None:
        ref = step.reference
        m = self.ControlState()
        m.when = stamp
        mc.set_pose(m.pose, ref.position, ref.orientation)
        mc.set_vec(m.twist.linear, ref.velocity)
        mc.set_vec(m.twist.angular, ref.omega)
        mc.set_vec(m.accel.linear, ref.accel)
        mc.set_vec(m.accel.angular, ref.alpha)
        self.pub_traj.publish(m)

    def _publish_path(self, stamp: Any, t: float) -> None:
        """The law's predicted path (nav_msgs/Path, world frame), at most at candidates_rate."""
        if self.pub_path is None or t - self._last_path < self.candidates_period:
            return
        pts = self.law.predicted_path()
        if pts is None:
            return
        self._last_path = t
        msg = self.Path()
        msg.header.stamp, msg.header.frame_id = stamp, "world"
        poses = []
        for p in np.asarray(pts, float):
            ps = self.PoseStamped()
            ps.header.stamp, ps.header.frame_id = stamp, "world"
            ps.pose.position.x, ps.pose.position.y, ps.pose.position.z = (float(x) for x in p)
            ps.pose.orientation.w = 1.0
            poses.append(ps)
        msg.poses = poses
        self.pub_path.publish(msg)

    def _publish_candidates(self, step: Any, stamp: Any, t: float) -> None:
        """The candidates a sampling law considered (grey) and the one it chose (green)."""
        cands = getattr(step, "candidates", None)
        if cands is None or t - self._last_candidates < self.candidates_period:
            return
        self._last_candidates = t
        arr = self.MarkerArray()
        chosen = getattr(step, "chosen", None)
        lines = [(c, (0.6, 0.6, 0.6, 0.35), "candidates") for c in np.asarray(cands)]
        if chosen is not None:
            lines.append((np.asarray(chosen), (0.1, 0.9, 0.2, 1.0), "chosen"))
        out = []
        for i, (pts, colour, ns) in enumerate(lines):
            m = self.Marker()
            m.header.stamp, m.header.frame_id = stamp, "world"
            m.ns, m.id, m.type, m.action = ns, i, 4, 0          # LINE_STRIP, ADD
            m.pose.orientation.w = 1.0
            m.scale.x = 0.01 if ns == "candidates" else 0.02
            m.color.r, m.color.g, m.color.b, m.color.a = colour
            pl = []
            for p in pts[:: max(1, len(pts) // 50)]:
                q = self.Point()
                q.x, q.y, q.z = float(p[0]), float(p[1]), float(p[2])
                pl.append(q)
            m.points = pl
            out.append(m)
        arr.markers = out
        self.pub_cand.publish(arr)

    def _publish_mob(self, event: str, force: bool = False, log: bool = True) -> None:
        t = self._last_stamp if self._last_stamp is not None else 0.0
        if not force and t - self._last_mob_pub < 1.0:
            return
        self._last_mob_pub = t
        m = self.MotionState()
        if self._last_stamp is not None:
            mc.set_stamp(m.header.stamp, t)
        law = self.law
        m.state = law.state
        m.fsm_event = event or law.segment_result
        m.fsm_state = mc.MotionState.NAMES.get(law.state, str(law.state))
        if law.segment_result:
            m.fsm_state += f" {law.segment_result}"
        self.pub_mob.publish(m)
        if event and log:
            self.log.info(f"{m.fsm_state}: {event}")
