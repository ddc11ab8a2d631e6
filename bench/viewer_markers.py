"""Cost of the cargo bag's viewer Marker (TRIANGLE_LIST) that sim_node publishes at the mesh rate.

Per mesh sample: the Marker's CDR bytes from the node positions (markers.BagSurface.payload,
what sim_node publishes), for the rigid bag and the FEM bag at 400 and 1500 nodes; and that cost spread
over the sim's 62.5 Hz ticks at the default mesh_rate of 10 Hz, beside the sim's own per-tick
cost (the FEM bag at ~4x real time per CPU-second: 16 ms / 4 = 4 ms per tick). Target: under 5%
of the sim's tick.

    .venv/bin/python bench/viewer_markers.py
"""
from __future__ import annotations

import time

import numpy as np

TICK_MS = {"rigid": 16.0 / 40.0, "fem 400": 16.0 / 4.0, "fem 1500": 16.0 / 1.0}  # sim per tick


def main() -> None:
    import roszen
    from roszen import codec

    from astrobee_sim import markers
    from astrobee_sim.bags.mesh import bag_mesh

    Marker = roszen.message_class("visualization_msgs/msg/Marker")
    Point = roszen.message_class("geometry_msgs/msg/Point")
    Header = roszen.message_class("std_msgs/msg/Header")
    serialize = codec.msg_support("visualization_msgs/msg/Marker").serialize

    class Bag:
        def __init__(self, model, mesh=None):
            self.model, self.mesh = model, mesh

    cases = [("rigid", Bag("rigid"), np.random.default_rng(0).random((8, 3)))]
    for res in (400, 1500):
        mesh = bag_mesh(np.array([0.5, 0.35, 0.25]), [np.array([1.0, 0.0, 0.0])], res)
        cases.append((f"fem {res}", Bag("fem", mesh), mesh.nodes))
    print("cargo bag Marker (TRIANGLE_LIST) per mesh sample, and per 62.5 Hz sim tick at "
          "mesh_rate 10 Hz")
    print(f"{'bag':<10}{'nodes':>6}{'triangles':>10}{'ms/sample':>11}{'ms/tick':>9}"
          f"{'sim ms/tick':>13}{'share':>8}{'target':>8}")
    for name, bag, pts in cases:
        surface = markers.BagSurface(Marker, Point)
        header = Header()
        surface.payload(bag, pts, header, serialize)
        moved = pts + 0.001
        n = 100
        t0 = time.perf_counter()
        for _ in range(n):
            surface.payload(bag, moved, header, serialize)      # what sim_node publishes
        ms = (time.perf_counter() - t0) / n * 1e3
        per_tick = ms / 6.25
        share = per_tick / TICK_MS[name]
        print(f"{name:<10}{len(pts):>6}{len(surface.faces(bag, pts)):>10}{ms:>11.3f}"
              f"{per_tick:>9.3f}{TICK_MS[name]:>13.2f}{share:>7.1%}{'< 5%':>8}")


if __name__ == "__main__":
    main()
