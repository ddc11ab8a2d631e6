"""`astrobee bag render`: a recorded run -> MP4 or GIF, headless (chase view + overview).

Reads from the recording: the robots' /loc/truth/pose (or /tf's `body` frames when no pose was
recorded), the cargo bag's /sim/bag/state pose and its /sim/bag/mesh points, the planned path
/mob/planner/path and, when present, the controller's candidates (/gnc/ctl/candidates as a
nav_msgs/Path or a visualization_msgs/MarkerArray of line strips). The bag's surface: a mesh
sample holds points only, so the faces are rebuilt: 8 corners per part for the rigid, constraint
and composite models (their /sim/bag/mesh is the parts' box corners); for the FEM bag the tet
mesh of astrobee_sim/bags/mesh.py is regenerated for the recorded node count (variant from the
state, size and resolution searched) and its boundary triangles drawn; when no generated mesh
matches the recorded nodes, their convex hull. Mesh samples (10 Hz) are carried in the bag's
frame and placed at the 62.5 Hz state pose of each video frame, so the bag never lags the robot.

Time: a leg's sim clock restarts at each reset, so the video timeline is the pose stamps made
continuous across resets; every other topic is placed on it by its own stamp (or its receive
time). `render_demo_legs(run_dir)` writes one video per leg of a demo run (summary.json's
wall-clock windows).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from astrobee import rotations as rot

DEFAULT_FPS = 10
DEFAULT_SPEED = 4.0                    # sim seconds per video second
MAX_FRAMES = 3000                      # a longer video is refused (5 min at 10 fps; a leg ~110)
MAX_RESETS = 8                         # clock resets a recording's stamps may show (one a leg)
MAX_COORD = 1000.0                     # m: a sample farther from the origin is dropped (the ISS
# frame spans tens of metres; an exploded simulation's 1e7 m puts the robot's mesh, in the
# renderer's float32, into screen-sized triangles next to the camera: >30 s a frame, measured)
IDENTITY = np.array([0.0, 0.0, 0.0, 1.0])
PATH_RGB, TRAIL_RGB, CAND_RGB = (40, 210, 70), (80, 160, 255), (235, 80, 200)


@dataclass
class Track:
    """Samples on the video timeline: times (s), positions (N, 3), quaternions (N, 4)."""
    t: np.ndarray
    pos: np.ndarray
    quat: np.ndarray

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Pose at time t: positions interpolated, quaternions normalised-lerped."""
        i = int(np.searchsorted(self.t, t))
        if i <= 0:
            return self.pos[0], _unit_quat(self.quat[0])
        if i >= len(self.t):
            return self.pos[-1], _unit_quat(self.quat[-1])
        t0, t1 = self.t[i - 1], self.t[i]
        s = 0.0 if t1 <= t0 else (t - t0) / (t1 - t0)
        q0, q1 = self.quat[i - 1], self.quat[i]
        if float(q0 @ q1) < 0:
            q1 = -q1
        return (1 - s) * self.pos[i - 1] + s * self.pos[i], _unit_quat((1 - s) * q0 + s * q1)

    def velocity(self, t: float, dt: float = 0.25) -> np.ndarray:
        return (self.at(t + dt / 2)[0] - self.at(t - dt / 2)[0]) / dt


def _unit_quat(q: np.ndarray) -> np.ndarray:
    """q normalised; the identity for a zero quaternion (no 0/0 NaN into the renderer)."""
    n = float(np.linalg.norm(q))
    return q / n if n > 1e-9 else IDENTITY


@dataclass
class Recording:
    """What a video needs from a bag, on one timeline (s)."""
    robots: dict[str, Track] = field(default_factory=dict)
    bag: Track | None = None
    bag_model: str = ""
    bag_variant: str = ""
    deformation: tuple[np.ndarray, np.ndarray] | None = None      # (t, RMS m)
    mesh_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    mesh_local: list[np.ndarray] = field(default_factory=list)    # bag frame (world if no state)
    mesh_faces: np.ndarray | None = None
    mesh_source: str = ""
    paths: list[tuple[float, np.ndarray]] = field(default_factory=list)
    candidates: list[tuple[float, list[np.ndarray]]] = field(default_factory=list)

    @property
    def span(self) -> tuple[float, float]:
        t = np.concatenate([tr.t for tr in self.robots.values()])
        return float(t.min()), float(t.max())


class RenderError(Exception):
    """A recording that cannot be rendered (message says why, one line)."""


# ---- reading -------------------------------------------------------------------------------
def _stamp(h: Any) -> float:
    return float(h.stamp.sec) + 1e-9 * float(h.stamp.nanosec)


class _Timeline:
    """Maps (stamp, receive time) to one continuous time: the reference stamps plus an offset
    that grows at every clock reset (a stamp jumping back). Stamps jumping back more often than
    resets do (two clocks' samples interleaved: each jump added a whole leg, a 40-sample
    window became 900 s of video) are not trusted: the receive time is the timeline then."""

    def __init__(self, log_ns: list[int], stamps: list[float]):
        order = np.argsort(np.asarray(log_ns), kind="stable")
        self.log = np.asarray(log_ns, float)[order]
        s = np.asarray(stamps, float)[order]
        backs = s[1:] < s[:-1] - 1e-3
        self.stamped = int(backs.sum()) <= max(MAX_RESETS, len(s) // 100)
        if not self.stamped:
            self.off = np.zeros(len(s))
            self.cont = s[0] + (self.log - self.log[0]) * 1e-9
            return
        off = np.zeros(len(s))
        for i in range(1, len(s)):
            gap = (self.log[i] - self.log[i - 1]) * 1e-9
            off[i] = off[i - 1] + ((s[i - 1] - s[i] + max(gap, 0.0)) if backs[i - 1] else 0.0)
        self.off, self.cont = off, s + off

    def of(self, log_ns: int, stamp: float | None = None) -> float:
        i = min(max(int(np.searchsorted(self.log, log_ns)) - 1, 0), len(self.log) - 1)
        if stamp is None or stamp <= 0 or not self.stamped:
            return float(np.interp(log_ns, self.log, self.cont))
        return float(stamp + self.off[i])


def read_recording(bag_dir: str | os.PathLike,
                   log_window: tuple[float, float] | None = None) -> Recording:
    """Everything a video needs from a rosbag2 directory (optionally only the messages
    recorded in the wall-clock window `log_window`, seconds)."""
    from roszen import typestore
    from roszen.bag.metadata import BagError
    from roszen.bag.reader import BagReader

    try:
        reader = BagReader(bag_dir)
        topics = {t.name: t.type for t in reader.metadata().topics}
    except BagError as exc:
        raise RenderError(str(exc)) from None
    lo, hi = (log_window[0] * 1e9, log_window[1] * 1e9) if log_window else (-1.0, math.inf)
    pose_topics = {n: n[: -len("/loc/truth/pose")].strip("/") for n, ty in topics.items()
                   if n.endswith("/loc/truth/pose") and ty.endswith("PoseStamped")}
    extra = [n for n, ty in topics.items()
             if n.endswith("/sim/bag/state") or n.endswith("/sim/bag/mesh")
             or n.endswith("/mob/planner/path") or n.endswith("/gnc/ctl/candidates")]
    use_tf = not pose_topics and "/tf" in topics
    wanted = list(pose_topics) + extra + (["/tf"] if use_tf else [])
    raw: dict[str, list[tuple[int, Any]]] = {n: [] for n in wanted}
    decode: dict[str, Callable] = {n: typestore.deserializer(topics[n]) for n in wanted}
    for m in reader.messages(wanted):
        if lo <= m.publish_time_ns <= hi:    # wall receive time (log time may be sim time)
            try:
                raw[m.topic.name].append((m.log_time_ns, decode[m.topic.name](m.data)))
            except Exception:  # noqa: BLE001 - one bad record must not lose the video
                continue
    poses: dict[str, list[tuple[int, float, list, list]]] = {}
    for topic, name in pose_topics.items():
        poses[name] = [(ln, _stamp(msg.header), _xyz(msg.pose.position),
                        _xyzw(msg.pose.orientation)) for ln, msg in raw[topic]]
    if use_tf:
        for ln, msg in raw["/tf"]:
            for tf in msg.transforms:
                child = tf.child_frame_id.strip("/")
                if child == "body" or child.endswith("/body"):
                    name = child[: -len("body")].strip("/")
                    poses.setdefault(name, []).append(
                        (ln, _stamp(tf.header), _xyz(tf.transform.translation),
                         _xyzw(tf.transform.rotation)))
    recorded = sum(len(v) for v in poses.values())
    poses = {k: [p for p in v if _usable(p[2], p[3])] for k, v in poses.items()}
    poses = {k: v for k, v in poses.items() if v}
    if not poses:
        if recorded:
            raise RenderError(f"{bag_dir}: none of the {recorded} robot poses recorded"
                              + (" in the selected window" if log_window else "")
                              + f" is usable (not finite, or farther than {MAX_COORD:g} m)")
        raise RenderError(f"{bag_dir}: no robot pose recorded (/loc/truth/pose or /tf)"
                          + (" in the selected window" if log_window else ""))
    ref = poses.get("") or next(iter(poses.values()))
    line = _Timeline([p[0] for p in ref], [p[1] for p in ref])
    rec = Recording()
    for name, samples in sorted(poses.items()):
        rec.robots[name] = _track([(line.of(ln, st), x, q) for ln, st, x, q in samples])
    _read_bag_topics(rec, raw, line)
    for topic in (n for n in raw if n.endswith("/mob/planner/path")):
        for ln, msg in raw[topic]:
            pts = np.array([_xyz(ps.pose.position) for ps in msg.poses]).reshape(-1, 3)
            if len(pts) >= 2 and _usable(pts):
                rec.paths.append((line.of(ln), pts))
    for topic in (n for n in raw if n.endswith("/gnc/ctl/candidates")):
        for ln, msg in raw[topic]:
            lines = [c for c in _candidate_lines(msg) if _usable(c)]
            if lines:
                rec.candidates.append((line.of(ln), lines))
    rec.paths.sort(key=lambda x: x[0])
    rec.candidates.sort(key=lambda x: x[0])
    return rec


def _usable(pos: Any, quat: Any | None = None) -> bool:
    """A sample the renderer can draw: finite, within MAX_COORD of the origin, a quaternion
    of non-zero norm."""
    p = np.asarray(pos, float)
    if not (np.all(np.isfinite(p)) and np.all(np.abs(p) <= MAX_COORD)):
        return False
    if quat is None:
        return True
    q = np.asarray(quat, float)
    return bool(np.all(np.isfinite(q)) and np.linalg.norm(q) > 1e-6)


def _xyz(v: Any) -> list[float]:
    return [float(v.x), float(v.y), float(v.z)]


def _xyzw(q: Any) -> list[float]:
    return [float(q.x), float(q.y), float(q.z), float(q.w)]


def _track(samples: list[tuple[float, list, list]]) -> Track:
    samples.sort(key=lambda s: s[0])
    return Track(np.array([s[0] for s in samples]), np.array([s[1] for s in samples]),
                 np.array([s[2] for s in samples]))


def _candidate_lines(msg: Any) -> list[np.ndarray]:
    """Polylines of a candidates message: a nav_msgs/Path, or a MarkerArray's line strips."""
    if hasattr(msg, "poses"):
        pts = np.array([_xyz(ps.pose.position) for ps in msg.poses]).reshape(-1, 3)
        return [pts] if len(pts) >= 2 else []
    out = []
    for mk in getattr(msg, "markers", []):
        if int(mk.type) in (4, 5) and int(mk.action) == 0 and len(mk.points) >= 2:  # STRIP, LIST
            pts = np.array([_xyz(p) for p in mk.points])
            q, o = _xyzw(mk.pose.orientation), np.array(_xyz(mk.pose.position))
            if any(q[:3]) or np.any(o):
                pts = o + rot.rotate(np.asarray(q) / (np.linalg.norm(q) or 1.0), pts)
            out.append(pts)
    return out


def _read_bag_topics(rec: Recording, raw: dict, line: _Timeline) -> None:
    """The cargo bag's state track and its mesh samples in the bag frame."""
    states = [(ln, msg) for n in raw if n.endswith("/sim/bag/state") for ln, msg in raw[n]
              if _usable(_xyz(msg.pose.position), _xyzw(msg.pose.orientation))]
    meshes = [(ln, msg) for n in raw if n.endswith("/sim/bag/mesh") for ln, msg in raw[n]]
    if states:
        rec.bag = _track([(line.of(ln, _stamp(m.header)), _xyz(m.pose.position),
                           _xyzw(m.pose.orientation)) for ln, m in states])
        rec.bag_model, rec.bag_variant = str(states[-1][1].model), str(states[-1][1].variant)
        rec.deformation = (rec.bag.t.copy(), np.array([float(m.deformation) for _, m in states]))
    times, local = [], []
    for ln, m in meshes:
        pts = np.asarray(m.positions, float).reshape(-1, 3)
        if len(pts) < 4 or (local and len(pts) != len(local[0])) or not _usable(pts):
            continue
        t = line.of(ln, _stamp(m.header))
        if rec.bag is not None:
            c, q = rec.bag.at(t)
            pts = rot.rotate(rot.conjugate(q), pts - c)
        times.append(t)
        local.append(pts)
    if not local:
        return
    order = np.argsort(times, kind="stable")
    rec.mesh_t = np.asarray(times)[order]
    rec.mesh_local = [local[i] for i in order]
    rec.mesh_faces, rec.mesh_source = surface_faces(rec.bag_model, rec.bag_variant,
                                                    rec.mesh_local[0])


def surface_faces(model: str, variant: str, points: np.ndarray) -> tuple[np.ndarray, str]:
    """Triangles over the recorded bag points and how they were found: `boxes` (8 corners a
    part), `tet mesh (resolution R)` (the FEM generator re-run), or `convex hull`."""
    from astrobee_sim.render import box_surface, boundary_faces, hull_faces
    n = len(points)
    if model != "fem" and n % 8 == 0:
        return box_surface(points)[1], "boxes"
    if model == "fem":
        found = _fem_mesh(variant, points)
        if found is not None:
            return found
    return hull_faces(points), "convex hull"


def _fem_mesh(variant: str, points: np.ndarray) -> tuple[np.ndarray, str] | None:
    """The generated tet mesh with the recorded node count whose rest shape fits the points
    (bag frame) within 5 cm RMS: its boundary faces."""
    from astrobee import config
    from astrobee_sim.bags.base import handle_dirs
    from astrobee_sim.bags.mesh import bag_mesh
    from astrobee_sim.render import boundary_faces

    cfg = config.bags()
    try:
        handles = handle_dirs(variant or cfg["default"]["variant"])
    except Exception:  # noqa: BLE001 - unknown variant: no generated mesh
        return None
    sizes = [cfg["default"]["size"]] + [s["size"] for s in cfg["sizes"].values()]
    n = len(points)
    hl, hh = float(cfg.get("handle_length", 0.12)), float(cfg.get("handle_height", 0.04))
    for size in sizes:
        size = np.asarray(size, float)
        tried: set[int] = set()
        # grids of near-cubic cells over the spacings a 27..3000-node target can give
        for h in np.geomspace(0.01, float(size.max()), 160):
            grid = np.maximum(np.round(size / h).astype(int), 1) + 1
            res = int(np.prod(grid))
            if res in tried or res < 27 or res > 4 * n:
                continue
            tried.add(res)
            mesh = bag_mesh(size, handles, res, hl, hh)
            if len(mesh.nodes) != n:
                continue
            rest = mesh.nodes - mesh.nodes.mean(axis=0)
            got = points - points.mean(axis=0)
            if float(np.sqrt(np.mean(np.sum((rest - got) ** 2, axis=1)))) < 0.05:
                return boundary_faces(mesh.tets), f"tet mesh (resolution {res})"
    return None


# ---- scenes --------------------------------------------------------------------------------
def scene_at(rec: Recording, t: float, speed: float, t0: float):
    """The render.Scene of time t, and the first robot's direction of travel."""
    from astrobee_sim.render import Polyline, Scene, Surface
    sc = Scene()
    for tr in rec.robots.values():
        sc.robots.append(tr.at(t))
    first = next(iter(rec.robots.values()))
    vel = first.velocity(t)
    heading = vel if np.linalg.norm(vel) > 0.02 else _heading_from_path(rec, t, first)
    if rec.bag is not None or rec.mesh_local:
        sc.arm_deployed = True
        if rec.mesh_local and rec.mesh_faces is not None:
            k = max(int(np.searchsorted(rec.mesh_t, t, side="right")) - 1, 0)
            pts = rec.mesh_local[k]
            if rec.bag is not None:
                c, q = rec.bag.at(t)
                pts = c + rot.rotate(q, pts)
            sc.bag = Surface(pts, rec.mesh_faces)
    path = _latest(rec.paths, t)
    if path is not None:
        sc.lines.append(Polyline(path, PATH_RGB, 2))
    cands = _latest(rec.candidates, t, max_age=0.5)
    for c in cands or []:
        sc.lines.append(Polyline(c, CAND_RGB, 1))
    i = int(np.searchsorted(first.t, t, side="right"))
    if i >= 2:
        trail = np.vstack([first.pos[:i], first.at(t)[0]])
        sc.lines.append(Polyline(trail[:: max(1, len(trail) // 400)], TRAIL_RGB, 2))
    text = [f"t {t - t0:6.1f} s   playback x{speed:g}",
            f"speed {np.linalg.norm(vel):.3f} m/s"]
    if rec.deformation is not None and rec.bag_model in ("fem", "composite"):
        d = float(np.interp(t, *rec.deformation))
        text.append(f"cargo bag {rec.bag_model}: deformation {1000 * d:.0f} mm")
    elif rec.bag_model:
        text.append(f"cargo bag: {rec.bag_model}")
    sc.text = text
    return sc, heading


def _latest(samples: list, t: float, max_age: float | None = None):
    best = None
    for ts, v in samples:
        if ts <= t + 1e-9:
            best = (ts, v)
    if best is None:                # a plan made before the first pose: show it from the start
        return samples[0][1] if samples and max_age is None else None
    if max_age is not None and t - best[0] > max_age:
        return None
    return best[1]


def _heading_from_path(rec: Recording, t: float, track: Track) -> np.ndarray | None:
    """Direction to the robot's position 3 s later (at rest: towards where it will go)."""
    p0 = track.at(t)[0]
    for dt in (3.0, 10.0, 30.0):
        d = track.at(t + dt)[0] - p0
        if np.linalg.norm(d) > 0.05:
            return d
    return rot.rotate(track.at(t)[1], np.array([1.0, 0.0, 0.0]))


# ---- writing -------------------------------------------------------------------------------
@dataclass
class RenderResult:
    path: Path
    frames: int
    size: tuple[int, int]
    sim_seconds: float
    bag_surface: str


def render(bag_dir: str | os.PathLike, out: str | os.PathLike, *, fps: float = DEFAULT_FPS,
           speed: float = DEFAULT_SPEED, scale: float = 1.0,
           log_window: tuple[float, float] | None = None, start: float = 0.0,
           duration: float | None = None, title: str = "",
           progress: Callable[[int, int], None] | None = None,
           max_frames: int = MAX_FRAMES) -> RenderResult:
    """Render a recording to `out` (.mp4 through ffmpeg, .gif through Pillow). `speed` is sim
    seconds per video second; `start`/`duration` (sim s from the first pose) cut the flight;
    `scale` multiplies the default 896x384 frame; more than `max_frames` frames is refused."""
    from astrobee_sim.render import FlightRenderer, overview_camera
    if not all(math.isfinite(v) and v > 0 for v in (fps, speed, scale)):
        raise RenderError("--fps, --speed and --scale must be > 0")
    out = Path(out)
    kind = out.suffix.lower()
    if kind not in (".mp4", ".gif"):
        raise RenderError(f"output must end in .mp4 or .gif, got '{out.name}'")
    if not out.parent.is_dir():
        raise RenderError(f"output directory does not exist: {out.parent}")
    rec = read_recording(bag_dir, log_window)
    t_first, t_last = rec.span
    t0 = t_first + max(start, 0.0)
    t1 = t_last if duration is None else min(t_last, t0 + duration)
    if t1 < t0:
        raise RenderError(f"--start {start:g} s is past the end of the flight "
                          f"({t_last - t_first:.1f} s)")
    n = frame_count(t1 - t0, fps, speed, max_frames)
    times = t0 + np.arange(n) * speed / fps
    even = lambda v: max(16, int(round(v * scale / 16)) * 16)   # noqa: E731 - codec blocks
    fr = FlightRenderer((even(512), even(384)), (even(384), even(384)))
    pts = [tr.pos for tr in rec.robots.values()] + [p for _, p in rec.paths]
    ov = overview_camera(np.vstack(pts), aspect=1.0)
    sink = _Mp4(out, fr.size, fps) if kind == ".mp4" else _Gif(out, fps)
    try:
        for k, t in enumerate(times):
            scene, heading = scene_at(rec, float(t), speed, t_first)
            if title:
                scene.text.insert(0, title)
            sink.add(fr.render(scene, heading, ov))
            if progress:
                progress(k + 1, n)
        sink.close()
    except BaseException:
        sink.abort()
        raise
    finally:
        fr.close()
    return RenderResult(out, n, fr.size, float(t1 - t0), rec.mesh_source or "none")


def frame_count(seconds: float, fps: float, speed: float, max_frames: int = MAX_FRAMES) -> int:
    """Frames of a video of `seconds` of flight at `fps` and `speed` (sim s per video s): one
    for a zero-length flight; RenderError (one line) when it is not finite or more than
    max_frames."""
    if not (math.isfinite(seconds) and seconds >= 0 and fps > 0 and speed > 0):
        raise RenderError(f"no finite flight to render ({seconds:g} s at --fps {fps:g}, "
                          f"--speed {speed:g})")
    n = int(math.floor(seconds * fps / speed)) + 1
    if n > max_frames:
        raise RenderError(f"{seconds:.1f} s of flight at --speed {speed:g} and --fps {fps:g} "
                          f"is {n} frames, more than {max_frames}: cut it (--start, --duration) "
                          f"or raise --speed")
    return n


class _Mp4:
    """H.264 (yuv420p, plays everywhere) through the ffmpeg binary of imageio-ffmpeg."""

    def __init__(self, path: Path, size: tuple[int, int], fps: float):
        import imageio_ffmpeg
        self.path = path
        self.gen = imageio_ffmpeg.write_frames(str(path), size, fps=fps, codec="libx264",
                                               pix_fmt_out="yuv420p", quality=7,
                                               macro_block_size=16,
                                               output_params=["-loglevel", "error"])
        self.gen.send(None)

    def add(self, frame: np.ndarray) -> None:
        self.gen.send(np.ascontiguousarray(frame))

    def close(self) -> None:
        self.gen.close()

    def abort(self) -> None:
        try:
            self.gen.close()
        finally:
            self.path.unlink(missing_ok=True)


class _Gif:
    """Animated GIF through Pillow (frames kept until close: a GIF is meant to be short)."""

    def __init__(self, path: Path, fps: float):
        self.path, self.fps, self.frames = path, fps, []

    def add(self, frame: np.ndarray) -> None:
        from PIL import Image
        self.frames.append(Image.fromarray(frame).quantize(colors=128))

    def close(self) -> None:
        if self.frames:
            self.frames[0].save(self.path, save_all=True, append_images=self.frames[1:],
                                duration=int(round(1000 / self.fps)), loop=0)

    def abort(self) -> None:
        self.frames = []


# ---- a demo run's legs -----------------------------------------------------------------------
def render_demo_legs(run_dir: str | os.PathLike, bag_dir: str | os.PathLike | None = None,
                     **options: Any) -> list[Path]:
    """One video per leg of a run (runs/<t>/video_<scenario>.mp4, or video.mp4 for one leg),
    each leg cut from the recording by its wall-clock window in summary.json; the file name is
    noted in the leg's entry of summary.json. A leg that cannot be rendered (a failed leg with
    no usable pose, an empty window, too long a flight) gets `video_error`, one line, instead.
    Returns the videos written."""
    from astrobee_bringup.summary import write_json
    run_dir = Path(run_dir)
    bag_dir = Path(bag_dir) if bag_dir else run_dir / "bag"
    path = run_dir / "summary.json"
    data = json.loads(path.read_text())
    legs = data.get("legs", [])
    written = []
    for leg in legs:
        if leg.get("wall_t0") is None or leg.get("wall_t1") is None:
            continue
        name = "video.mp4" if len(legs) == 1 else f"video_{leg.get('scenario', len(written))}.mp4"
        window = (float(leg["wall_t0"]), float(leg["wall_t1"]))
        try:
            if not (math.isfinite(window[0]) and math.isfinite(window[1])
                    and window[1] > window[0]):
                raise RenderError(f"empty leg: wall-clock window {window[0]:.3f}-{window[1]:.3f}")
            render(bag_dir, run_dir / name, log_window=window,
                   title=str(leg.get("scenario", "")), **options)
        except (RenderError, ValueError, ArithmeticError) as exc:
            leg["video_error"] = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            continue
        leg["video"] = name
        written.append(run_dir / name)
    write_json(path, data)
    return written


# ---- the command -----------------------------------------------------------------------------
def main(argv: list[str]) -> int:
    """`astrobee bag render RECORDING -o flight.mp4 [--gif] ...`; bad arguments exit 1."""
    p = _Parser(
        prog="astrobee bag render",
        description="Render a recorded run to video, headless: chase camera + overview, "
                    "robot, cargo bag, planned path, controller candidates, time/speed.")
    p.add_argument("recording", help="rosbag2 directory (e.g. runs/<t>/bag)")
    p.add_argument("-o", "--output", help="output file (.mp4 or .gif; default flight.mp4, "
                   "flight.gif with --gif)")
    p.add_argument("--gif", action="store_true", help="write an animated GIF")
    p.add_argument("--fps", type=float, default=DEFAULT_FPS, help=f"video frames per second "
                   f"(default {DEFAULT_FPS})")
    p.add_argument("--speed", type=float, default=DEFAULT_SPEED,
                   help=f"sim seconds per video second (default {DEFAULT_SPEED:g})")
    p.add_argument("--scale", type=float, default=1.0, help="frame size factor (1 = 896x384)")
    p.add_argument("--start", type=float, default=0.0, help="sim seconds to skip")
    p.add_argument("--duration", type=float, help="sim seconds to render (default: all)")
    p.add_argument("--leg", type=int, help="render only leg N (0-based) of the run whose "
                   "summary.json sits beside the recording")
    try:
        a = p.parse_args(argv)
    except SystemExit as exc:                     # -h
        return 0 if exc.code == 0 else 1
    except RenderError as exc:
        return _fail(str(exc))
    out = Path(a.output or ("flight.gif" if a.gif else "flight.mp4"))
    if a.gif and out.suffix.lower() != ".gif":
        return _fail(f"--gif needs an output ending in .gif, got '{out.name}'")
    window, title = None, ""
    try:
        if a.leg is not None:
            window, title = _leg_window(Path(a.recording), a.leg)
        res = render(a.recording, out, fps=a.fps, speed=a.speed, scale=a.scale,
                     log_window=window, start=a.start, duration=a.duration, title=title)
    except RenderError as exc:
        return _fail(str(exc))
    except KeyboardInterrupt:
        return _fail("interrupted")
    print(f"{res.path}: {res.frames} frames {res.size[0]}x{res.size[1]}, "
          f"{res.sim_seconds:.1f} s of flight, cargo bag surface: {res.bag_surface}")
    return 0


class _Parser(argparse.ArgumentParser):
    """argparse whose errors are one line (raised, printed by main) instead of usage + exit 2."""

    def error(self, message: str):
        raise RenderError(message)


def _leg_window(bag: Path, leg: int) -> tuple[tuple[float, float], str]:
    summary = bag.resolve().parent / "summary.json"
    if not summary.is_file():
        raise RenderError(f"--leg needs {summary}")
    legs = json.loads(summary.read_text()).get("legs", [])
    if not 0 <= leg < len(legs):
        raise RenderError(f"--leg {leg}: the run has {len(legs)} leg(s)")
    entry = legs[leg]
    if entry.get("wall_t0") is None or entry.get("wall_t1") is None:
        raise RenderError(f"--leg {leg}: summary.json gives no time window for it")
    return (float(entry["wall_t0"]), float(entry["wall_t1"])), str(entry.get("scenario", ""))


def _fail(msg: str) -> int:
    print(f"astrobee bag render: {msg}", file=sys.stderr)
    return 1
