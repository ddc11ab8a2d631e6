"""`astrobee bag render`: a synthesised recording (robot flying out of Node 2 towards the JEM with
a rigid cargo bag, planned path, controller candidates) renders to GIF and MP4 with the frame
count and size asked for, the robot shows where it is, a FEM-sized node cloud gets the
generated mesh's surface, and bad arguments exit 1 with one line."""
from __future__ import annotations

import json
import subprocess

import numpy as np
import pytest

from conftest import ASTROBEE
from roszen import typestore
from roszen.bag.writer import BagWriter
from roszen.qos import LATCHED, QoSProfile

Q = [0.0, 0.0, -0.7071067811865476, 0.7071067811865476]       # facing -y (towards the JEM)
START = np.array([10.95, 0.0, 4.84])
CORNERS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)
HALF = np.array([0.25, 0.21, 0.125])
T0_NS = 1_700_000_000_000_000_000


def stamp_header(h, t: float) -> None:
    """A world-frame header stamped t s (also the cargo-visible tests')."""
    h.stamp.sec, h.stamp.nanosec = int(t), int(round((t - int(t)) * 1e9))
    h.frame_id = "world"


def set_pose(pose, pos, q) -> None:
    """A geometry_msgs/Pose from a position and an [x, y, z, w] quaternion."""
    pose.position.x, pose.position.y, pose.position.z = (float(v) for v in pos)
    o = pose.orientation
    o.x, o.y, o.z, o.w = (float(v) for v in q)


def _path_msg(points, t):
    P, PS = typestore.message_class("nav_msgs/msg/Path"), \
        typestore.message_class("geometry_msgs/msg/PoseStamped")
    m = P()
    stamp_header(m.header, t)
    poses = []
    for p in points:
        ps = PS()
        stamp_header(ps.header, t)
        set_pose(ps.pose, p, Q)
        poses.append(ps)
    m.poses = poses
    return m


def write_recording(bag_dir, seconds: float = 4.0, rate: float = 20.0, fem_nodes=None) -> None:
    """A recording as the graph writes it: robot moving at 0.2 m/s along -y, its cargo bag held
    0.55 m ahead (state + mesh of box corners, or the given FEM node cloud), the plan, and one
    candidate path per second."""
    types = {"/loc/truth/pose": "geometry_msgs/msg/PoseStamped",
             "/sim/bag/state": "astrobee_msgs/msg/BagState",
             "/sim/bag/mesh": "astrobee_msgs/msg/BagMesh",
             "/mob/planner/path": "nav_msgs/msg/Path",
             "/gnc/ctl/candidates": "nav_msgs/msg/Path"}
    w = BagWriter(bag_dir)
    for name, ty in types.items():
        w.add_topic(name, ty, typestore.message_definition(ty), typestore.type_hash(ty),
                    [LATCHED if name == "/mob/planner/path" else QoSProfile(depth=10)])
    ser = {n: typestore.serializer(ty) for n, ty in types.items()}
    goal = START + [0.0, -6.0, 0.0]
    w.write("/mob/planner/path", ser["/mob/planner/path"](
        _path_msg(np.linspace(START, goal, 10), 0.0)), T0_NS)
    PS = typestore.message_class("geometry_msgs/msg/PoseStamped")
    BS = typestore.message_class("astrobee_msgs/msg/BagState")
    BM = typestore.message_class("astrobee_msgs/msg/BagMesh")
    for k in range(int(seconds * rate) + 1):
        t = k / rate
        log = T0_NS + int(t * 1e9) + 1000
        pos = START + [0.0, -0.2 * t, 0.0]
        ps = PS()
        stamp_header(ps.header, t)
        set_pose(ps.pose, pos, Q)
        w.write("/loc/truth/pose", ser["/loc/truth/pose"](ps), log)
        centre = pos + [0.0, -0.55, 0.0]
        bs = BS()
        stamp_header(bs.header, t)
        bs.model, bs.variant = ("fem" if fem_nodes is not None else "rigid"), "front"
        set_pose(bs.pose, centre, [0, 0, 0, 1])
        w.write("/sim/bag/state", ser["/sim/bag/state"](bs), log + 1)
        if k % 2 == 0:
            pts = centre + (fem_nodes if fem_nodes is not None else CORNERS * HALF)
            bm = BM()
            stamp_header(bm.header, t)
            bm.num_nodes = len(pts)
            bm.positions = np.asarray(pts, np.float32).reshape(-1)
            w.write("/sim/bag/mesh", ser["/sim/bag/mesh"](bm), log + 2)
        if k % int(rate) == 0:
            cand = np.linspace(pos, pos + [0.3, -1.0, 0.0], 5)
            w.write("/gnc/ctl/candidates", ser["/gnc/ctl/candidates"](_path_msg(cand, t)),
                    log + 3)
    w.close()


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    bag = tmp_path_factory.mktemp("render") / "bag"
    write_recording(bag)
    return bag


def _run(*args):
    return subprocess.run([ASTROBEE, "bag", "render", *map(str, args)], capture_output=True,
                          text=True, timeout=240)


def test_gif_and_mp4_have_the_frames_asked_for(recording, tmp_path):
    # 4 s of flight at 2 sim s per video s and 2 fps: frames at t = 0, 1, 2, 3, 4
    gif = tmp_path / "flight.gif"
    r = _run(recording, "--gif", "-o", gif, "--speed", 2, "--fps", 2, "--scale", 0.5)
    assert r.returncode == 0, r.stderr
    assert "5 frames 448x192" in r.stdout and "boxes" in r.stdout
    from PIL import Image
    with Image.open(gif) as im:
        assert im.size == (448, 192)
        assert im.n_frames == 5

    mp4 = tmp_path / "flight.mp4"
    r = _run(recording, "-o", mp4, "--speed", 4, "--fps", 2, "--scale", 0.5)
    assert r.returncode == 0, r.stderr
    import imageio_ffmpeg
    reader = imageio_ffmpeg.read_frames(str(mp4))
    meta = reader.__next__()
    assert tuple(meta["size"]) == (448, 192)
    frames = [np.frombuffer(f, np.uint8).reshape(192, 448, 3) for f in reader]
    assert len(frames) == 3                                         # t = 0, 2, 4
    assert frames[0].std() > 10                                     # not a blank picture


def test_robot_is_drawn_where_it_is(recording):
    """Rendering the same camera with and without the robot changes the pixels around the
    robot's projected position and leaves the far corners alone."""
    from astrobee_bringup import render_tracks
    from astrobee_sim.render import Camera, Renderer, Scene, project

    rec = render_tracks.read_tracks(recording)
    pos, q = rec.robots[""].at(2.0)
    assert np.allclose(pos, START + [0, -0.4, 0], atol=1e-6)
    r = Renderer()
    try:
        cam = Camera(eye=pos + [1.2, 0.9, -0.4], target=pos)
        w, h = 160, 120
        with_robot = r.render(Scene(robots=[(pos, q)]), cam, w, h).astype(int)
        without = r.render(Scene(), cam, w, h).astype(int)
    finally:
        r.close()
    view, proj = cam.matrices(w, h)
    (u, v), _ = project(np.array([pos, pos]), view, proj, w, h, cam.near)[0]
    u, v = int(u), int(v)
    assert abs(u - w / 2) < 2 and abs(v - h / 2) < 2                 # looked at: image centre
    diff = np.abs(with_robot - without).sum(axis=2)
    assert (diff[v - 8:v + 8, u - 8:u + 8] > 30).mean() > 0.8
    assert diff[:10, :10].max() == 0 and diff[-10:, -10:].max() == 0


def test_recording_timeline_bag_and_candidates(recording):
    from astrobee_bringup import render_recording, render_tracks
    rec = render_tracks.read_tracks(recording)
    assert rec.span == pytest.approx((0.0, 4.0))
    assert rec.mesh_source == "boxes" and len(rec.mesh_faces) == 12
    scene, heading = render_recording.scene_at(rec, 1.0, 4.0, 0.0)
    assert heading[1] < 0 and abs(heading[0]) < 1e-6                # flying along -y
    c = scene.bag.vertices.mean(axis=0)
    assert np.allclose(c, START + [0, -0.2 - 0.55, 0], atol=1e-6)  # placed at the state pose
    assert scene.arm_deployed
    colours = [ln.rgb for ln in scene.lines]
    assert render_recording.PATH_RGB in colours and render_recording.CAND_RGB in colours
    assert any("speed 0.200 m/s" in s for s in scene.text)
    # 0.6 s after the last candidate (t=1) it is stale and not drawn
    scene, _ = render_recording.scene_at(rec, 1.6, 4.0, 0.0)
    assert render_recording.CAND_RGB not in [ln.rgb for ln in scene.lines]


def test_fem_node_cloud_gets_the_generated_surface(tmp_path):
    from astrobee_bringup import render_tracks
    from astrobee_sim.bags.base import handle_dirs
    from astrobee_sim.bags.mesh import bag_mesh
    mesh = bag_mesh([0.5, 0.42, 0.25], handle_dirs("front"), 250)
    bag = tmp_path / "bag"
    write_recording(bag, seconds=1.0, fem_nodes=mesh.nodes - mesh.nodes.mean(axis=0))
    rec = render_tracks.read_tracks(bag)
    assert rec.mesh_source.startswith("tet mesh")
    from astrobee_sim.render import boundary_faces
    assert len(rec.mesh_faces) == len(boundary_faces(mesh.tets))
    # an unknown node count falls back to the convex hull of the cloud
    faces, how = render_tracks.surface_faces("fem", "front", np.random.default_rng(0).random((37, 3)))
    assert how == "convex hull" and faces.shape[1] == 3


def test_demo_legs_get_one_video_each(recording, tmp_path):
    from astrobee_bringup import render_recording
    run = tmp_path / "run"
    run.mkdir()
    (run / "summary.json").write_text(json.dumps({"legs": [
        {"scenario": "a", "wall_t0": T0_NS / 1e9, "wall_t1": T0_NS / 1e9 + 1.0},
        {"scenario": "b", "wall_t0": T0_NS / 1e9 + 3.0, "wall_t1": T0_NS / 1e9 + 4.5},
        {"scenario": "c", "wall_t0": 1.0, "wall_t1": 2.0}]}))
    out = render_demo_legs = render_recording.render_demo_legs(run, recording, fps=2, speed=2,
                                                         scale=0.25)
    assert [p.name for p in render_demo_legs] == ["video_a.mp4", "video_b.mp4"]
    assert all(p.stat().st_size > 0 for p in out)
    legs = json.loads((run / "summary.json").read_text())["legs"]
    assert legs[0]["video"] == "video_a.mp4" and "no robot pose" in legs[2]["video_error"]


@pytest.mark.parametrize("args, message", [
    (["/nonexistent/bag"], "does not exist"),
    (["{bag}", "-o", "out.avi"], "must end in .mp4 or .gif"),
    (["{bag}", "--gif", "-o", "x.mp4"], "--gif needs an output ending in .gif"),
    (["{bag}", "--fps", "0"], "must be > 0"),
    (["{bag}", "--start", "99"], "past the end"),
    (["{bag}", "--leg", "0"], "--leg needs"),
    (["{bag}", "--bogus"], "unrecognized arguments"),
])
def test_bad_arguments_exit_1_with_one_line(recording, tmp_path, args, message):
    r = subprocess.run([ASTROBEE, "bag", "render",
                        *[a.format(bag=recording) for a in args]],
                       capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert r.returncode == 1
    assert message in r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in r.stderr
