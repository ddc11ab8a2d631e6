"""CDR serialize/deserialize time of roszen.typestore beside rosbags' generated code (reference).

Run: .venv/bin/python bench/types_cdr.py [--full]
"""
from __future__ import annotations

import argparse
import sys
import timeit
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "src")]

from rosbags.typesys import Stores, get_types_from_msg, get_typestore  # noqa: E402

from roszen import typestore as ts  # noqa: E402

ts.register_interface_path(ROOT / "astrobee_msgs")


def per_call_us(fn, seconds: float) -> float:
    n = 1
    while True:
        t = timeit.timeit(fn, number=n)
        if t > seconds / 5:
            break
        n *= 4
    best = min(timeit.repeat(fn, number=n, repeat=5))
    return best / n * 1e6


def samples():
    """One message of each type the sim publishes per tick (plus the big mesh and FamCommand)."""
    M = ts.message_class
    ps = M("geometry_msgs/msg/PoseStamped")()
    ps.header.frame_id = "world"
    ps.pose.position.x = 1.0
    ps.pose.orientation.w = 1.0
    tw = M("geometry_msgs/msg/TwistStamped")()
    tw.header = ps.header
    tw.twist.linear.x = 0.1
    ekf = M("astrobee_msgs/msg/EkfState")()
    ekf.header, ekf.child_frame_id, ekf.pose = ps.header, "bsharp/body", ps.pose
    clock = M("rosgraph_msgs/msg/Clock")()
    clock.clock.sec = 12
    tfs = []
    for child in ("bsharp/body", "queen/body", "bag"):
        t = M("geometry_msgs/msg/TransformStamped")()
        t.header, t.child_frame_id = ps.header, child
        t.transform.rotation.w = 1.0
        tfs.append(t)
    tf = M("tf2_msgs/msg/TFMessage")(transforms=tfs)
    bag = M("astrobee_msgs/msg/BagState")()
    bag.header, bag.model, bag.variant = ps.header, "fem", "duffel"
    bag.attached = np.array([True, False])
    contact = M("astrobee_msgs/msg/Contact")(body_a="bsharp", body_b="bag")
    contacts = M("astrobee_msgs/msg/Contacts")(contacts=[contact, contact], in_contact=True)
    mesh = M("astrobee_msgs/msg/BagMesh")(num_nodes=1000)
    mesh.header.frame_id = "world"
    mesh.positions = np.random.default_rng(0).normal(size=3000).astype(np.float32)
    fam = M("astrobee_msgs/msg/FamCommand")()
    fam.wrench.force.x = 0.1
    return [("rosgraph_msgs/msg/Clock", clock), ("geometry_msgs/msg/PoseStamped", ps),
            ("geometry_msgs/msg/TwistStamped", tw), ("astrobee_msgs/msg/EkfState", ekf),
            ("tf2_msgs/msg/TFMessage", tf), ("astrobee_msgs/msg/BagState", bag),
            ("astrobee_msgs/msg/Contacts", contacts), ("astrobee_msgs/msg/BagMesh", mesh),
            ("astrobee_msgs/msg/FamCommand", fam)]


# messages per sim tick with two robots: clock, tf, bag, contacts + pose, twist, ekf per robot
TICK = {"rosgraph_msgs/msg/Clock": 1, "geometry_msgs/msg/PoseStamped": 2, "geometry_msgs/msg/TwistStamped": 2,
        "astrobee_msgs/msg/EkfState": 2, "tf2_msgs/msg/TFMessage": 1, "astrobee_msgs/msg/BagState": 1,
        "astrobee_msgs/msg/Contacts": 1}


def rosbags_store():
    store = get_typestore(Stores.ROS2_JAZZY)
    types = {}
    for name in ts.list_types():
        if name.startswith("astrobee_msgs/msg/"):
            types.update(get_types_from_msg(ts.definition_text(name), name))
    store.register(types)
    return store


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="short runs (default)")
    ap.add_argument("--full", action="store_true", help="longer runs")
    args = ap.parse_args(argv)
    seconds = 1.0 if args.full else 0.2
    store = rosbags_store()
    print(f"{'message':34s} {'bytes':>6s} {'ser us':>8s} {'deser us':>9s} {'round us':>9s}"
          f" | {'rosbags ser':>11s} {'deser':>7s}")
    tick = [0.0, 0.0]
    for name, msg in samples():
        data = ts.serialize(msg, name)
        ser = per_call_us(lambda: ts.serialize(msg, name), seconds)
        des = per_call_us(lambda: ts.deserialize(data, name), seconds)
        rmsg = store.deserialize_cdr(data, name)
        assert bytes(store.serialize_cdr(rmsg, name, little_endian=True)) == data
        rser = per_call_us(lambda: store.serialize_cdr(rmsg, name, little_endian=True), seconds)
        rdes = per_call_us(lambda: store.deserialize_cdr(data, name), seconds)
        tick[0] += TICK.get(name, 0) * ser
        tick[1] += TICK.get(name, 0) * rser
        print(f"{name:34s} {len(data):6d} {ser:8.2f} {des:9.2f} {ser + des:9.2f}"
              f" | {rser:11.2f} {rdes:7.2f}")
    print(f"{'sim tick: serialize %d msgs' % sum(TICK.values()):34s} {'':6s} {tick[0]:8.2f} {'':9s} {'':9s}"
          f" | {tick[1]:11.2f}")
    print("target: PoseStamped round trip < 20 us; reference: rosbags' generated code (same bytes)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
