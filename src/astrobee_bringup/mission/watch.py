"""What the mission follows of one robot: its truth pose and twist, reference and commands, its
/mob/state changes and its /sim/fault; during a leg every message also goes to the leg's
astrobee.leg_samples builder (the samples the Task judges)."""
from __future__ import annotations

from typing import Any

import numpy as np

from astrobee import msgconv as mc
from astrobee.leg_samples import LegSamples
from astrobee.task import robot_named
from astrobee_bringup.series import Series, robot_label

IDLE, STOPPED, CONTROLLING = (mc.MotionState.IDLE, mc.MotionState.STOPPED,
                              mc.MotionState.CONTROLLING)
# After a fault (the sim's propulsion watchdog: the controller is gone) the leg ends once the
# robot has been watched coasting this long (sim s), or this many wall s (a slow lockstep sim).
FAULT_WATCH_SIM, FAULT_WATCH_WALL = 0.5, 3.0


class RobotWatch:
    """One robot (namespace `name`, "" = the default robot): its pose, reference and commands
    (a summary.Series for the plot), its /mob/state changes and its /sim/fault."""

    def __init__(self, node: Any, name: str, latched: Any, deep_latched: Any) -> None:
        pre = mc.ns(name) + "/"
        self.name = name
        self.label = robot_label(name)
        self.named = robot_named(name)
        self.series = Series()
        self.leg: LegSamples | None = None       # the current leg's samples (set by the leg)
        self.pose: tuple[np.ndarray, np.ndarray] | None = None
        self.sim_time = float("nan")
        self.mob_state: int | None = None
        self.mob_event = ""
        self.mob_changes: list[tuple[float, int, str]] = []
        self.faults: list[tuple[float, str]] = []       # (sim time, text) during this flight
        self.fault_active: tuple[float, str] | None = None
        self.log = node.get_logger()
        # the truth the Task judges: a deep queue (a loaded mission must not drop samples)
        node.create_subscription("geometry_msgs/msg/PoseStamped", pre + mc.POSE, self._on_pose, 100)
        node.create_subscription("geometry_msgs/msg/TwistStamped", pre + mc.TWIST,
                                 self._on_twist, 100)
        self.cmd_ns = -1                # stamp (ns) of the last command (any control mode)
        node.create_subscription("astrobee_msgs/msg/FamCommand", pre + mc.COMMAND,
                                 self._on_command, 10)
        node.create_subscription("astrobee_msgs/msg/ControlState", pre + mc.TRAJ,
                                 self._on_traj, 10)
        # every state change counts: a deep queue (a depth-1 queue keeps only the newest of a
        # burst such as STOPPING -> STOPPED on a loaded machine)
        node.create_subscription("astrobee_msgs/msg/MotionState", pre + mc.MOB_STATE,
                                 self._on_mob, deep_latched)
        node.create_subscription("astrobee_msgs/msg/Fault", pre + mc.FAULT, self._on_fault,
                                 deep_latched)
        self.seg_pub = node.create_publisher("astrobee_msgs/msg/Segment", pre + mc.SEGMENT, latched)

    def _on_command(self, msg: Any) -> None:
        self.cmd_ns = mc.stamp_ns(msg.header.stamp)
        self.series.add_command(msg)
        if self.leg is not None:
            self.leg.add_command(self.name, msg)

    def _on_traj(self, msg: Any) -> None:
        self.series.add_traj(msg)
        if self.leg is not None:
            self.leg.add_traj(self.name, msg)

    def _on_pose(self, msg: Any) -> None:
        self.pose = mc.pose(msg.pose)
        self.sim_time = mc.stamp_ns(msg.header.stamp) * 1e-9
        self.series.add_pose(msg)
        if self.leg is not None:
            self.leg.add_pose(self.name, msg)

    def _on_twist(self, msg: Any) -> None:
        if self.leg is not None:
            self.leg.add_twist(self.name, msg)

    def _on_mob(self, msg: Any) -> None:
        state = int(msg.state)
        if state != self.mob_state or (msg.fsm_event and msg.fsm_event != self.mob_event):
            self.mob_changes.append((mc.stamp_ns(msg.header.stamp) * 1e-9, state,
                                     str(msg.fsm_event)))
        self.mob_state, self.mob_event = state, str(msg.fsm_event)

    def _on_fault(self, msg: Any) -> None:
        if self.leg is not None:
            self.leg.add_fault(self.name, msg)
        if msg.active:
            fault = (mc.stamp_ns(msg.header.stamp) * 1e-9,
                     f"{msg.source}: {msg.message} (code {msg.code})")
            self.fault_active = fault
            self.faults.append(fault)
            self.log.warn(f"fault of {self.named}: {fault[1]}")
        else:
            self.fault_active = None

    def start_leg(self, leg: LegSamples | None = None) -> int:
        """Forget the previous leg's figures and faults (an active fault stays) and send this
        leg's messages to `leg`; returns the index of the next /mob/state change."""
        self.series = Series()
        self.leg = leg
        self.faults = [self.fault_active] if self.fault_active else []
        return len(self.mob_changes)

    def controlling_since(self, n: int) -> float | None:
        """Sim time of the first CONTROLLING state from change n on, else None."""
        return next((t for t, s, _ in self.mob_changes[n:] if s == CONTROLLING), None)

    def position_at(self, t: float) -> list[float] | None:
        """The recorded position nearest sim time t."""
        if not self.series.pose_t:
            return None
        i = int(np.argmin(np.abs(np.asarray(self.series.pose_t) - t)))
        return list(self.series.position[i])
