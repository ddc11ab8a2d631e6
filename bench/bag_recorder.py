"""Bag recorder throughput: messages/s and MB/s recorded without loss.

A router, a publisher process and `astrobee bag record -a` run as separate processes. The
publisher offers the cargo graph's real streams (state at 62.5 Hz, FEM bag mesh, commands),
then stress loads; the table compares what was published with what the bag holds.

    .venv/bin/python bench/bag_recorder.py [--quick | --full]
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ASTROBEE = str(Path(sys.executable).parent / "astrobee")

# name: [(topic, type, rate Hz, mesh nodes or None)]
GRAPH = [("/loc/truth/pose", "geometry_msgs/msg/PoseStamped", 62.5, None),
         ("/loc/truth/twist", "geometry_msgs/msg/TwistStamped", 62.5, None),
         ("/gnc/ekf", "astrobee_msgs/msg/EkfState", 62.5, None),
         ("/gnc/ctl/command", "astrobee_msgs/msg/FamCommand", 62.5, None),
         ("/sim/bag/state", "astrobee_msgs/msg/BagState", 62.5, None)]
SCENARIOS = {
    "graph, mesh 12 KB @ 10 Hz": GRAPH + [("/sim/bag/mesh", "astrobee_msgs/msg/BagMesh", 10.0, 1000)],
    "graph, mesh 24 KB @ 62.5 Hz": GRAPH + [("/sim/bag/mesh", "astrobee_msgs/msg/BagMesh", 62.5, 2000)],
    "stress: 24 KB mesh @ 500 Hz": [("/sim/bag/mesh", "astrobee_msgs/msg/BagMesh", 500.0, 2000)],
    "stress: pose @ 2000 Hz": [("/loc/truth/pose", "geometry_msgs/msg/PoseStamped", 2000.0, None)],
    "stress: pose @ 5000 Hz": [("/loc/truth/pose", "geometry_msgs/msg/PoseStamped", 5000.0, None)],
}


def publisher(spec: str, duration: float) -> int:
    """Child process: publish the streams of `spec` (JSON) for `duration` s, print counts."""
    import numpy as np

    import astrobee  # noqa: F401  (registers astrobee_msgs)
    from roszen import Node, message_class
    streams = json.loads(spec)
    node = Node("bench_publisher", enable_rosout=False, start_parameter_services=False)
    pubs = []
    for topic, type_name, rate, nodes in streams:
        msg = message_class(type_name)()
        if nodes:
            msg.num_nodes = nodes
            msg.positions = np.random.default_rng(0).random(3 * nodes).astype(np.float32)
        pubs.append([node.create_publisher(type_name, topic, 10), msg, 1.0 / rate, 0, topic])
    # wait for the recorder to subscribe to every topic
    end = time.monotonic() + 20
    while time.monotonic() < end and not all(p[0].get_subscription_count() for p in pubs):
        time.sleep(0.05)
    time.sleep(0.5)
    print("publishing", flush=True)
    t0 = time.monotonic()
    nxt = [t0] * len(pubs)
    while True:
        now = time.monotonic()
        if now - t0 >= duration:
            break
        i = min(range(len(pubs)), key=nxt.__getitem__)
        if nxt[i] > now:
            time.sleep(min(nxt[i] - now, 0.002))
            continue
        pub, msg, period, _, _ = pubs[i]
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(time.time_ns(), 1_000_000_000)
        pub.publish(msg)
        pubs[i][3] += 1
        nxt[i] += period
    elapsed = time.monotonic() - t0
    time.sleep(0.5)
    print(json.dumps({"elapsed": elapsed, "counts": {p[4]: p[3] for p in pubs}}), flush=True)
    node.destroy_node()
    return 0


def run_scenario(name: str, streams, duration: float, port: int, tmp: Path) -> dict:
    from roszen.testing import zenoh_env
    env = zenoh_env(port)
    bag = tmp / name.replace(" ", "_").replace(",", "").replace("@", "at").replace(":", "")
    rec = subprocess.Popen([ASTROBEE, "bag", "record", "-a", "-o", str(bag)], env=env,
                           stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                           start_new_session=True)
    pub = subprocess.Popen([sys.executable, __file__, "--publish", json.dumps(streams),
                            "--duration", str(duration)], env=env, stdout=subprocess.PIPE,
                           text=True, start_new_session=True)
    try:
        out = pub.communicate(timeout=duration + 60)[0].splitlines()
        result = json.loads(out[-1])
        time.sleep(0.5)
        rec.send_signal(signal.SIGINT)
        rec.wait(timeout=60)
    finally:
        for p in (pub, rec):
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait()
    from roszen.bag.reader import BagReader
    meta = BagReader(bag).metadata()
    recorded = {t.name: t.count for t in meta.topics}
    sent = sum(result["counts"].values())
    got = sum(recorded.get(t, 0) for t in result["counts"])
    size = sum(len(m.data) for m in BagReader(bag).messages(list(result["counts"])))
    disk = sum(p.stat().st_size for p in bag.glob("*.mcap"))
    return {"name": name, "sent": sent, "got": got, "rate": sent / result["elapsed"],
            "mbps": size / result["elapsed"] / 1e6, "disk": disk / 1e6,
            "lost": sent - got}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--publish", help=argparse.SUPPRESS)
    ap.add_argument("--duration", type=float, default=None)
    g = ap.add_mutually_exclusive_group()
    g.add_argument("--quick", action="store_true", help="4 s per scenario (default)")
    g.add_argument("--full", action="store_true", help="15 s per scenario")
    a = ap.parse_args()
    if a.publish:
        return publisher(a.publish, a.duration)
    duration = a.duration or (15.0 if a.full else 4.0)
    from roszen import testing
    rows = []
    with tempfile.TemporaryDirectory() as tmp, testing.router() as port:
        for name, streams in SCENARIOS.items():
            rows.append(run_scenario(name, streams, duration, port, Path(tmp)))
    print(f"\nbag recorder throughput ({duration:g} s per scenario, `astrobee bag record -a`, "
          "zstd chunks; publisher, recorder, router in separate processes; msgs/s = achieved "
          "publish rate; the payloads repeat, so the bag compresses well)")
    head = f"{'scenario':32} {'msgs/s':>9} {'MB/s':>7} {'sent':>7} {'recorded':>9} {'lost':>5} {'bag MB':>7}"
    print(head)
    print("-" * len(head))
    for r in rows:
        print(f"{r['name']:32} {r['rate']:9.0f} {r['mbps']:7.2f} {r['sent']:7d} {r['got']:9d} "
              f"{r['lost']:5d} {r['disk']:7.2f}")
    print("reference: the graph needs ~375 msgs/s and ~1.6 MB/s (state/commands at 62.5 Hz, "
          "24 KB mesh at 62.5 Hz) with no loss")
    return 0


if __name__ == "__main__":
    sys.exit(main())
