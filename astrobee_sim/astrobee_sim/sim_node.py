"""sim_node: the Simulation served on the ROS 2 graph (thin wiring; physics lives in simulation.py).

Per robot namespace <ns> ("" for the default robot): publishes <ns>/loc/truth/pose,
<ns>/loc/truth/twist (world-frame linear and angular velocity), <ns>/gnc/ekf (EkfState: world
velocity, BODY omega), latched <ns>/mob/flight_mode and <ns>/sim/fault (propulsion watchdog);
subscribes <ns>/gnc/ctl/command (FamCommand, BODY wrench); serves <ns>/mob/set_flight_mode.
Global: /clock, /tf, /sim/bag/state, /sim/bag/mesh (mesh_rate), /sim/contacts, latched
/sim/markers; services /sim/reset, /sim/set_flight_mode, /sim/control.

Clock modes: realtime (paced to the wall clock), fast (no pacing), lockstep (after publishing
the state of tick k the sim waits, at most `lockstep_timeout` s of wall time, for a command
stamped >= tick k on every robot whose command topic has a publisher; on timeout it logs and
steps on, the propulsion watchdog then acting as on the robot). Commands stamped more than
`command_max_lead` (0.5 s) ahead of sim time are dropped with a rate-limited warning: after a
reset sim time restarts at 0, so answers to pre-reset states land there; a reset also forgets
the lockstep command stamps, and a command counts for the current tick at most.
"""
from __future__ import annotations

import os
import sys
import time
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")    # before numpy: see astrobee_sim/__init__.py

import numpy as np  # noqa: E402

from astrobee import config, flight_modes
from .robot import qrot
from .simulation import ScenarioError, Simulation, sim_defaults

FAULT_WATCHDOG = 1


def _ns(name: str) -> str:
    return f"/{name}" if name else ""


def _stamp(msg_stamp: Any, t_ns: int) -> None:
    msg_stamp.sec, msg_stamp.nanosec = int(t_ns // 1_000_000_000), int(t_ns % 1_000_000_000)


def _vec(dst: Any, v) -> None:
    dst.x, dst.y, dst.z = float(v[0]), float(v[1]), float(v[2])


def _pose(dst: Any, p, q) -> None:
    _vec(dst.position, p)
    dst.orientation.x, dst.orientation.y, dst.orientation.z, dst.orientation.w = (float(x) for x in q)


class SimNode:
    """Wires a Simulation to topics and services; callbacks never raise."""

    def __init__(self, argv: list[str] | None = None) -> None:
        import roszen
        from roszen import LATCHED

        self.roszen = roszen
        self.node = n = roszen.Node("sim_node", argv=argv)
        self.log = n.get_logger()
        d = sim_defaults()
        par = lambda name, default: n.declare_parameter(name, d.get(name, default)).value  # noqa: E731
        self.scenario = par("scenario", "node2_to_jem")
        bag_model = par("bag_model", "")
        bag_variant = par("bag_variant", "")
        bag_resolution = int(par("bag_resolution", 0))
        robots_param = str(par("robots", ""))       # comma list of robot names; "" = the scenario's
        robots = [r.strip() for r in robots_param.split(",")] if robots_param.strip() else None
        self.clock_mode = par("clock_mode", "realtime")
        if self.clock_mode not in ("realtime", "fast", "lockstep"):
            raise ValueError(f"clock_mode must be realtime, fast or lockstep, not {self.clock_mode!r}")
        physics_rate = float(par("physics_rate", 350.0))
        self.publish_rate = float(par("publish_rate", 62.5))
        self.mesh_rate = float(par("mesh_rate", 10.0))
        self.lockstep_timeout = float(par("lockstep_timeout", 1.0))
        self.lockstep_start_timeout = float(par("lockstep_start_timeout", 30.0))
        # commands stamped further than this ahead of sim time are dropped (stale, pre-reset)
        self.command_max_lead_ns = int(float(par("command_max_lead", 0.5)) * 1e9)
        seed = int(par("seed", 0))
        gui = bool(par("gui", False))
        drag = bool(par("drag", False))
        flight_mode = par("flight_mode", "")
        self.max_sim_time = float(par("max_sim_time", 0.0))   # 0: run until stopped
        if physics_rate <= 0 or self.publish_rate <= 0 or physics_rate < self.publish_rate:
            raise ValueError("physics_rate and publish_rate must be > 0 with physics_rate >= publish_rate")
        self.sim = Simulation(self.scenario, seed=seed, physics_rate=physics_rate, gui=gui, drag=drag,
                              bag_model=bag_model or None, bag_variant=bag_variant or None,
                              bag_resolution=bag_resolution or None, robots=robots,
                              flight_mode=flight_mode or None)
        M = roszen.message_class
        self.M = {k: M(v) for k, v in {
            "clock": "rosgraph_msgs/msg/Clock", "pose": "geometry_msgs/msg/PoseStamped",
            "twist": "geometry_msgs/msg/TwistStamped", "ekf": "astrobee_msgs/msg/EkfState",
            "tf": "tf2_msgs/msg/TFMessage", "tfs": "geometry_msgs/msg/TransformStamped",
            "bag": "astrobee_msgs/msg/BagState", "mesh": "astrobee_msgs/msg/BagMesh",
            "contacts": "astrobee_msgs/msg/Contacts", "contact": "astrobee_msgs/msg/Contact",
            "markers": "visualization_msgs/msg/MarkerArray", "marker": "visualization_msgs/msg/Marker",
            "mode": "astrobee_msgs/msg/FlightMode", "fault": "astrobee_msgs/msg/Fault"}.items()}
        self.pub_clock = n.create_publisher("rosgraph_msgs/msg/Clock", "/clock", roszen.CLOCK)
        self.pub_tf = n.create_publisher("tf2_msgs/msg/TFMessage", "/tf", 10)
        self.pub_bag = n.create_publisher("astrobee_msgs/msg/BagState", "/sim/bag/state", 10)
        self.pub_mesh = n.create_publisher("astrobee_msgs/msg/BagMesh", "/sim/bag/mesh", 2)
        self.pub_contacts = n.create_publisher("astrobee_msgs/msg/Contacts", "/sim/contacts", 10)
        self.pub_markers = n.create_publisher("visualization_msgs/msg/MarkerArray", "/sim/markers", LATCHED)
        self.robot_io: dict[str, dict] = {}
        self._make_robot_io()
        n.create_service("astrobee_msgs/srv/Reset", "/sim/reset", self._on_reset)
        n.create_service("astrobee_msgs/srv/SetFlightMode", "/sim/set_flight_mode",
                         lambda req: self._on_set_mode(req, None))
        n.create_service("astrobee_msgs/srv/SimControl", "/sim/control", self._on_control)
        self.paused = False
        self.pending_steps = 0
        self.tick = 0
        self._last_mesh = -1e9
        self._wall0 = time.monotonic()
        self._sim0 = 0.0
        self._warned: dict[str, float] = {}
        self.publish_markers()
        self.publish_modes()
        self.publish_state()
        self.log.info(f"sim up: scenario {self.sim.scenario_name}, robots {list(self.sim.robots)}, "
                      f"bag {self.sim.scenario.bag.model if self.sim.scenario.bag else 'none'}, "
                      f"clock {self.clock_mode}, physics {physics_rate:g} Hz")

    # ---- wiring per robot --------------------------------------------------------------
    def _make_robot_io(self) -> None:
        n, roszen = self.node, self.roszen
        for name in self.sim.robots:
            if name in self.robot_io:
                continue
            ns = _ns(name)
            io = {
                "pose": n.create_publisher("geometry_msgs/msg/PoseStamped", f"{ns}/loc/truth/pose", 10),
                "twist": n.create_publisher("geometry_msgs/msg/TwistStamped", f"{ns}/loc/truth/twist", 10),
                "ekf": n.create_publisher("astrobee_msgs/msg/EkfState", f"{ns}/gnc/ekf", 10),
                "mode": n.create_publisher("astrobee_msgs/msg/FlightMode", f"{ns}/mob/flight_mode",
                                           roszen.LATCHED),
                "fault": n.create_publisher("astrobee_msgs/msg/Fault", f"{ns}/sim/fault", roszen.LATCHED),
                "cmd_stamp": -1, "raw_stamp": -1, "fault_state": None, "topic": f"{ns}/gnc/ctl/command",
            }
            n.create_subscription("astrobee_msgs/msg/FamCommand", f"{ns}/gnc/ctl/command",
                                  lambda msg, nm=name: self._on_command(nm, msg), 10)
            n.create_service("astrobee_msgs/srv/SetFlightMode", f"{ns}/mob/set_flight_mode",
                             lambda req, nm=name: self._on_set_mode(req, nm))
            self.robot_io[name] = io

    # ---- callbacks ---------------------------------------------------------------------
    def _warn(self, key: str, text: str, every: float = 2.0) -> None:
        now = time.monotonic()
        if now - self._warned.get(key, -1e9) >= every:
            self._warned[key] = now
            self.log.warn(text)

    def _on_command(self, name: str, msg: Any) -> None:
        try:
            w = msg.wrench
            wrench = np.array([w.force.x, w.force.y, w.force.z, w.torque.x, w.torque.y, w.torque.z], float)
            stamp = int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)
        except (AttributeError, TypeError, ValueError) as exc:
            self._warn("badcmd", f"malformed command for robot {name!r} dropped: {exc}")
            return
        if name not in self.sim.robots:
            return
        now = self.now_ns()
        if stamp > now + self.command_max_lead_ns:
            # after a reset sim time restarts at 0: a command answering a state from before the
            # reset carries a stamp ahead of the new sim time; it would also let lockstep skip
            # its waits up to that stamp
            self._warn("ahead", f"command for robot {name!r} stamped {stamp / 1e9:.3f} s, more than "
                       f"{self.command_max_lead_ns / 1e9:g} s ahead of sim time {now / 1e9:.3f} s "
                       f"(from before a reset?): dropped")
            return
        if not self.sim.command(wrench, name):
            self._warn("rejected", f"command rejected for robot {name!r} (non-finite or > 100 N/Nm): "
                       f"{np.array2string(wrench, precision=3)}")
            return
        io = self.robot_io[name]
        # a command never answers a tick the sim has not reached: lockstep counts it for the
        # current tick at most (a slightly-ahead stamp must not let later ticks run unanswered),
        # and a stamp answers one tick only (repeats of one command arriving a tick apart, as
        # on a loaded machine, must not each let the sim step on)
        if stamp != io["raw_stamp"]:
            io["raw_stamp"] = stamp
            io["cmd_stamp"] = max(io["cmd_stamp"], min(stamp, now))

    def _on_set_mode(self, req: Any, robot: str | None) -> Any:
        resp = self.roszen.response_class("astrobee_msgs/srv/SetFlightMode")()
        try:
            if robot is None:
                self.sim.set_flight_mode(req.flight_mode)
            else:
                self.sim.robots[robot].set_flight_mode(req.flight_mode)
        except flight_modes.UnknownFlightMode as exc:
            resp.success, resp.message = False, str(exc)
            return resp
        self.publish_modes()
        resp.success, resp.message = True, f"flight mode {req.flight_mode}"
        return resp

    def _on_reset(self, req: Any) -> Any:
        resp = self.roszen.response_class("astrobee_msgs/srv/Reset")()
        try:
            self.sim.reset(req.scenario or None, int(req.seed))
        except (ScenarioError, config.ConfigError, ValueError) as exc:
            resp.success, resp.message = False, str(exc)
            self.log.error(f"reset refused: {exc}")
            return resp
        self._make_robot_io()
        for io in self.robot_io.values():
            io["cmd_stamp"], io["raw_stamp"], io["fault_state"] = -1, -1, None
        self.tick = 0
        self._wall0, self._sim0 = time.monotonic(), 0.0
        self.publish_markers()
        self.publish_modes()
        self.publish_state()
        resp.success, resp.message = True, f"reset to {self.sim.scenario_name} (seed {self.sim.seed})"
        self.log.info(resp.message)
        return resp

    def _on_control(self, req: Any) -> Any:
        R = self.roszen.response_class("astrobee_msgs/srv/SimControl")
        resp = R()
        if req.command == 0:
            self.paused = True
            resp.message = "paused"
        elif req.command == 1:
            self.paused = False
            self._wall0, self._sim0 = time.monotonic(), self.sim.time
            resp.message = "resumed"
        elif req.command == 2:
            if not self.paused:
                resp.success, resp.message = False, "STEP needs a paused simulation (send PAUSE first)"
                return resp
            steps = max(1, int(req.steps))
            self.sim.step(steps)
            self.publish_state()
            resp.message = f"stepped {steps}"
        else:
            resp.success, resp.message = False, f"unknown command {req.command} (0 PAUSE, 1 RESUME, 2 STEP)"
            return resp
        resp.success = True
        _stamp(resp.sim_time, self.now_ns())
        return resp

    # ---- publishing --------------------------------------------------------------------
    def now_ns(self) -> int:
        return int(round(self.sim.time * 1e9))

    def _robot_msgs(self, name: str) -> dict:
        """The per-tick messages of one robot, built once (publish() serialises at once, so
        mutating them afterwards is safe); headers, poses and rotations are shared objects."""
        M = self.M
        ps = M["pose"]()
        ps.header.frame_id = "world"
        tw = M["twist"]()
        tw.header = ps.header
        ekf = M["ekf"]()
        ekf.header = ps.header
        ekf.child_frame_id = f"{name}/body" if name else "body"
        ekf.pose = ps.pose
        ekf.confidence = 0
        ts = M["tfs"]()
        ts.header = ps.header
        ts.child_frame_id = ekf.child_frame_id
        ts.transform.rotation = ps.pose.orientation
        return {"pose": ps, "twist": tw, "ekf": ekf, "tfs": ts}

    def _global_msgs(self) -> dict:
        M = self.M
        bs = M["bag"]()
        bs.header.frame_id = "world"
        bts = M["tfs"]()
        bts.header = bs.header
        bts.child_frame_id = "bag"
        bts.transform.rotation = bs.pose.orientation
        cs = M["contacts"]()
        cs.header.frame_id = "world"
        return {"clock": M["clock"](), "tf": M["tf"](), "bag": bs, "bag_tfs": bts, "contacts": cs}

    def publish_state(self) -> None:
        t = self.now_ns()
        g = self.__dict__.get("_msgs")
        if g is None:
            g = self._msgs = self._global_msgs()
        clk = g["clock"]
        _stamp(clk.clock, t)
        self.pub_clock.publish(clk)
        transforms = []
        positions = []
        for name, r in self.sim.robots.items():
            io = self.robot_io[name]
            msgs = io.get("msgs")
            if msgs is None:
                msgs = io["msgs"] = self._robot_msgs(name)
            pos, q, v, w = self.sim.robot_state(name)
            positions.append(pos)
            ps, tw, ekf, ts = msgs["pose"], msgs["twist"], msgs["ekf"], msgs["tfs"]
            _stamp(ps.header.stamp, t)               # shared by twist, ekf and tf
            _pose(ps.pose, pos, q)                   # shared by ekf (and its rotation by tf)
            io["pose"].publish(ps)
            _vec(tw.twist.linear, v)
            _vec(tw.twist.angular, w)
            io["twist"].publish(tw)
            _vec(ekf.velocity, v)
            _vec(ekf.omega, qrot((-q[0], -q[1], -q[2], q[3]), w))      # world -> body
            io["ekf"].publish(ekf)
            _vec(ts.transform.translation, pos)
            transforms.append(ts)
            fault = self.sim.fault[name]
            if fault != io["fault_state"]:
                io["fault_state"] = fault
                f = self.M["fault"]()
                f.header = ps.header
                f.source = "sim/propulsion_watchdog"
                f.code = FAULT_WATCHDOG
                f.active = bool(fault)
                f.message = (f"no command for {self.sim.watchdog_timeout:g} s: propulsion stopped"
                             if fault else "commands flowing")
                io["fault"].publish(f)
        bag = self.sim.bag
        rc, bc = self.sim.clearance(positions)
        if bag is not None:
            st = bag.state()
            bs, bts = g["bag"], g["bag_tfs"]
            _stamp(bs.header.stamp, t)
            bs.model, bs.variant = bag.model, bag.variant
            _pose(bs.pose, st.position, st.orientation)
            _vec(bs.velocity, st.velocity)
            _vec(bs.omega, st.omega)
            bs.deformation = float(st.deformation)
            bs.attached = np.array(st.attached, dtype=bool)
            self.pub_bag.publish(bs)
            _vec(bts.transform.translation, st.position)
            transforms.append(bts)
            if self.sim.time - self._last_mesh >= 1.0 / self.mesh_rate - 1e-9:
                self._last_mesh = self.sim.time
                pts = bag.points()
                mm = self.M["mesh"]()
                mm.header = bs.header
                mm.num_nodes = len(pts)
                mm.positions = np.asarray(pts, np.float32).reshape(-1)
                self.pub_mesh.publish(mm)
        tf = g["tf"]
        tf.transforms = transforms
        self.pub_tf.publish(tf)
        cs = g["contacts"]
        _stamp(cs.header.stamp, t)
        lst = []
        for c in self.sim.contacts():
            m = self.M["contact"]()
            m.body_a, m.body_b = c.body_a, c.body_b
            _vec(m.position, c.position)
            _vec(m.normal, c.normal)
            m.normal_force = float(c.normal_force)
            lst.append(m)
        cs.contacts = lst
        cs.in_contact = bool(lst)
        cs.robot_clearance, cs.bag_clearance = float(rc), float(bc)
        self.pub_contacts.publish(cs)

    def publish_modes(self) -> None:
        for name, r in self.sim.robots.items():
            m, fm = self.M["mode"](), r.mode
            _stamp(m.header.stamp, self.now_ns())
            m.name, m.control_enabled, m.speed = fm.name, fm.control_enabled, fm.speed
            m.collision_radius = fm.collision_radius
            m.tolerance_pos = m.tolerance_pos_endpoint = fm.tolerance_pos
            m.tolerance_att = fm.tolerance_att
            for k in ("att_kp", "att_ki", "omega_kd", "pos_kp", "pos_ki", "vel_kd"):
                _vec(getattr(m, k), getattr(fm, k))
            m.hard_limit_vel, m.hard_limit_accel = fm.hard_limit_vel, fm.hard_limit_accel
            m.hard_limit_omega, m.hard_limit_alpha = fm.hard_limit_omega, fm.hard_limit_alpha
            self.robot_io[name]["mode"].publish(m)

    def publish_markers(self) -> None:
        from .world import module_colour
        M = self.M
        arr = M["markers"]()
        out = []
        w = self.sim.world
        for i, (box, mod) in enumerate(zip(w.keep_in, w.modules)):
            m = M["marker"]()
            m.header.frame_id = "world"
            m.ns, m.id, m.type, m.action = "keep_in", i, 1, 0           # CUBE, ADD
            _vec(m.pose.position, (box[:3] + box[3:]) / 2)
            m.pose.orientation.w = 1.0
            _vec(m.scale, box[3:] - box[:3])
            m.color.r, m.color.g, m.color.b = module_colour(mod)
            m.color.a = 0.15
            out.append(m)
        for i, (name, mod) in enumerate(config.iss()["modules"].items()):
            m = M["marker"]()
            m.header.frame_id = "world"
            m.ns, m.id, m.type, m.action = "modules", i, 9, 0           # TEXT_VIEW_FACING
            _vec(m.pose.position, mod["origin"])
            m.pose.orientation.w = 1.0
            m.scale.z = 0.2
            m.color.r = m.color.g = m.color.b = m.color.a = 1.0
            m.text = mod.get("label", name)
            out.append(m)
        arr.markers = out
        self.pub_markers.publish(arr)

    # ---- main loop ---------------------------------------------------------------------
    def _drain(self, timeout: float = 0.0) -> None:
        """Run the callbacks that are ready (waiting up to `timeout` for the first)."""
        if self.node.spin_once(timeout_sec=timeout):
            while self.node.spin_once(timeout_sec=0):
                pass

    def _wait_commands(self) -> None:
        """Lockstep: wait for a command stamped >= the current tick from every commanded robot.

        A robot counts once its command topic has a publisher or it has sent a command. At the
        first tick (after start or a reset) the sim waits up to `lockstep_start_timeout` for a
        controller to appear, later ticks up to `lockstep_timeout`; on timeout it logs and
        steps on. While waiting it republishes the state every 0.5 s (a late subscriber may
        have missed it).
        """
        t = self.now_ns()
        first = self.tick == 0
        limit = self.lockstep_start_timeout if first else self.lockstep_timeout
        end = time.monotonic() + limit
        next_pub = time.monotonic() + 0.5

        def waiting():
            want = [n for n, io in self.robot_io.items() if n in self.sim.robots and
                    (io["cmd_stamp"] >= 0 or self.node.count_publishers(io["topic"]) > 0)]
            if first and not want:
                return ["(no controller yet)"]
            return [n or "/" for n in want if self.robot_io[n]["cmd_stamp"] < t]
        late = waiting()
        while late:
            now = time.monotonic()
            if now >= end:
                self._warn("lockstep", f"lockstep: no command for t={t / 1e9:.3f} s from {late} "
                           f"within {limit:g} s; stepping on")
                return
            if now >= next_pub:
                self.publish_state()
                next_pub = now + 0.5
            self._drain(min(end - now, 0.02))
            late = waiting()

    def run_tick(self) -> None:
        """Wait (lockstep), step to the next publish tick, publish."""
        if self.clock_mode == "lockstep":
            self._wait_commands()
        self.tick += 1
        target = int(round(self.tick / self.publish_rate / self.sim.dt))
        self.sim.step(max(1, target - self.sim.steps))
        self.publish_state()

    def spin(self) -> None:
        import roszen
        while roszen.ok() and self.node._alive:
            if self.max_sim_time and self.sim.time >= self.max_sim_time:
                self.log.info(f"max_sim_time {self.max_sim_time:g} s reached")
                return
            self._drain(0.0)
            if self.paused:
                self._drain(0.05)
                continue
            self.run_tick()
            if self.clock_mode == "realtime":
                ahead = (self.sim.time - self._sim0) - (time.monotonic() - self._wall0)
                while ahead > 0:           # serve callbacks while waiting for the wall clock
                    self._drain(ahead)
                    ahead = (self.sim.time - self._sim0) - (time.monotonic() - self._wall0)
                if ahead < -1.0:        # far behind: do not try to catch up in a burst
                    self._warn("behind", f"sim running behind real time by {-ahead:.1f} s")
                    self._wall0, self._sim0 = time.monotonic(), self.sim.time

    def close(self) -> None:
        self.node.destroy_node()
        self.sim.close()


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv if argv is None else argv
    try:
        sn = SimNode(argv)
    except (config.ConfigError, ScenarioError, flight_modes.UnknownFlightMode, ValueError) as exc:
        print(f"sim_node: error: {exc}", file=sys.stderr)
        return 2
    try:
        sn.spin()
    except KeyboardInterrupt:
        pass
    finally:
        sn.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
