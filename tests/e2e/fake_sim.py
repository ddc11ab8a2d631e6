"""A stand-in simulator for graph tests of the mission/controller/planner chain without pybullet:
a numpy rigid body in lockstep with the controller (publishes a state, waits for the command of
that stamp, steps), with /clock, /loc/truth/pose|twist, /gnc/ekf, /sim/contacts and /sim/fault, and /sim/reset (teleport to a scenario's start).

    python tests/e2e/fake_sim.py --position X Y Z --yaw RAD
"""
from __future__ import annotations

import argparse
import sys
import time

import numpy as np

import roszen
from astrobee import rotations as rot
from astrobee_control import mass as mp
from astrobee_control.rigid_body import RigidBody

DT = 1.0 / 62.5


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--position", type=float, nargs=3, required=True)
    ap.add_argument("--yaw", type=float, default=0.0)
    a = ap.parse_args()
    node = roszen.Node("sim_node")
    body = RigidBody(mp.robot(), a.position, rot.from_axis_angle([0, 0, 1], a.yaw))
    M = roszen.message_class
    pubs = {n: node.create_publisher(t, n, 10) for n, t in (
        ("/loc/truth/pose", "geometry_msgs/msg/PoseStamped"),
        ("/loc/truth/twist", "geometry_msgs/msg/TwistStamped"),
        ("/gnc/ekf", "astrobee_msgs/msg/EkfState"),
        ("/sim/contacts", "astrobee_msgs/msg/Contacts"),
        ("/sim/fault", "astrobee_msgs/msg/Fault"))}
    clock = node.create_publisher("rosgraph_msgs/msg/Clock", "/clock", roszen.CLOCK)
    cmds: dict = {}
    node.create_subscription("astrobee_msgs/msg/FamCommand", "/gnc/ctl/command",
                             lambda m: cmds.__setitem__((m.header.stamp.sec, m.header.stamp.nanosec), m), 50)
    t, wrench, last_cmd_t, fault = 0.0, np.zeros(6), 0.0, False
    Reset = roszen.response_class("astrobee_msgs/srv/Reset")

    def on_reset(req):
        nonlocal body
        from astrobee import config
        resp = Reset()
        try:
            r = config.scenario(req.scenario)["robots"][0]
        except config.ConfigError as exc:
            resp.success, resp.message = False, str(exc)
            return resp
        body = RigidBody(mp.robot(), r["position"], r["orientation"])
        resp.success, resp.message = True, f"reset to {req.scenario}"
        return resp

    node.create_service("astrobee_msgs/srv/Reset", "/sim/reset", on_reset)
    try:
        while True:
            s = body.state()
            sec = int(t)
            stamp = M("builtin_interfaces/msg/Time")()
            stamp.sec, stamp.nanosec = sec, int(round((t - sec) * 1e9))
            c = M("rosgraph_msgs/msg/Clock")()
            c.clock = stamp
            clock.publish(c)
            pose = M("geometry_msgs/msg/PoseStamped")()
            pose.header.stamp, pose.header.frame_id = stamp, "world"
            pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = s.position
            o = pose.pose.orientation
            o.x, o.y, o.z, o.w = s.orientation
            tw = M("geometry_msgs/msg/TwistStamped")()
            tw.header.stamp = stamp
            tw.twist.linear.x, tw.twist.linear.y, tw.twist.linear.z = s.velocity
            w = rot.rotate(s.orientation, s.omega)
            tw.twist.angular.x, tw.twist.angular.y, tw.twist.angular.z = w
            ekf = M("astrobee_msgs/msg/EkfState")()
            ekf.header.stamp = stamp
            ekf.pose = pose.pose
            ekf.velocity = tw.twist.linear
            ekf.omega.x, ekf.omega.y, ekf.omega.z = s.omega
            ct = M("astrobee_msgs/msg/Contacts")()
            ct.header.stamp = stamp
            ct.robot_clearance, ct.bag_clearance = 0.5, -1.0
            for n, m in (("/loc/truth/pose", pose), ("/loc/truth/twist", tw), ("/gnc/ekf", ekf),
                         ("/sim/contacts", ct)):
                pubs[n].publish(m)
            key = (stamp.sec, stamp.nanosec)
            end = time.monotonic() + 0.2  # lockstep, but run on without a controller
            while key not in cmds and time.monotonic() < end:
                node.spin_once(timeout_sec=0.005)
            if key in cmds:
                m = cmds.pop(key)
                wrench = np.array([m.wrench.force.x, m.wrench.force.y, m.wrench.force.z,
                                   m.wrench.torque.x, m.wrench.torque.y, m.wrench.torque.z])
                last_cmd_t = t
            if t - last_cmd_t > 0.32:
                wrench = np.zeros(6)
                if not fault:
                    fault = True
                    f = M("astrobee_msgs/msg/Fault")()
                    f.header.stamp, f.source, f.code, f.active = stamp, "watchdog", 1, True
                    f.message = "no command for 0.32 s"
                    pubs["/sim/fault"].publish(f)
            for _ in range(2):
                body.step(wrench[:3], wrench[3:], DT / 2)
            t += DT
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
    return 0


if __name__ == "__main__":
    sys.exit(main())
