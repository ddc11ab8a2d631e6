"""Render benchmark: frames per second of `astrobee bag render`'s renderer at the default frame
size (chase 512x384 + overview 384x384), robot flying Node 2 -> JEM with the cargo bag (rigid
box and a 412-node FEM surface), the planned path and the flown trail; the MP4 encode; and the
rejected alternative (matplotlib mplot3d drawing the same walls) for the record; a --compare
frame (two columns of chase view over overview).

Usage: python bench/render_bench.py [RECORDING]   (with a recorded bag: the whole command on
its first 60 s of flight too, reading the recording included)
Target: >= 10 frames/s (a 46 s leg at the default x4 playback and 10 fps is 116 frames: ~12 s).
"""
from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from astrobee_sim.bags.base import handle_dirs
from astrobee_sim.bags.mesh import bag_mesh
from astrobee_sim.render import (FlightRenderer, Polyline, Scene, Surface, boundary_faces,
                                 box_surface, overview_camera)

Q = np.array([0.0, 0.0, -0.7071067811865476, 0.7071067811865476])
START, GOAL = np.array([10.95, 0.0, 4.84]), np.array([10.93, -6.0, 4.85])
CORNERS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)
N = 30


def scenes(fem: bool) -> list[Scene]:
    mesh = bag_mesh([0.5, 0.42, 0.25], handle_dirs("front"), 400)
    faces = boundary_faces(mesh.tets) if fem else box_surface(CORNERS)[1]
    local = mesh.nodes - mesh.nodes.mean(axis=0) if fem else CORNERS * [0.25, 0.21, 0.125]
    path = np.linspace(START, GOAL, 20)
    out = []
    for k in range(N):
        pos = START + (GOAL - START) * k / (N - 1)
        wobble = 0.01 * np.sin(7 * local + k) if fem else 0.0
        out.append(Scene(robots=[(pos, Q)], arm_deployed=True,
                         bag=Surface(pos + [0, -0.55, 0] + local + wobble, faces),
                         lines=[Polyline(path), Polyline(np.linspace(START, pos, 10),
                                                         (80, 160, 255))],
                         text=[f"t {k:6.1f} s   playback x4", "speed 0.150 m/s"]))
    return out


def timed(fn, n: int) -> float:
    t = time.perf_counter()
    for k in range(n):
        fn(k)
    return (time.perf_counter() - t) / n


def main() -> int:
    fr = FlightRenderer()
    ov = overview_camera(np.vstack([START, GOAL]))
    heading = GOAL - START
    from astrobee_sim.render import chase_camera
    print(f"frame {fr.size[0]}x{fr.size[1]} (chase 512x384 | overview 384x384), {N} frames "
          "Node 2 -> JEM")
    print(f"{'what':<44}{'ms/frame':>10}{'frames/s':>10}  target")
    rows = []
    for fem in (False, True):
        sc = scenes(fem)
        name = "FEM bag (412 nodes)" if fem else "rigid bag"
        chase = timed(lambda k: fr.chase.render(sc[k], chase_camera(fr.world, sc[k].robots[0][0],
                                                                   heading), 512, 384), N)
        over = timed(lambda k: fr.overview.render(sc[k], ov, 384, 384, draw_text=False), N)
        both = timed(lambda k: fr.render(sc[k], heading, ov), N)
        rows += [(f"chase view, {name}", chase, ""), (f"overview, {name}", over, ""),
                 (f"chase + overview, {name}", both, ">= 10 /s")]
    sc = scenes(True)                      # --compare: two stacked 448x320 columns, FEM bag
    cols = [FlightRenderer((448, 320), (448, 320), stacked=True) for _ in range(2)]
    ov2 = overview_camera(np.vstack([START, GOAL]), aspect=448 / 320)
    compare = timed(lambda k: [c.render(sc[k], heading, ov2) for c in cols], N)
    for c in cols:
        c.close()
    rows.append(("--compare frame (2 x 448x640), FEM bag", compare, "~2x a frame"))
    frames = [fr.render(s, heading, ov) for s in scenes(False)]
    import imageio_ffmpeg
    with tempfile.TemporaryDirectory() as d:
        gen = imageio_ffmpeg.write_frames(str(Path(d) / "b.mp4"), fr.size, fps=10,
                                          codec="libx264", pix_fmt_out="yuv420p", quality=7,
                                          macro_block_size=16,
                                          output_params=["-loglevel", "error"])
        gen.send(None)
        enc = timed(lambda k: gen.send(frames[k]), N)
        gen.close()
    rows.append(("MP4 encode (libx264, fed per frame)", enc, ""))
    fr.close()
    rows.append(("matplotlib mplot3d, same walls (rejected)", _mpl(), ""))
    for what, s, target in rows:
        print(f"{what:<44}{1000 * s:>10.1f}{1 / s:>10.1f}  {target}")
    if len(sys.argv) > 1:
        from astrobee_bringup.render_recording import render
        with tempfile.TemporaryDirectory() as d:
            t = time.perf_counter()
            res = render(sys.argv[1], Path(d) / "flight.mp4", duration=60.0)
            dt = time.perf_counter() - t
        print(f"\nastrobee bag render {sys.argv[1]}: {res.frames} frames, {res.sim_seconds:.1f} s "
              f"of flight in {dt:.1f} s wall ({res.frames / dt:.1f} frames/s incl. reading the "
              f"recording), cargo bag surface: {res.cargo_surface}")
    return 0


def _mpl() -> float:
    """mplot3d drawing every wall slab's faces at 512x384 (orbit camera only)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection
    from astrobee_sim.world import World
    w = World.from_config()
    idx = [[0, 1, 3, 2], [4, 5, 7, 6], [0, 1, 5, 4], [2, 3, 7, 6], [0, 2, 6, 4], [1, 3, 7, 5]]
    polys = []
    for b in w.walls:
        c = np.array([[x, y, z] for x in (b[0], b[3]) for y in (b[1], b[4]) for z in (b[2], b[5])])
        polys += [c[i] for i in idx]
    fig = plt.figure(figsize=(5.12, 3.84), dpi=100)
    ax = fig.add_subplot(projection="3d")
    ax.add_collection3d(Poly3DCollection(polys, facecolor=(0.8, 0.8, 0.8, 0.4)))
    ax.set_xlim(8, 13), ax.set_ylim(-7, 2), ax.set_zlim(3, 7)

    def draw(k):
        ax.view_init(elev=20, azim=30 + k)
        fig.canvas.draw()
        np.asarray(fig.canvas.buffer_rgba())
    s = timed(draw, 10)
    plt.close(fig)
    return s


if __name__ == "__main__":
    sys.exit(main())
