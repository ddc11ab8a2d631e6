"""Real-time factor of the simulator while the robot drives the bag, per bag model.

Three figures per row: the Simulation loop (physics + the per-tick state queries sim_node makes),
the whole sim_node process in lockstep with this process as the controller over the ROS 2 wire
(publishing every topic, one command per tick, router in between: the round trip counts), and
sim_node in fast clock mode (no waiting: its own throughput, publishing included).
Reference: pyastrobee 0.6x real time at 379 FEM nodes (FACTS.md section 6).
Targets: >= 3x at ~400 nodes on one core, >= 50x for the reduced models.

    .venv/bin/python bench/sim_rtf.py            # --quick (default): a few simulated seconds
    .venv/bin/python bench/sim_rtf.py --full     # longer runs
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from astrobee import rotations as rot
from astrobee_sim.robot import qrot
from astrobee_sim.simulation import Simulation

CASES = [("fem", 400), ("fem", 1000), ("constraint", 0), ("composite", 0), ("rigid", 0)]
TARGET = {"fem": 3.0, "constraint": 50.0, "composite": 50.0, "rigid": 50.0}
# round one's figures on this machine (Simulation wall / sim_node wall), before the overhead cuts
ROUND1 = {("fem", 400): (1.1, 0.8), ("fem", 1000): (0.4, float("nan")), ("constraint", 0): (32.9, 11.8),
          ("composite", 0): (4.0, 3.6), ("rigid", 0): (36.7, 13.5)}


def pd_wrench(pos, q, v, w, goal, q_goal):
    """Body-frame wrench of a plain PD law (gains of the nominal flight mode, mass 20 kg).

    Plain floats (the controller's cost is not the simulator's: numpy calls on 3-vectors cost
    more than the reduced models' physics step)."""
    qx, qy, qz, qw = (float(c) for c in q)
    qi = (-qx, -qy, -qz, qw)
    f = qrot(qi, [20.0 * (0.6 * (float(g) - float(p)) - 1.2 * float(u)) for g, p, u in zip(goal, pos, v)])
    gx, gy, gz, gw = (float(c) for c in q_goal)
    # e = conj(q) * q_goal: small-angle attitude error, body frame
    ex = qw * gx - qx * gw - qy * gz + qz * gy
    ey = qw * gy + qx * gz - qy * gw - qz * gx
    ez = qw * gz - qx * gy + qy * gx - qz * gw
    ew = qw * gw + qx * gx + qy * gy + qz * gz
    s = 2.0 if ew >= 0 else -2.0
    wb = qrot(qi, w)
    return [f[0], f[1], f[2], 0.15 * (4.0 * s * ex - 3.2 * wb[0]),
            0.15 * (4.0 * s * ey - 3.2 * wb[1]), 0.15 * (4.0 * s * ez - 3.2 * wb[2])]


def goal_at(t, start):
    """Back and forth 0.6 m along the station's y axis every 10 s: the bag is dragged and pushed."""
    return start + np.array([0.0, -0.6 if int(t / 10) % 2 == 0 else 0.0, 0.0])


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process (Linux /proc)."""
    import os
    fields = open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def library_rtf(model: str, res: int, seconds: float, fem_solver: str | None = None
                ) -> tuple[float, float, int]:
    """(wall, CPU) real-time factor of the library loop and the FEM node count."""
    sim = Simulation("node2_to_jem_bag", bag_model=model, bag_resolution=res or None,
                     fem_solver=fem_solver)
    try:
        start, q0 = sim.robot_state()[:2]
        nodes = len(sim.bag.points()) if model == "fem" else 0
        t0, c0 = time.perf_counter(), time.process_time()
        tick = 0
        while sim.time < seconds:
            pos, q, v, w = sim.robot_state()
            sim.command(pd_wrench(pos, q, v, w, goal_at(sim.time, start), q0))
            tick += 1
            sim.step(max(1, int(round(tick * 0.016 / sim.dt)) - sim.steps))
            sim.bag_state()
            sim.clearance()
            sim.contacts()
        return sim.time / (time.perf_counter() - t0), sim.time / (time.process_time() - c0), nodes
    finally:
        sim.close()


def node_rtf(model: str, res: int, seconds: float, mode: str = "lockstep") -> tuple[float, float]:
    """sim_node with this process closing the loop over the ROS 2 wire: in lockstep (the sim
    waits for each tick's command: the round trip counts) or fast (no waiting: the sim's own
    throughput with every topic published; commands then arrive a few ticks late)."""
    import roszen
    from roszen import testing
    with testing.router() as port:
        env = testing.zenoh_env(port)
        args = ["-m", "astrobee_sim.sim_node", "--ros-args", "-p", "scenario:=node2_to_jem_bag",
                "-p", f"bag_model:={model}", "-p", f"clock_mode:={mode}",
                "-p", f"max_sim_time:={seconds + 1.0}"]
        if res:
            args += ["-p", f"bag_resolution:={res}"]
        proc = testing.spawn(testing.python_cmd(*args), env)
        ctx = roszen.Context(env=env)
        node = roszen.Node("sim_rtf_bench", context=ctx)
        try:
            Cmd = roszen.message_class("astrobee_msgs/msg/FamCommand")
            pub = node.create_publisher("astrobee_msgs/msg/FamCommand", "/gnc/ctl/command", 10)
            marks: dict = {}
            last = [-1]
            start = []

            def on_ekf(m):
                t_ns = m.header.stamp.sec * 10**9 + m.header.stamp.nanosec
                if t_ns == last[0]:
                    return
                last[0] = t_ns
                t = t_ns * 1e-9
                pos = np.array([m.pose.position.x, m.pose.position.y, m.pose.position.z])
                q = np.array([m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z,
                              m.pose.orientation.w])
                v = np.array([m.velocity.x, m.velocity.y, m.velocity.z])
                w_body = np.array([m.omega.x, m.omega.y, m.omega.z])
                if not start:
                    start.extend([pos, q])
                wr = pd_wrench(pos, q, v, rot.rotate(q, w_body), goal_at(t, start[0]), start[1])
                c = Cmd()
                c.header.stamp = m.header.stamp
                (c.wrench.force.x, c.wrench.force.y, c.wrench.force.z, c.wrench.torque.x,
                 c.wrench.torque.y, c.wrench.torque.z) = (float(x) for x in wr)
                pub.publish(c)
                if t >= 0.5 and "t0" not in marks:          # past start-up transients
                    marks["t0"], marks["w0"], marks["c0"] = t, time.perf_counter(), cpu_seconds(proc.pid)
                marks["t1"], marks["w1"] = t, time.perf_counter()
                if t < seconds + 0.5:
                    marks["c1"] = cpu_seconds(proc.pid)

            node.create_subscription("astrobee_msgs/msg/EkfState", "/gnc/ekf", on_ekf, 50)
            end = time.monotonic() + 20 + 5 * seconds
            while marks.get("t1", 0.0) < seconds + 0.5 and time.monotonic() < end and proc.poll() is None:
                node.spin_once(timeout_sec=0.05)
            if "t0" not in marks or marks["t1"] <= marks["t0"]:
                return float("nan"), float("nan")
            dt = marks["t1"] - marks["t0"]
            return dt / (marks["w1"] - marks["w0"]), dt / max(marks["c1"] - marks["c0"], 1e-3)
        finally:
            node.destroy_node()
            ctx.shutdown()
            testing.stop(proc)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", default=True)
    ap.add_argument("--full", action="store_true")
    ap.add_argument("--no-node", action="store_true", help="skip the sim_node (process) column")
    a = ap.parse_args()
    secs = {("fem", 400): 3.0, ("fem", 1000): 1.5}
    scale = 5.0 if a.full else 1.0
    rows = []
    for model, res in CASES:
        s = secs.get((model, res), 10.0) * scale
        lib_wall, lib_cpu, nodes = library_rtf(model, res, s)
        nd_wall, nd_cpu = (float("nan"),) * 2 if a.no_node else node_rtf(model, res, s)
        fast_wall, fast_cpu = (float("nan"),) * 2 if a.no_node else node_rtf(model, res, s, "fast")
        rows.append((model, nodes, s, lib_wall, lib_cpu, nd_wall, nd_cpu, fast_wall, fast_cpu))
    print("\nsim real-time factor while a PD law drags the bag (350 Hz physics, 62.5 Hz ticks)")
    print("wall = elapsed time on this (shared, 2-core) machine; cpu = per CPU-second of the sim "
          "process (the 'one core' figure); sim_node = lockstep with this process as the controller "
          "over the wire (includes the round trip per tick); fast = sim_node in fast clock mode "
          "(no waiting), same controller")
    print(f"{'model':<11}{'nodes':>6}{'sim s':>6}{'Simulation wall':>16}{'cpu':>7}"
          f"{'lockstep wall':>14}{'cpu':>7}{'fast wall':>10}{'cpu':>7}{'target':>8}"
          f"{'round 1 (lib/lockstep)':>24}  reference (pyastrobee)")
    for (model, nodes, s, lw, lc, nw, nc, fw, fc), case in zip(rows, CASES):
        ref = "0.6x at 379 nodes" if model == "fem" else "-"
        r1 = ROUND1.get(case, (float("nan"),) * 2)
        print(f"{model:<11}{nodes or '-':>6}{s:>6.1f}{lw:>15.1f}x{lc:>6.1f}x{nw:>13.1f}x{nc:>6.1f}x"
              f"{fw:>9.1f}x{fc:>6.1f}x{TARGET[model]:>7.0f}x{r1[0]:>16.1f}x /{r1[1]:>5.1f}x  {ref}")


if __name__ == "__main__":
    main()
