"""`astrobee bag render` on what a failed leg leaves: one pose, no pose, poses that are not
finite or flung far off (an exploded simulation: 1e7 m put the robot's mesh in screen-sized
triangles next to the chase camera, >30 s a frame), zero quaternions, an empty window. Each
renders a frame or is refused with one line, quickly; nothing divides by zero."""
from __future__ import annotations

import json
import math
import warnings

import numpy as np
import pytest

from astrobee_bringup import render_recording as rb
from astrobee_bringup import render_tracks as rt
from roszen import typestore
from roszen.bag.writer import BagWriter
from roszen.qos import QoSProfile

Q = [0.0, 0.0, -0.7071067811865476, 0.7071067811865476]
START = np.array([10.95, 0.0, 4.84])
T0_NS = 1_700_000_000_000_000_000
POSE = "geometry_msgs/msg/PoseStamped"


def write_poses(bag_dir, samples, log_s=None) -> None:
    """A recording of /loc/truth/pose only: samples are (t, position, quaternion); logged at
    T0_NS + t (receive time = sim time, as --use-sim-time records) or at T0_NS + log_s[k]."""
    w = BagWriter(bag_dir)
    w.add_topic("/loc/truth/pose", POSE, typestore.message_definition(POSE),
                typestore.type_hash(POSE), [QoSProfile(depth=10)])
    ser, PS = typestore.serializer(POSE), typestore.message_class(POSE)
    for k, (t, pos, q) in enumerate(samples):
        m = PS()
        m.header.stamp.sec, m.header.stamp.nanosec = int(t), int(round((t - int(t)) * 1e9))
        m.pose.position.x, m.pose.position.y, m.pose.position.z = (float(v) for v in pos)
        o = m.pose.orientation
        o.x, o.y, o.z, o.w = (float(v) for v in q)
        w.write("/loc/truth/pose", ser(m), T0_NS + int((t if log_s is None else log_s[k]) * 1e9))
    w.close()


@pytest.mark.parametrize("seconds, fps, speed", [
    (float("nan"), 10, 4), (float("inf"), 10, 4), (-1.0, 10, 4), (5.0, 0.0, 4), (5.0, 10, 0.0)])
def test_frame_count_refuses_what_is_not_a_flight(seconds, fps, speed):
    with pytest.raises(rt.RenderError) as exc:
        rb.frame_count(seconds, fps, speed)
    assert len(str(exc.value).splitlines()) == 1


def test_frame_count_of_a_zero_length_leg_is_one_frame_and_long_ones_are_refused():
    assert rb.frame_count(0.0, 10, 4) == 1
    assert rb.frame_count(4.0, 2, 2) == 5
    with pytest.raises(rt.RenderError, match="more than 100"):
        rb.frame_count(1000.0, 10, 4, max_frames=100)


def test_zero_quaternions_interpolate_without_nan():
    tr = rt.Track(np.array([0.0, 1.0, 2.0]), np.zeros((3, 3)),
                  np.array([[0, 0, 0, 1.0], [0, 0, 0, 0.0], [0, 0, 0, 0.0]]))
    with warnings.catch_warnings():
        warnings.simplefilter("error")                  # a 0/0 warns: fails the test
        for t in np.linspace(-1, 3, 17):
            p, q = tr.at(float(t))
            assert np.all(np.isfinite(q)) and math.isclose(float(np.linalg.norm(q)), 1.0)


def test_unusable_poses_are_dropped_and_a_leg_of_them_refused(tmp_path):
    good = [(0.016 * k, START + [0, -0.01 * k, 0], Q) for k in range(3)]
    flung = [(0.05 + 0.016 * k, START + [0, 1e7 * (k + 1), 0], Q) for k in range(3)]
    bad = [(0.2, [math.nan] * 3, Q), (0.25, START, [0, 0, 0, 0]), (0.3, [math.inf, 0, 0], Q)]
    write_poses(tmp_path / "mixed", good + flung + bad)
    rec = rt.read_tracks(tmp_path / "mixed")
    assert len(rec.robots[""].t) == 3 and rec.span == pytest.approx((0.0, 0.032))
    write_poses(tmp_path / "bad", flung + bad)
    with pytest.raises(rt.RenderError, match="none of the 6 robot poses .* is usable"):
        rt.read_tracks(tmp_path / "bad")


def test_one_pose_renders_one_frame_and_too_long_a_flight_is_refused_at_once(tmp_path):
    write_poses(tmp_path / "bag", [(3.0, START, Q)])
    res = rb.render(tmp_path / "bag", tmp_path / "one.gif", scale=0.25)
    assert res.frames == 1 and res.sim_seconds == 0.0 and (tmp_path / "one.gif").stat().st_size
    write_poses(tmp_path / "long", [(0.0, START, Q), (500.0, START, Q)])
    with pytest.raises(rt.RenderError, match="1251 frames, more than 1000"):
        rb.render(tmp_path / "long", tmp_path / "long.gif", max_frames=1000)
    assert not (tmp_path / "long.gif").exists()


def test_demo_legs_skip_failed_and_empty_legs_with_a_reason(tmp_path):
    """Legs of a run: one flown (a video), one whose window holds no pose, one whose robot was
    flung off, one with an empty window: three reasons, one line each, no exception."""
    t0 = T0_NS / 1e9
    write_poses(tmp_path / "bag", [(0.1 * k, START + [0, -0.02 * k, 0], Q) for k in range(11)]
                + [(2.0 + 0.1 * k, START + [0, 1e8, 0], Q) for k in range(5)])
    run = tmp_path / "run"
    run.mkdir()
    (run / "summary.json").write_text(json.dumps({"legs": [
        {"scenario": "flown", "wall_t0": t0, "wall_t1": t0 + 1.0},
        {"scenario": "nothing", "wall_t0": t0 + 1.5, "wall_t1": t0 + 1.9},
        {"scenario": "flung", "wall_t0": t0 + 2.0, "wall_t1": t0 + 2.5},
        {"scenario": "empty", "wall_t0": t0 + 3.0, "wall_t1": t0 + 3.0},
        {"scenario": "not flown", "wall_t0": None, "wall_t1": None}]}))
    out = rb.render_demo_legs(run, tmp_path / "bag", fps=2, speed=2, scale=0.25)
    assert [p.name for p in out] == ["video_flown.mp4"]
    legs = json.loads((run / "summary.json").read_text())["legs"]
    errors = [leg.get("video_error", "") for leg in legs]
    assert legs[0]["video"] == "video_flown.mp4" and not errors[0]
    assert "no robot pose recorded" in errors[1] and "selected window" in errors[1]
    assert "is usable" in errors[2] and "empty leg" in errors[3] and not errors[4]
    assert all(len(e.splitlines()) <= 1 for e in errors)


def test_renderer_draws_nothing_far_off_or_not_finite():
    """The renderer itself (an environment's rgb_array uses it too): a robot flung 1e7 m off,
    a NaN robot, a NaN bag and a camera on either: a blank or station-only frame, no hang."""
    from astrobee_sim.render import Camera, FlightRenderer, Polyline, Scene, Surface, \
        overview_camera
    fr = FlightRenderer((64, 48), (48, 48))
    try:
        far = START + [0.0, 1e7, 0.0]
        ov = overview_camera(np.array([START, far]))
        frame = fr.render(Scene(robots=[(far, np.array(Q))], lines=[
            Polyline(np.array([START, far]))]), np.array([0.0, 1.0, 0.0]), ov)
        assert frame.shape == (48, 112, 3) and np.all(frame[:, :64] == 30)   # blank chase
        nan = np.full(3, np.nan)
        scene = Scene(robots=[(nan, np.array(Q))],
                      bag=Surface(np.full((8, 3), np.nan), np.array([[0, 1, 2]])))
        img = fr.chase.render(scene, Camera(eye=START + [1.0, 0, 0], target=START), 64, 48)
        assert img.shape == (48, 64, 3) and img.std() > 1      # the station, drawn
        img = fr.chase.render(scene, Camera(eye=nan, target=START), 64, 48)
        assert np.all(img == 30)
    finally:
        fr.close()


def test_the_launch_names_each_leg_left_without_a_video(tmp_path, capsys):
    from astrobee_bringup.launch import cargo_transport
    (tmp_path / "summary.json").write_text(json.dumps({"legs": [
        {"scenario": "a", "video": "video_a.mp4"},
        {"scenario": "b", "video_error": "empty leg: wall-clock window 1.000-1.000"}]}))
    cargo_transport._print_video_errors(tmp_path / "summary.json")
    assert capsys.readouterr().out.splitlines() == [
        "[video] b: not rendered: empty leg: wall-clock window 1.000-1.000"]


def test_interleaved_clocks_do_not_stretch_the_timeline(tmp_path):
    """Stamps of two clocks interleaved (each jump back was taken for a reset and added a whole
    leg: 40 samples became 900 s of video) fall back to the receive time; a real reset (one
    jump back) still continues the timeline."""
    alternating = [(0.016 * k + (45.0 if k % 2 else 0.0), START, Q) for k in range(40)]
    write_poses(tmp_path / "alt", alternating, log_s=[0.016 * k for k in range(40)])
    rec = rt.read_tracks(tmp_path / "alt")
    assert rec.span[1] - rec.span[0] == pytest.approx(39 * 0.016), rec.span     # not 900 s
    reset = [(45.0 + 0.016 * k, START, Q) for k in range(10)] + [(0.016 * k, START, Q)
                                                                  for k in range(10)]
    line = rt._Timeline([int(1e9 * 0.016 * k) for k in range(20)], [s[0] for s in reset])
    assert line.stamped and np.all(np.diff(line.cont) > 0)
    assert line.cont[-1] - line.cont[0] == pytest.approx(19 * 0.016, abs=0.02)
