"""Cross-process latency/throughput of roszen (rmw_zenoh wire) beside bare zenoh put/subscribe.

Spawns a router and a receiver process; this process publishes/calls. One-way latency uses
CLOCK_MONOTONIC stamps (system-wide on Linux) carried in the message. Prints one table.
Usage: .venv/bin/python bench/runtime_latency.py [--quick | --full]
"""
from __future__ import annotations

import argparse
import json
import os
import struct
import subprocess
import sys
import threading
import time

import numpy as np

import roszen
from roszen.testing import python_cmd, read_until, router, spawn, stop, zenoh_env

BLOB = 12 * 1024
# throughput runs lossless on both sides: KEEP_ALL (zenoh congestion control BLOCK) / bare BLOCK
TPUT_QOS = roszen.QoSProfile(depth=1000, history=roszen.History.KEEP_ALL)
_TS = struct.Struct("<q")


# ------------------------------------------------------------------------------ receiver process
def receiver(spin: str = "spin") -> int:
    import zenoh
    lat: dict = {k: [] for k in ("ros_pose", "ros_blob", "ros_tput", "z_pose", "z_blob", "z_tput")}
    node = roszen.Node("bench_rx")

    def on_pose(m) -> None:
        lat["ros_pose"].append(time.monotonic_ns() - (m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec))

    def on_blob(m) -> None:
        lat["ros_blob"].append(time.monotonic_ns() - _TS.unpack_from(m.data.tobytes(), 0)[0])

    def on_tput(m) -> None:
        lat["ros_tput"].append(time.monotonic_ns())

    node.create_subscription("geometry_msgs/msg/PoseStamped", "/bench/pose", on_pose, 1000)
    node.create_subscription("std_msgs/msg/UInt8MultiArray", "/bench/blob", on_blob, 1000)
    node.create_subscription("geometry_msgs/msg/PoseStamped", "/bench/tput", on_tput, TPUT_QOS)
    Resp = roszen.response_class("example_interfaces/srv/AddTwoInts")

    def add(req):
        r = Resp()
        r.sum = req.a + req.b
        return r
    node.create_service("example_interfaces/srv/AddTwoInts", "/bench/add", add)

    zs = zenoh.open(roszen.zconfig.session_config())
    cb = zenoh.handlers.Callback

    def z_lat(key):
        def f(s) -> None:
            lat[key].append(time.monotonic_ns() - _TS.unpack_from(s.payload.to_bytes(), 0)[0])
        return f
    subs = [zs.declare_subscriber("bench/z/pose", cb(z_lat("z_pose"), indirect=False)),
            zs.declare_subscriber("bench/z/blob", cb(z_lat("z_blob"), indirect=False)),
            zs.declare_subscriber("bench/z/tput", cb(lambda s: lat["z_tput"].append(time.monotonic_ns()),
                                                     indirect=False))]
    qbl = zs.declare_queryable("bench/z/srv", cb(lambda q: (q.reply(q.key_expr, q.payload.to_bytes()), q.drop()),
                                                 indirect=False), complete=True)

    def commands() -> None:
        for line in sys.stdin:
            key = line.strip()
            if key == "QUIT":
                break
            vals = lat.get(key, [])
            print("RESULT " + json.dumps({"key": key, "values": list(vals)}), flush=True)
            vals.clear()
        node.destroy_node()
        os._exit(0)
    threading.Thread(target=commands, daemon=True).start()
    print("READY", flush=True)
    if spin == "spin":
        node.spin()
    while True:
        node.spin_once(0.5)


# ------------------------------------------------------------------------------ sender side
def result(rx, key: str) -> list:
    rx.stdin.write(key + "\n")
    rx.stdin.flush()
    line = read_until(rx, "RESULT", timeout=30)[-1]
    return json.loads(line[len("RESULT "):])["values"]


def stats_us(ns: list) -> tuple:
    if not ns:
        return (float("nan"), float("nan"), 0)
    a = np.asarray(ns, dtype=float) / 1e3
    return (float(np.median(a)), float(np.percentile(a, 99)), len(a))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", default=True)
    ap.add_argument("--full", action="store_true")
    ap.add_argument("--role", default="sender")
    ap.add_argument("--only", default="", help="comma list of sections: pose,blob,tput,srv (default all)")
    ap.add_argument("--rounds", type=int, default=3, help="throughput bursts per side (best is shown)")
    ap.add_argument("--spin", default="spin", choices=("spin", "spin_once"),
                    help="receiver loop: node.spin() (default) or a spin_once(0.5) loop")
    args = ap.parse_args(argv)
    if args.role == "receiver":
        return receiver(args.spin)
    only = set(filter(None, args.only.split(",")))

    def want(section: str) -> bool:
        return not only or section in only
    n_lat = 2000 if args.full else 400
    n_tput = 50000 if args.full else 10000
    n_srv = 1000 if args.full else 200
    period = 0.002

    import zenoh
    with router() as port:
        env = zenoh_env(port, domain_id=77)
        os.environ.update({k: env[k] for k in ("ZENOH_CONFIG_OVERRIDE", "ROS_DOMAIN_ID")})
        rx = spawn(python_cmd(os.path.abspath(__file__), "--role", "receiver", "--spin", args.spin), env,
                   stdin=subprocess.PIPE, stderr=subprocess.DEVNULL)
        try:
            read_until(rx, "READY", timeout=30)
            node = roszen.Node("bench_tx")
            ctx = node.context
            zs = zenoh.open(roszen.zconfig.session_config())
            Pose = roszen.message_class("geometry_msgs/msg/PoseStamped")
            Blob = roszen.message_class("std_msgs/msg/UInt8MultiArray")
            p_pose = node.create_publisher("geometry_msgs/msg/PoseStamped", "/bench/pose", 1000)
            p_blob = node.create_publisher("std_msgs/msg/UInt8MultiArray", "/bench/blob", 1000)
            p_tput = node.create_publisher("geometry_msgs/msg/PoseStamped", "/bench/tput", TPUT_QOS)
            zp = {k: zs.declare_publisher(f"bench/z/{k}", congestion_control=zenoh.CongestionControl.DROP)
                  for k in ("pose", "blob")}
            zp["tput"] = zs.declare_publisher("bench/z/tput", congestion_control=zenoh.CongestionControl.BLOCK)
            for p in (p_pose, p_blob, p_tput):
                ctx.graph.wait_for(lambda p=p: p.get_subscription_count() > 0, 10)
            time.sleep(0.5)
            rows, notes = [], []

            def paced(send, n) -> None:
                for _ in range(50):  # warm-up, discarded below
                    send()
                    time.sleep(period)
                for _ in range(n):
                    send()
                    time.sleep(period)
                time.sleep(0.3)

            # --- PoseStamped latency
            pose = Pose()
            pose.header.frame_id = "world"
            pose_bytes = len(p_pose._sup.serialize(pose))
            if want("pose"):

                def send_pose() -> None:
                    t = time.monotonic_ns()
                    pose.header.stamp.sec, pose.header.stamp.nanosec = divmod(t, 1_000_000_000)
                    p_pose.publish(pose)
                zpay = bytearray(pose_bytes)

                def send_zpose() -> None:
                    _TS.pack_into(zpay, 0, time.monotonic_ns())
                    zp["pose"].put(bytes(zpay))
                paced(send_pose, n_lat)
                ros = stats_us(result(rx, "ros_pose")[50:])
                paced(send_zpose, n_lat)
                bare = stats_us(result(rx, "z_pose")[50:])
                rows.append(("PoseStamped latency median [us]", ros[0], bare[0]))
                rows.append(("PoseStamped latency p99 [us]", ros[1], bare[1]))

            # --- 12 KB latency
            if want("blob"):
                blob = Blob()
                buf = np.zeros(BLOB, dtype=np.uint8)

                def send_blob() -> None:
                    buf[:8] = np.frombuffer(_TS.pack(time.monotonic_ns()), dtype=np.uint8)
                    blob.data = buf
                    p_blob.publish(blob)
                zb = bytearray(BLOB)

                def send_zblob() -> None:
                    _TS.pack_into(zb, 0, time.monotonic_ns())
                    zp["blob"].put(bytes(zb))
                paced(send_blob, n_lat)
                ros = stats_us(result(rx, "ros_blob")[50:])
                paced(send_zblob, n_lat)
                bare = stats_us(result(rx, "z_blob")[50:])
                rows.append(("12 KB latency median [us]", ros[0], bare[0]))
                rows.append(("12 KB latency p99 [us]", ros[1], bare[1]))

            # --- throughput, PoseStamped back to back
            if want("tput"):
                def rate(times: list) -> float:
                    return (len(times) - 1) / ((times[-1] - times[0]) * 1e-9) if len(times) > 1 else 0.0

                def burst(send, key: str) -> tuple:
                    t0 = time.perf_counter()
                    for _ in range(n_tput):
                        send()
                    sent = n_tput / (time.perf_counter() - t0)
                    time.sleep(1.0)
                    got = result(rx, key)
                    return rate(got), sent, 100.0 * len(got) / n_tput
                zt_payload = bytes(pose_bytes)
                put = zp["tput"].put
                ros_runs, z_runs = [], []
                for _ in range(args.rounds):  # best of N: the machine is shared, single runs vary
                    ros_runs.append(burst(lambda: p_tput.publish(pose), "ros_tput"))
                    z_runs.append(burst(lambda: put(zt_payload), "z_tput"))
                ros, bare = max(ros_runs), max(z_runs)
                rows.append(("PoseStamped msgs/s (1 pub -> 1 sub)", ros[0], bare[0]))
                rows.append(("  send loop msgs/s", ros[1], bare[1]))
                rows.append(("  received of sent [%]", ros[2], bare[2]))
                notes.append(f"msgs/s: KEEP_ALL (bare: congestion BLOCK), {n_tput} back to back, "
                             f"best of {args.rounds} bursts per side")

            # --- service round trip
            if want("srv"):
                T = "example_interfaces/srv/AddTwoInts"
                cli = node.create_client(T, "/bench/add")
                cli.wait_for_service(10)
                req = roszen.request_class(T)()
                req.a, req.b = 1, 2
                rtt = []
                for i in range(n_srv + 20):
                    t = time.monotonic_ns()
                    cli.call(req, timeout_sec=10)
                    rtt.append(time.monotonic_ns() - t)
                zq = zs.declare_querier("bench/z/srv", target=zenoh.QueryTarget.ALL_COMPLETE,
                                        consolidation=zenoh.ConsolidationMode.NONE, timeout=10)
                zrtt = []
                payload = bytes(24)
                for i in range(n_srv + 20):
                    t = time.monotonic_ns()
                    for _r in zq.get(payload=payload):
                        pass
                    zrtt.append(time.monotonic_ns() - t)
                ros, bare = stats_us(rtt[20:]), stats_us(zrtt[20:])
                rows.append(("service round trip median [us]", ros[0], bare[0]))
                rows.append(("service round trip p99 [us]", ros[1], bare[1]))
            rx.stdin.write("QUIT\n")
            rx.stdin.flush()
            node.destroy_node()
            zs.close()
        finally:
            stop(rx)
            roszen.shutdown()

    from importlib.metadata import version
    print(f"\nroszen (rmw_zenoh wire) vs bare zenoh {version('eclipse-zenoh')}, "
          f"cross-process via a local router, {'full' if args.full else 'quick'} run")
    print(f"{'metric':40s} {'roszen':>12s} {'bare zenoh':>12s} {'ratio':>7s}")
    for name, a, b in rows:
        ratio = a / b if b and not name.startswith("  ") else float("nan")
        if "msgs/s (" in name and a:
            ratio = b / a
        print(f"{name:40s} {a:12.1f} {b:12.1f} {ratio:7.2f}")
    for n in notes:
        print(n)
    print("ratio: roszen cost over bare zenoh (latency: ours/bare; msgs/s: bare/ours); target <= 2, "
          "PoseStamped median < 500 us")
    return 0


if __name__ == "__main__":
    sys.exit(main())
