"""Real-time factor of the simulator while the robot drives the bag, per bag model.

Table 1, three figures per row: the Simulation loop (physics + the per-tick state queries
sim_node makes), the whole sim_node process in lockstep with this process as the controller over
the ROS 2 wire (publishing every topic, one command per tick, router in between: the round trip
counts), and sim_node in fast clock mode (no waiting: its own throughput, publishing included).
The FEM bag on the fast solver (the default) and on Bullet's (the reference), same run.

Table 2: the whole graph as `astrobee launch cargo_transport` starts it (router,
sim_node in lockstep, planner, the PD or MPC controller process, mission; no recorder) flying
Node 2 -> JEM with the FEM bag: the mission's real-time factor over the 44 s flight. Bullet's
solver in the same run as the reference; the pair laws (pair_gov, gov_clear: pair_gov with its
lever and clearance weight as studies/lever_clearance.yaml flies it, through controller_params:=,
and wmpc) on the demo's carry (strap grasp, a 5 N bump on the bag) beside PD on the same flight.
And K=64 batched copies of the fast FEM bag + robot
(fem_rollout) in bag-seconds per wall second.
Reference: pyastrobee 0.6x real time at 379 FEM nodes (FACTS.md section 6).
Targets: >= 3x at ~400 nodes (goal 10x), >= 1x at ~1500 nodes, >= 50x for the reduced
models, MPC in the loop with the FEM bag >= 1x.

    .venv/bin/python bench/sim_rtf.py            # --quick (default): a few simulated seconds
    .venv/bin/python bench/sim_rtf.py --full     # longer runs, the 1500-node graph row
    .venv/bin/python bench/sim_rtf.py --graph-only   # only Table 2 (whole graph, per controller)
    .venv/bin/python bench/sim_rtf.py --node-fast 5   # rigid/constraint through sim_node, fast
                                                      # clock, with and without a recorder
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from astrobee import rotations as rot
from astrobee_sim.robot import qrot
from astrobee_sim.simulation import Simulation

# (model, FEM nodes, FEM solver): fast is the default solver, bullet the reference
CASES = [("fem", 400, "fast"), ("fem", 400, "bullet"), ("fem", 1500, "fast"), ("fem", 1500, "bullet"),
         ("constraint", 0, ""), ("composite", 0, ""), ("rigid", 0, "")]
TARGET = {"fem": 3.0, "constraint": 50.0, "composite": 50.0, "rigid": 50.0}
TARGET_FEM_1500 = 1.0
# round one's figures on this machine (Simulation wall / sim_node wall), before the overhead cuts
# (Bullet's FEM bag then)
ROUND1 = {("fem", 400, "bullet"): (1.1, 0.8), ("constraint", 0, ""): (32.9, 11.8),
          ("composite", 0, ""): (4.0, 3.6), ("rigid", 0, ""): (36.7, 13.5)}
# the graph rows: (controller, FEM nodes, solver, target, scenario); the controller is a
# registered law or a study's controller label (VARIANTS); --full adds the 1500-node ones.
# BUMP: the demo's carry (strap grasp, a 5 N bump on the bag from the seed) for the pair laws
# beside PD on the same flight
BUMP = "node2_to_jem_fem_bag_bump"
GRAPH = [("pd", 400, "fast", "3x (goal 10x)", "node2_to_jem_bag"),
         ("pd", 400, "bullet", "reference", "node2_to_jem_bag"),
         ("mpc", 400, "fast", "1x", "node2_to_jem_bag"),
         ("pd", 400, "fast", "reference", BUMP), ("pair_gov", 400, "fast", "1x", BUMP),
         ("gov_clear", 400, "fast", "1x", BUMP), ("wmpc", 400, "fast", "1x", BUMP)]
# controller labels of a row that are a law with parameters: label -> the study defining it
# (its `controllers: {label: {controller, params}}`), flown with controller_params:=
VARIANTS = {"gov_clear": "studies/lever_clearance.yaml"}
GRAPH_FULL = [("pd", 1500, "fast", "1x", "node2_to_jem_bag"),
              ("pd", 1500, "bullet", "reference", "node2_to_jem_bag")]


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


def drag_rtf(sim, seconds: float) -> tuple[float, float]:
    """(wall, CPU) real-time factor of `seconds` of the library loop while a PD law drags the
    robot (and its bag) along a line: command, 62.5 Hz steps, bag state, clearance, contacts."""
    start, q0 = sim.robot_state()[:2]
    sim.clearance()                                 # one-time loads outside the timing
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
    return sim.time / (time.perf_counter() - t0), sim.time / (time.process_time() - c0)


def library_rtf(model: str, res: int, seconds: float, fem_solver: str | None = None
                ) -> tuple[float, float, int]:
    """(wall, CPU) real-time factor of the library loop and the FEM node count."""
    sim = Simulation("node2_to_jem_bag", bag_model=model, bag_resolution=res or None,
                     fem_solver=fem_solver)
    try:
        nodes = len(sim.bag.points()) if model == "fem" else 0
        return (*drag_rtf(sim, seconds), nodes)
    finally:
        sim.close()


def node_rtf(model: str, res: int, seconds: float, mode: str = "lockstep",
             fem_solver: str = "", record: bool = False) -> tuple[float, float]:
    """sim_node with this process closing the loop over the ROS 2 wire: in lockstep (the sim
    waits for each tick's command: the round trip counts) or fast (no waiting: the sim's own
    throughput with every topic published; commands then arrive a few ticks late).

    record: a bag recorder (`astrobee bag record -a`) subscribed to every topic as in a launch
    (the sim starts paused and runs once the recorder has subscribed: every topic then has a
    subscriber and costs its whole send)."""
    import subprocess
    import tempfile
    import roszen
    from roszen import testing
    with testing.router() as port, tempfile.TemporaryDirectory(prefix="sim_rtf_rec_") as tmp:
        env = testing.zenoh_env(port)
        args = ["-m", "astrobee_sim.sim_node", "--ros-args", "-p", "scenario:=node2_to_jem_bag",
                "-p", f"bag_model:={model}", "-p", f"clock_mode:={mode}",
                "-p", f"max_sim_time:={seconds + 1.0}"]
        if res:
            args += ["-p", f"bag_resolution:={res}"]
        if fem_solver:
            args += ["-p", f"fem_solver:={fem_solver}"]
        rec = None
        if record:
            args += ["-p", "start_paused:=true"]
            rec = testing.spawn(testing.python_cmd("-m", "astrobee_bringup.cli", "bag", "record", "-a",
                                                   "-o", f"{tmp}/bag"), env,
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
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
            if record and not _start_recorded(node, proc):
                return float("nan"), float("nan")
            end = time.monotonic() + 20 + 5 * seconds
            while marks.get("t1", 0.0) < seconds + 0.5 and time.monotonic() < end and proc.poll() is None:
                node.spin_once(timeout_sec=0.05)
            if mode == "fast":
                # the sim's own figures (it logs them at max_sim_time): here a controller slower
                # than the sim receives its states late and in bursts, so their arrival times
                # do not time the sim
                while proc.poll() is None and time.monotonic() < end:
                    node.spin_once(timeout_sec=0.05)
                own = _own_rate(proc)
                if own is not None:
                    return own
            if "t0" not in marks or marks["t1"] <= marks["t0"]:
                return float("nan"), float("nan")
            dt = marks["t1"] - marks["t0"]
            return dt / (marks["w1"] - marks["w0"]), dt / max(marks["c1"] - marks["c0"], 1e-3)
        finally:
            node.destroy_node()
            ctx.shutdown()
            testing.stop(proc)
            if rec is not None:
                testing.stop(rec)


def _own_rate(proc) -> tuple[float, float] | None:
    """(wall, CPU) real-time factor from sim_node's max_sim_time log line, None if absent."""
    import re
    if proc.poll() is None:
        return None
    try:
        err = proc.stderr.read()
    except (OSError, ValueError):
        return None
    m = re.search(r"max_sim_time .* reached: .*\(([0-9.]+)x real time\), .*\(([0-9.]+)x per CPU s\)", err)
    return (float(m.group(1)), float(m.group(2))) if m else None


RECORDED = ("/clock", "/loc/truth/pose", "/loc/truth/twist", "/gnc/ekf", "/tf", "/sim/bag/state",
            "/sim/contacts")


def _start_recorded(node, proc, timeout: float = 60.0) -> bool:
    """Wait for the recorder's subscriptions to the per-tick topics, then reset and resume the
    paused sim (False if that did not happen in time)."""
    from astrobee import msgconv as mc
    import roszen
    end = time.monotonic() + timeout
    while any(node.count_subscribers(t) < (2 if t == "/gnc/ekf" else 1) for t in RECORDED):
        if time.monotonic() > end or proc.poll() is not None:
            return False
        node.spin_once(timeout_sec=0.05)
    for srv, name, fields in (("astrobee_msgs/srv/Reset", mc.SIM_RESET, {}),
                              ("astrobee_msgs/srv/SimControl", mc.SIM_CONTROL,
                               {"command": mc.SimControl.RESUME})):
        cli = node.create_client(srv, name)
        if not cli.wait_for_service(timeout_sec=max(0.1, end - time.monotonic())):
            return False
        req = roszen.request_class(srv)()
        for k, v in fields.items():
            setattr(req, k, v)
        fut = cli.call_async(req)
        while not fut.done() and time.monotonic() < end:
            node.spin_once(timeout_sec=0.02)
        if not fut.done() or not fut.result().success:
            return False
    return True


def controller_of(label: str) -> tuple[str, dict]:
    """(registered law, its parameters over config/controllers.yaml) of a row's controller
    label: a law itself, or a study's controller (VARIANTS)."""
    if label not in VARIANTS:
        return label, {}
    from astrobee.config import load_yaml, project_root
    spec = load_yaml(project_root() / VARIANTS[label])["controllers"][label]
    return spec["controller"], dict(spec.get("params") or {})


def graph_rtf(controller: str, res: int, solver: str, scenario: str = "node2_to_jem_bag",
              timeout: float = 900.0, params: dict | None = None) -> tuple[float, str]:
    """The whole cargo_transport graph (lockstep, no recorder) flying `scenario` (Node 2 ->
    JEM) with the FEM bag: (the mission's real-time factor over the flight, its verdict).
    `params`: the law's parameters over config/controllers.yaml (controller_params:=)."""
    import json
    import subprocess
    import sys
    import tempfile
    import yaml
    from roszen import testing
    with tempfile.TemporaryDirectory(prefix="sim_rtf_graph_") as run:
        cmd = [sys.executable, "-m", "astrobee_bringup.cli", "launch", "cargo_transport",
               "--port", str(testing.free_port()), "--run-dir", run,
               f"scenario:={scenario}", "bag_model:=fem", f"bag_resolution:={res}",
               f"fem_solver:={solver}", f"controller:={controller}", "record:=false", "video:=false"]
        if params:
            given = f"{run}/controller_params.yaml"
            with open(given, "w") as f:
                yaml.safe_dump({controller: params}, f)
            cmd.append(f"controller_params:={given}")
        try:
            subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=timeout)
            leg = json.load(open(f"{run}/summary.json"))["legs"][0]
        except (subprocess.TimeoutExpired, OSError, ValueError, KeyError, IndexError) as exc:
            return float("nan"), f"no result ({type(exc).__name__})"
        return float(leg.get("real_time_factor") or float("nan")), str(leg.get("reason", ""))


def batched_rtf(res: int, k: int, seconds: float) -> tuple[float, int]:
    """Bag-seconds per wall second of K copies of robot + fast FEM bag stepped together."""
    from astrobee_sim.bags.fem_rollout import FemRollout
    sim = Simulation("node2_to_jem_bag", bag_model="fem", bag_resolution=res, fem_solver="fast")
    try:
        ro = FemRollout.from_bag(sim.bag, sim.robots[""], k, sim.dt)
        rng = np.random.default_rng(0)
        wr = np.c_[rng.uniform(-0.5, 0.5, (k, 3)), rng.uniform(-0.05, 0.05, (k, 3))]
        ro.step(wr, 1)                                   # factor outside the timing
        steps = max(1, int(round(seconds / sim.dt)))
        t0 = time.perf_counter()
        ro.step(wr, steps)
        return k * steps * sim.dt / (time.perf_counter() - t0), sim.bag.num_nodes
    finally:
        sim.close()


# the reduced models through sim_node in fast clock mode with a controller in the loop,
# before the per-tick overhead cut (README: wall x real time, the ranges of several runs)
NODE_FAST_BEFORE = {"rigid": "24-40x", "constraint": "21-30x"}


def node_fast_table(runs: int, seconds: float) -> None:
    """The reduced models through sim_node, fast clock, this process as the PD controller, with
    and without a bag recorder: each run's wall and per-CPU-second real-time factor, the load."""
    import os
    print(f"\nsim_node, fast clock, PD controller over the wire, {seconds:g} sim s a run "
          f"(target 50x; before the overhead cut: rigid {NODE_FAST_BEFORE['rigid']}, "
          f"constraint {NODE_FAST_BEFORE['constraint']} wall)")
    print(f"{'model':<11}{'recorder':>9}{'wall':>8}{'cpu':>8}{'load':>7}")
    for model in ("rigid", "constraint"):
        for record in (False, True):
            walls, cpus = [], []
            for _ in range(runs):
                load = os.getloadavg()[0]
                w, c = node_rtf(model, 0, seconds, "fast", record=record)
                walls.append(w)
                cpus.append(c)
                print(f"{model:<11}{'yes' if record else 'no':>9}{w:>7.1f}x{c:>7.1f}x{load:>7.1f}",
                      flush=True)
            print(f"{model:<11}{'yes' if record else 'no':>9}{np.nanmedian(walls):>7.1f}x"
                  f"{np.nanmedian(cpus):>7.1f}x  median of {runs}; target 50x", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", default=True)
    ap.add_argument("--full", action="store_true")
    ap.add_argument("--no-node", action="store_true", help="skip the sim_node (process) columns")
    ap.add_argument("--no-graph", action="store_true", help="skip the whole-graph rows")
    ap.add_argument("--graph-only", action="store_true", help="only the whole-graph rows")
    ap.add_argument("--node-fast", type=int, default=0, metavar="RUNS",
                    help="only the reduced models through sim_node in fast clock mode, RUNS runs "
                         "each with and without a recorder")
    a = ap.parse_args()
    if a.node_fast:
        node_fast_table(a.node_fast, 30.0)
        return
    secs = {("fem", 400): 3.0, ("fem", 1500): 1.5}
    scale = 5.0 if a.full else 1.0
    rows = []
    for model, res, solver in ([] if a.graph_only else CASES):
        s = secs.get((model, res), 10.0) * scale
        if solver == "bullet" and res > 1000:
            s /= 3.0                                    # 0.3x real time: keep it short
        lib_wall, lib_cpu, nodes = library_rtf(model, res, s, fem_solver=solver or None)
        nd_wall, nd_cpu = (float("nan"),) * 2 if a.no_node else node_rtf(model, res, s, fem_solver=solver)
        fast_wall, fast_cpu = ((float("nan"),) * 2 if a.no_node
                               else node_rtf(model, res, s, "fast", fem_solver=solver))
        rows.append((model, nodes, solver, s, lib_wall, lib_cpu, nd_wall, nd_cpu, fast_wall, fast_cpu))
    if rows:
        print("\nsim real-time factor while a PD law drags the bag (350 Hz physics, 62.5 Hz ticks)")
        print("wall = elapsed time on this (shared, 2-core) machine; cpu = per CPU-second of the sim "
              "process (the 'one core' figure); sim_node = lockstep with this process as the controller "
              "over the wire (includes the round trip per tick); fast = sim_node in fast clock mode "
              "(no waiting), same controller")
        print(f"{'model':<11}{'nodes':>6}{'solver':>7}{'sim s':>6}{'Simulation wall':>16}{'cpu':>7}"
              f"{'lockstep wall':>14}{'cpu':>7}{'fast wall':>10}{'cpu':>7}{'target':>8}"
              f"{'round 1 (lib/lockstep)':>24}  reference (pyastrobee)")
        for (model, nodes, solver, s, lw, lc, nw, nc, fw, fc), case in zip(rows, CASES):
            ref = "0.6x at 379 nodes" if model == "fem" else "-"
            r1 = ROUND1.get(case, (float("nan"),) * 2)
            target = TARGET_FEM_1500 if model == "fem" and nodes > 1000 else TARGET[model]
            target_s = f"{target:.0f}x" if solver != "bullet" else "ref"
            print(f"{model:<11}{nodes or '-':>6}{solver or '-':>7}{s:>6.1f}{lw:>15.1f}x{lc:>6.1f}x"
                  f"{nw:>13.1f}x{nc:>6.1f}x{fw:>9.1f}x{fc:>6.1f}x{target_s:>8}"
                  f"{r1[0]:>16.1f}x /{r1[1]:>5.1f}x  {ref}")
    if a.no_graph:
        return
    import os
    graph = []
    for c, r, sv, tg, sc in GRAPH + (GRAPH_FULL if a.full else []):
        law, params = controller_of(c)
        load = os.getloadavg()[0]                   # at the row's start (the machine is shared)
        graph.append((c, r, sv, tg, sc, *graph_rtf(law, r, sv, sc, params=params), load))
    print("\nthe whole graph (astrobee launch cargo_transport, lockstep, no recorder) flying "
          "Node 2 -> JEM (44 s) with the FEM bag: the mission's real-time factor; "
          f"{BUMP}: the strap grasp and a 5 N bump on the bag (the demo's carry); "
          + "; ".join(f"{k}: {controller_of(k)[0]} with {controller_of(k)[1]}" for k in VARIANTS))
    print(f"{'controller':<11}{'nodes':>6}{'solver':>8}{'real time':>11}  {'target':<16}"
          f"{'scenario':<27}{'load':>5}  verdict")
    for c, r, sv, tg, sc, rtf, why, load in graph:
        print(f"{c:<11}{r:>6}{sv:>8}{rtf:>10.1f}x  {tg:<16}{sc:<27}{load:>5.1f}  {why}")
    if a.graph_only:
        return
    k64, n64 = batched_rtf(400, 64, 0.15 * scale)
    print(f"\nbatched fast FEM bag, K=64 copies + robot, {n64} nodes: {k64:.1f} bag-s per wall s "
          f"(rollouts; Bullet: one process per copy)")


if __name__ == "__main__":
    main()
