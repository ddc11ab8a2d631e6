"""Videos show the cargo bag: a recorded two-robot leg (robots named bumble and queen, the bag
between them) and a FEM leg whose sim recorded no mesh sample (the bag's rest shape from
/sim/scenario) render with the bag's colour in every frame of both views; a no-bag leg shows
none. The overlay gives the swing angle, the clearance and a red flash at a contact; --compare
puts two legs of one run side by side. Small frames, few of them."""
from __future__ import annotations

import json

import numpy as np
import pytest

from test_render import set_pose, stamp_header

from roszen import typestore
from roszen.bag.writer import BagWriter
from roszen.qos import LATCHED, QoSProfile

Q = [0.0, 0.0, -0.7071067811865476, 0.7071067811865476]       # facing -y
START = np.array([10.95, 0.0, 4.84])
SIZE = np.array([0.50, 0.42, 0.25])
T0_NS = 1_700_000_000_000_000_000
TYPES = {"pose": "geometry_msgs/msg/PoseStamped", "/sim/bag/state": "astrobee_msgs/msg/BagState",
         "/sim/bag/mesh": "astrobee_msgs/msg/BagMesh", "/sim/contacts": "astrobee_msgs/msg/Contacts",
         "/sim/scenario": "astrobee_msgs/msg/ScenarioInfo"}


def write_leg(bag_dir, robots=("",), bag: str | None = "rigid", mesh: bool = True,
              seconds: float = 2.0, rate: float = 10.0, contact_at: float | None = None,
              t0_ns: int = T0_NS, writer: BagWriter | None = None, close: bool = True) -> BagWriter:
    """One leg as the graph records it: each robot flying -y at 0.2 m/s (robots side by side
    0.8 m apart along x), the scenario, the bag 0.5 m ahead of the first (state; box-corner
    mesh unless mesh=False), contacts with one contact point at `contact_at`."""
    w = writer or BagWriter(bag_dir)
    if writer is None:
        names = [f"/{r}/loc/truth/pose" if r else "/loc/truth/pose" for r in robots]
        for name, ty in [(n, TYPES["pose"]) for n in names] + [
                (n, t) for n, t in TYPES.items() if n != "pose"]:
            w.add_topic(name, ty, typestore.message_definition(ty), typestore.type_hash(ty),
                        [LATCHED if name == "/sim/scenario" else QoSProfile(depth=10)])
    ser = {ty: typestore.serializer(ty) for ty in TYPES.values()}
    M = {k: typestore.message_class(ty) for k, ty in TYPES.items()}
    sc = M["/sim/scenario"]()
    stamp_header(sc.header, 0.0)
    sc.name, sc.robots = "leg", list(robots)
    sc.carrying_bag = bag is not None
    sc.bag_model, sc.bag_variant, sc.bag_nodes = bag or "", "front", 0
    if bag == "fem":
        from astrobee_sim.bags.base import handle_dirs
        from astrobee_sim.bags.mesh import bag_mesh
        sc.bag_nodes = len(bag_mesh(SIZE, handle_dirs("front"), 120).nodes)
    sc.bag_size.x, sc.bag_size.y, sc.bag_size.z = (float(v) for v in SIZE)
    w.write("/sim/scenario", ser[TYPES["/sim/scenario"]](sc), t0_ns)
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    for k in range(int(seconds * rate) + 1):
        t = k / rate
        log = t0_ns + int(t * 1e9) + 1000
        for i, r in enumerate(robots):
            ps = M["pose"]()
            stamp_header(ps.header, t)
            set_pose(ps.pose, START + [0.8 * i, -0.2 * t, 0.0], Q)
            w.write(f"/{r}/loc/truth/pose" if r else "/loc/truth/pose", ser[TYPES["pose"]](ps), log)
        centre = START + [0.0, -0.2 * t - 0.5, 0.0]
        cs = M["/sim/contacts"]()
        stamp_header(cs.header, t)
        cs.robot_clearance, cs.bag_clearance = 0.6, (0.4 if bag else -1.0)
        if contact_at is not None and abs(t - contact_at) < 1e-9:
            c = typestore.message_class("astrobee_msgs/msg/Contact")()
            c.body_a, c.body_b = "bag", "wall"
            c.position.x, c.position.y, c.position.z = (float(v) for v in centre + [0, 0, 0.12])
            cs.contacts, cs.in_contact = [c], True
        w.write("/sim/contacts", ser[TYPES["/sim/contacts"]](cs), log + 1)
        if bag is None:
            continue
        bs = M["/sim/bag/state"]()
        stamp_header(bs.header, t)
        bs.model, bs.variant = bag, "front"
        set_pose(bs.pose, centre, [0, 0, 0, 1])
        w.write("/sim/bag/state", ser[TYPES["/sim/bag/state"]](bs), log + 2)
        if mesh:
            bm = M["/sim/bag/mesh"]()
            stamp_header(bm.header, t)
            pts = centre + corners * SIZE / 2
            bm.num_nodes = len(pts)
            bm.positions = np.asarray(pts, np.float32).reshape(-1)
            w.write("/sim/bag/mesh", ser[TYPES["/sim/bag/mesh"]](bm), log + 3)
    if close:
        w.close()
    return w


def bag_pixels(img: np.ndarray) -> int:
    """Pixels of the cargo bag's orange (shaded or lit): red over green over blue, saturated."""
    r, g, b = (img[..., k].astype(int) for k in range(3))
    return int(np.sum((r > 60) & (r > 1.3 * g) & (g > 1.6 * b + 5)))


def red_pixels(img: np.ndarray) -> int:
    r, g, b = (img[..., k].astype(int) for k in range(3))
    return int(np.sum((r > 200) & (g < 60) & (b < 60)))


def frames_of(path, size):
    import imageio_ffmpeg
    reader = imageio_ffmpeg.read_frames(str(path))
    reader.__next__()
    return [np.frombuffer(f, np.uint8).reshape(size[1], size[0], 3) for f in reader]


@pytest.mark.parametrize("robots, bag, mesh", [
    (("bumble", "queen"), "rigid", True),          # two robots, neither the default one
    (("queen",), "fem", False),                    # the FEM bag, no mesh sample recorded
])
def test_the_bag_is_in_every_frame_of_both_views(tmp_path, robots, bag, mesh):
    from astrobee_bringup import render_recording, render_tracks
    bag_dir = tmp_path / "bag"
    write_leg(bag_dir, robots, bag, mesh)
    rec = render_tracks.read_tracks(bag_dir)
    assert list(rec.robots) == list(robots)
    if not mesh:
        assert "rest shape" in rec.mesh_source and rec.mesh_source.startswith("tet mesh")
    res = render_recording.render(bag_dir, tmp_path / "v.mp4", fps=2, speed=1, scale=0.5)
    frames = frames_of(res.path, res.size)
    assert len(frames) == res.frames == 5
    chase_w = res.size[0] - res.size[1]                  # overview is square
    for f in frames:
        assert bag_pixels(f[:, :chase_w]) > 30, "no cargo bag in the chase view"
        assert bag_pixels(f[:, chase_w:]) > 3, "no cargo bag in the overview"
    scene, _ = render_recording.scene_at(rec, 1.0, 1.0, 0.0)
    assert len(scene.robots) == len(robots)
    assert not any("deformation" in s for s in scene.text)
    assert any("swing" in s and "deg" in s for s in scene.text)
    assert any("bag to wall 0.40 m" in s for s in scene.text)


def test_no_bag_leg_shows_no_bag(tmp_path):
    from astrobee_bringup import render_recording
    bag_dir = tmp_path / "bag"
    write_leg(bag_dir, ("",), None)
    res = render_recording.render(bag_dir, tmp_path / "v.mp4", fps=1, speed=2, scale=0.5)
    frames = frames_of(res.path, res.size)
    assert frames and all(bag_pixels(f) == 0 for f in frames)
    assert res.cargo_surface == "none"


def test_a_contact_flashes_red_and_the_swing_is_measured(tmp_path):
    from astrobee_bringup import render_recording, render_tracks
    from astrobee_sim.render import FlightRenderer, overview_camera
    bag_dir = tmp_path / "bag"
    write_leg(bag_dir, ("",), "rigid", contact_at=1.0)
    rec = render_tracks.read_tracks(bag_dir)
    # the bag moves with the robot: no swing; its handle ('front': -y, 0.25 m from the centre
    # here) stays on the robot, so the centre moved 0.1 m sideways swings atan(0.1 / 0.25)
    assert render_tracks.swing_angle(rec, 1.5) == pytest.approx(0.0, abs=1e-6)
    rec.cargo.pos[-1] += [0.1, 0.0, 0.0]
    assert np.degrees(render_tracks.swing_angle(rec, rec.cargo.t[-1])) == pytest.approx(
        np.degrees(np.arctan2(0.1, 0.25)), abs=0.5)
    fr = FlightRenderer((256, 192), (192, 192))
    try:
        ov = overview_camera(rec.robots[""].pos)
        hit, _ = render_recording.scene_at(rec, 1.0, 1.0, 0.0)
        calm, _ = render_recording.scene_at(rec, 1.6, 1.0, 0.0)
        assert any(s.startswith("CONTACT") for s in hit.text) and hit.spots
        assert not calm.spots
        assert red_pixels(fr.render(hit, None, ov)) > red_pixels(fr.render(calm, None, ov)) + 20
    finally:
        fr.close()


def test_compare_two_legs_of_one_run_side_by_side(tmp_path):
    from astrobee_bringup import render_recording
    bag_dir = tmp_path / "run" / "bag"
    bag_dir.parent.mkdir()
    w = write_leg(bag_dir, ("",), "rigid", seconds=1.0, close=False)
    write_leg(bag_dir, ("",), "rigid", seconds=1.0, t0_ns=T0_NS + 5_000_000_000, writer=w)
    (tmp_path / "run" / "summary.json").write_text(json.dumps({"legs": [
        {"scenario": "pd", "wall_t0": T0_NS / 1e9, "wall_t1": T0_NS / 1e9 + 2},
        {"scenario": "mpc", "wall_t0": T0_NS / 1e9 + 5, "wall_t1": T0_NS / 1e9 + 7}]}))
    out = tmp_path / "c.mp4"
    assert render_recording.main(["--compare", f"{bag_dir}:0", f"{bag_dir}:1", "-o", str(out),
                            "--fps", "2", "--speed", "1", "--scale", "0.5"]) == 0
    size = (464, 320)                     # two 224-wide columns, a 4 px divider, padded to 16
    frames = frames_of(out, size)
    assert len(frames) == 3
    half = size[0] // 2
    for f in frames:
        assert bag_pixels(f[:, :half]) > 10 and bag_pixels(f[:, half:]) > 10
    assert render_recording.main(["--compare", str(bag_dir), "-o", str(out)]) == 1
    # the demo's comparison: two legs by scenario, noted in summary.json
    run = tmp_path / "run"
    made = render_recording.render_demo_compare(run, ("pd", "mpc"), fps=1, speed=2, scale=0.25)
    assert made == run / "video_compare.mp4" and made.stat().st_size > 0
    note = json.loads((run / "summary.json").read_text())["comparison"]
    assert note == {"legs": ["pd", "mpc"], "video": "video_compare.mp4"}
    assert render_recording.render_demo_compare(run, ("pd", "lqr")) is None
