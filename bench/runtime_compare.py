"""The same nodes on both runtimes side by side: roszen (rmw_zenoh's wire, router) and real rclpy
(rmw_fastrtps_cpp, UDP, discovery on this machine), through roszen.runtime (ASTROBEE_RUNTIME).

Rows: roszen, rclpy with the SingleThreadedExecutor (the default) and with the EventsExecutor
(ASTROBEE_RCLPY_EXECUTOR=events). Columns: the hop graph in lockstep (sim_node rigid backend + planner + PD + mission,
the mission's real-time factor over the leg: every tick a state -> command round trip),
sim_node alone in fast clock (20 sim s, its own real-time factor: publishing every topic), the
one-way latency of a PoseStamped to an echo process and back (half the round trip, median and
p90 of 300), and the CPU cost of publishing a PoseStamped (a roszen object, then its CDR bytes).
Reference (FACTS.md, a scratch venv on this machine): rclpy latency 1.3-1.8x roszen's, publish
CPU 3-5x as objects (rosidl objects there; roszen objects crossing as CDR here).

    .venv-rclpy/bin/python bench/runtime_compare.py      # needs make install-rclpy
"""
from __future__ import annotations

import json
import os
import random
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
HOP = {"description": "bench hop", "flight_mode": "nominal",
       "robots": [{"name": "", "position": [10.95, 0.5, 4.84],
                   "orientation": [0.0, 0.0, -0.7071067811865476, 0.7071067811865476]}],
       "bag": None, "goal": {"position": [10.95, -1.5, 4.84],
                             "orientation": [0.0, 0.0, -0.7071067811865476, 0.7071067811865476]}}
PINGS = 300
PUBLISHES = 3000


def child(role: str) -> int:
    """echo: PoseStamped /bench/ping -> /bench/pong as raw bytes; ping: latency and publish cost."""
    import numpy as np
    from roszen import runtime as rt
    node = rt.Node(f"bench_{role}", argv=[sys.argv[0]])
    if role == "echo":
        pub = node.create_publisher("geometry_msgs/msg/PoseStamped", "/bench/pong", 10)
        node.create_subscription("geometry_msgs/msg/PoseStamped", "/bench/ping", pub.publish, 10,
                                 raw=True)
        print("ready", flush=True)
        node.spin()
        return 0
    got: list = []
    pub = node.create_publisher("geometry_msgs/msg/PoseStamped", "/bench/ping", 10)
    node.create_subscription("geometry_msgs/msg/PoseStamped", "/bench/pong",
                             lambda m: got.append(time.monotonic_ns() - m.header.stamp.sec * 10**9
                                                  - m.header.stamp.nanosec), 10)
    msg = rt.message_class("geometry_msgs/msg/PoseStamped")()
    msg.header.frame_id = "world"
    end = time.monotonic() + 30
    while node.count_subscribers("/bench/ping") == 0 or node.count_publishers("/bench/pong") == 0:
        node.spin_once(timeout_sec=0.05)
        if time.monotonic() > end:
            raise SystemExit("no echo within 30 s")
    time.sleep(0.5)
    for i in range(PINGS + 20):
        n = len(got)
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(time.monotonic_ns(), 10**9)
        pub.publish(msg)
        deadline = time.monotonic() + 1.0
        while len(got) == n and time.monotonic() < deadline:
            node.spin_once(timeout_sec=0.01)
    rtt = np.array(got[20:]) * 1e-3          # us; the first 20 warm up
    silent = node.create_publisher("geometry_msgs/msg/PoseStamped", "/bench/silent", 10)
    cpu = []
    for payload in (msg, bytes(rt.codec.msg_support("geometry_msgs/msg/PoseStamped").serialize(msg))):
        t0 = time.process_time()
        for _ in range(PUBLISHES):
            silent.publish(payload)
        cpu.append((time.process_time() - t0) / PUBLISHES * 1e6)
    print(json.dumps({"latency_median_us": float(np.median(rtt) / 2) if len(rtt) else None,
                      "latency_p90_us": float(np.percentile(rtt, 90) / 2) if len(rtt) else None,
                      "received": len(rtt), "publish_object_us": cpu[0],
                      "publish_bytes_us": cpu[1]}), flush=True)
    node.destroy_node()
    return 0


def env_for(runtime: str, cfg: Path, port: int | None) -> dict:
    """runtime: roszen, rclpy (SingleThreadedExecutor) or rclpy-events (EventsExecutor)."""
    env = dict(os.environ, ASTROBEE_RUNTIME=runtime.split("-")[0], ASTROBEE_CONFIG_DIR=str(cfg),
               PYTHONUNBUFFERED="1", ROS_DOMAIN_ID=str(random.randint(1, 100)),
               ASTROBEE_RCLPY_EXECUTOR="events" if runtime.endswith("events") else "")
    if runtime.startswith("rclpy"):
        env.update(RMW_IMPLEMENTATION="rmw_fastrtps_cpp", FASTDDS_BUILTIN_TRANSPORTS="UDPv4",
                   ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    else:
        from roszen.testing import zenoh_env
        env.update(zenoh_env(port, domain_id=int(env["ROS_DOMAIN_ID"])))
    return env


def measure(runtime: str, cfg: Path, port: int | None) -> dict:
    """The four figures of one runtime (each graph started and stopped here)."""
    from roszen.testing import spawn, stop
    py, env, out = sys.executable, env_for(runtime, cfg, port), {}
    fast = subprocess.run([py, "-m", "astrobee_sim.sim_node", "--ros-args", "-p", "backend:=rigid",
                           "-p", "scenario:=bench_hop", "-p", "clock_mode:=fast",
                           "-p", "max_sim_time:=20.0"], env=env, capture_output=True, text=True,
                          timeout=300)
    m = re.search(r"\(([\d.]+)x real time\)", fast.stdout + fast.stderr)
    out["fast_rtf"] = float(m.group(1)) if m else None
    procs = []
    try:
        for argv in ([py, "-m", "astrobee_sim.sim_node", "--ros-args", "-p", "backend:=rigid",
                      "-p", "scenario:=bench_hop", "-p", "clock_mode:=lockstep"],
                     [py, "-m", "astrobee_planning.planner_node"],
                     [py, "-m", "astrobee_control.pd_controller_node", "--ros-args",
                      "-p", "use_sim_time:=true"]):
            procs.append(spawn(argv, env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        with tempfile.TemporaryDirectory() as run:
            mission = subprocess.run([py, "-m", "astrobee_bringup.mission", "--scenario",
                                      "bench_hop", "--run-dir", run, "--timeout", "200"],
                                     env=env, capture_output=True, text=True, timeout=300)
        m = re.search(r"SUCCESS.*\(([\d.]+) s sim, ([\d.]+)x real time\)", mission.stdout)
        out["lockstep_rtf"] = float(m.group(2)) if m else None
    finally:
        for p in reversed(procs):
            stop(p, timeout=5.0)
    echo = spawn([py, __file__, "--child", "echo"], env, stdout=subprocess.PIPE,
                 stderr=subprocess.DEVNULL)
    try:
        echo.stdout.readline()
        ping = subprocess.run([py, __file__, "--child", "ping"], env=env, capture_output=True,
                              text=True, timeout=180)
        out.update(json.loads(ping.stdout.strip().splitlines()[-1]))
    finally:
        stop(echo, timeout=5.0)
    return out


def main() -> int:
    if "--child" in sys.argv:
        return child(sys.argv[sys.argv.index("--child") + 1])
    try:
        import rclpy  # noqa: F401
        import astrobee_msgs.msg  # noqa: F401
    except ImportError as exc:
        raise SystemExit(f"runtime_compare: real rclpy is not here ({exc}): make install-rclpy, "
                         f"then .venv-rclpy/bin/python bench/runtime_compare.py") from None
    from roszen.testing import router
    with tempfile.TemporaryDirectory() as d:
        cfg = Path(d) / "config"
        shutil.copytree(ROOT / "config", cfg)
        (cfg / "scenarios" / "bench_hop.yaml").write_text(yaml.safe_dump(HOP))
        res = {}
        with router() as port:
            res["roszen"] = measure("roszen", cfg, port)
        res["rclpy"] = measure("rclpy", cfg, None)
        res["rclpy-events"] = measure("rclpy-events", cfg, None)
    print(f"load average {os.getloadavg()[0]:.1f}; {PINGS} pings, {PUBLISHES} publishes")
    print("| runtime | lockstep hop RTF | sim_node fast RTF | latency median / p90 (us) "
          "| publish object / bytes (CPU us) |")
    print("|---|---|---|---|---|")
    for name, r in res.items():
        f = lambda v, fmt: "-" if v is None else format(v, fmt)  # noqa: E731
        what = {"roszen": "rmw_zenoh wire", "rclpy": "rmw_fastrtps_cpp, SingleThreadedExecutor",
                "rclpy-events": "rmw_fastrtps_cpp, EventsExecutor"}[name]
        print(f"| {name} ({what}) "
              f"| {f(r.get('lockstep_rtf'), '.1f')}x | {f(r.get('fast_rtf'), '.1f')}x "
              f"| {f(r.get('latency_median_us'), '.0f')} / {f(r.get('latency_p90_us'), '.0f')} "
              f"| {f(r.get('publish_object_us'), '.1f')} / {f(r.get('publish_bytes_us'), '.1f')} |")
    print("reference (FACTS.md): rclpy latency 1.3-1.8x roszen's; publish CPU 3-5x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
