"""What a video needs from a recording, on one timeline: the robots' tracks (/loc/truth/pose, or
/tf's `body` frames when no pose was recorded), the cargo bag's state track and mesh samples,
the scenario as the sim built it (/sim/scenario: the bag's model, size, node count), contacts
and clearances (/sim/contacts), the planned path and the controller's candidates. Read through
the one recording reader (astrobee_lab.recording).

The bag's surface: a mesh sample holds points only, so the faces are rebuilt: 8 corners per part
for the rigid, constraint and composite models (their /sim/bag/mesh is the parts' box corners);
for the FEM bag the tet mesh of astrobee_sim/bags/mesh.py is regenerated for the recorded node
count and its boundary triangles drawn; when no generated mesh matches, their convex hull. A leg
with a bag state but no mesh sample (the sim publishes the mesh at 10 Hz; a sim that skipped it)
gets the bag's rest shape from /sim/scenario (the FEM rest mesh, or the box) carried at the
state pose. Mesh samples are carried in the bag's frame and placed at the 62.5 Hz state pose of
each video frame, so the bag never lags the robot.

Time: a leg's sim clock restarts at each reset, so the timeline is the reference robot's pose
stamps made continuous across resets; every other topic is placed on it by its own stamp (or
its receive time).
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from astrobee import rotations as rot
from astrobee.msgconv import stamp_s

MAX_RESETS = 8                         # clock resets a recording's stamps may show (one a leg)
MAX_COORD = 1000.0                     # m: a sample farther from the origin is dropped (the ISS
# frame spans tens of metres; an exploded simulation's 1e7 m puts the robot's mesh, in the
# renderer's float32, into screen-sized triangles next to the camera: >30 s a frame, measured)
IDENTITY = np.array([0.0, 0.0, 0.0, 1.0])


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
class FlightTracks:
    """What a video needs from a recording, on one timeline (s): the robots', the cargo bag's."""
    robots: dict[str, Track] = field(default_factory=dict)
    cargo: Track | None = None
    cargo_model: str = ""
    cargo_variant: str = ""
    cargo_nodes: int = 0
    mesh_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    mesh_local: list[np.ndarray] = field(default_factory=list)    # bag frame (world if no state)
    mesh_faces: np.ndarray | None = None
    mesh_source: str = ""
    paths: list[tuple[float, np.ndarray]] = field(default_factory=list)
    candidates: list[tuple[float, list[np.ndarray]]] = field(default_factory=list)
    robot_order: list[str] = field(default_factory=list)           # the scenario's order
    cargo_size: np.ndarray | None = None                           # m, from /sim/scenario
    cargo_handles: list[np.ndarray] = field(default_factory=list)  # handle points, bag frame
    # /sim/contacts: times, robot and bag clearance (m, nan unknown), contact points per sample
    contact_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    robot_clearance: np.ndarray = field(default_factory=lambda: np.zeros(0))
    cargo_clearance: np.ndarray = field(default_factory=lambda: np.zeros(0))
    contact_points: list[np.ndarray] = field(default_factory=list)

    @property
    def span(self) -> tuple[float, float]:
        t = np.concatenate([tr.t for tr in self.robots.values()])
        return float(t.min()), float(t.max())


class RenderError(Exception):
    """A recording that cannot be rendered (message says why, one line)."""


# ---- reading -------------------------------------------------------------------------------
def _stamp(h: Any) -> float:
    return stamp_s(h.stamp)


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


def read_tracks(recording: str | os.PathLike,
                log_window: tuple[float, float] | None = None) -> FlightTracks:
    """Everything a video needs from a rosbag2 directory (optionally only the messages
    recorded in the wall-clock window `log_window`, seconds)."""
    from astrobee_lab.recording import Recording, RecordingError

    try:
        reader = Recording(recording)
        return _read(reader, recording, log_window)
    except RecordingError as exc:           # missing, unreadable, or a damaged chunk
        raise RenderError(str(exc)) from None


def _read(reader: Any, recording: str | os.PathLike,
          log_window: tuple[float, float] | None) -> FlightTracks:
    """read_tracks's work on the opened recording `reader`."""
    topics = reader.topics
    pose_topics = {n: n[: -len("/loc/truth/pose")].strip("/") for n, ty in topics.items()
                   if n.endswith("/loc/truth/pose") and ty.endswith("PoseStamped")}
    extra = [n for n, ty in topics.items()
             if n.endswith("/sim/bag/state") or n.endswith("/sim/bag/mesh")
             or n.endswith("/mob/planner/path") or n.endswith("/gnc/ctl/candidates")
             or n == "/sim/contacts"]
    use_tf = not pose_topics and "/tf" in topics
    wanted = list(pose_topics) + extra + (["/tf"] if use_tf else [])
    raw: dict[str, list[tuple[int, Any]]] = {n: [] for n in wanted}
    for m in reader.messages(wanted, log_window):
        raw[m.topic].append((m.log_ns, m.msg))
    scenario = _scenario(reader, log_window)
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
            raise RenderError(f"{recording}: none of the {recorded} robot poses recorded"
                              + (" in the selected window" if log_window else "")
                              + f" is usable (not finite, or farther than {MAX_COORD:g} m)")
        raise RenderError(f"{recording}: no robot pose recorded (/loc/truth/pose or /tf)"
                          + (" in the selected window" if log_window else ""))
    order = [r for r in (scenario.robots if scenario is not None else []) if r in poses]
    order += sorted(r for r in poses if r not in order)
    # the reference clock: the robot with the most samples (a robot of an earlier leg may
    # leave a few in this leg's window)
    ref = max(poses.values(), key=len)
    line = _Timeline([p[0] for p in ref], [p[1] for p in ref])
    rec = FlightTracks(robot_order=order)
    for name in order:
        rec.robots[name] = _track([(line.of(ln, st), x, q) for ln, st, x, q in poses[name]])
    _read_scenario(rec, scenario)
    _read_cargo_topics(rec, raw, line)
    _read_contacts(rec, raw.get("/sim/contacts", []), line)
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


def _read_cargo_topics(rec: FlightTracks, raw: dict, line: _Timeline) -> None:
    """The cargo bag's state track and its mesh samples in the bag frame (or its rest shape)."""
    states = [(ln, msg) for n in raw if n.endswith("/sim/bag/state") for ln, msg in raw[n]
              if _usable(_xyz(msg.pose.position), _xyzw(msg.pose.orientation))]
    meshes = [(ln, msg) for n in raw if n.endswith("/sim/bag/mesh") for ln, msg in raw[n]]
    if states:
        rec.cargo = _track([(line.of(ln, _stamp(m.header)), _xyz(m.pose.position),
                           _xyzw(m.pose.orientation)) for ln, m in states])
        rec.cargo_model, rec.cargo_variant = str(states[-1][1].model), str(states[-1][1].variant)
    times, local = [], []
    for ln, m in meshes:
        pts = np.asarray(m.positions, float).reshape(-1, 3)
        if len(pts) < 4 or (local and len(pts) != len(local[0])) or not _usable(pts):
            continue
        t = line.of(ln, _stamp(m.header))
        if rec.cargo is not None:
            c, q = rec.cargo.at(t)
            pts = rot.rotate(rot.conjugate(q), pts - c)
        times.append(t)
        local.append(pts)
    if not local:
        if rec.cargo is not None and rec.cargo_size is not None:    # no mesh sample: rest shape
            pts, faces, how = rest_surface(rec.cargo_model, rec.cargo_variant, rec.cargo_size,
                                           rec.cargo_nodes)
            rec.mesh_t, rec.mesh_local = np.zeros(1), [pts]
            rec.mesh_faces, rec.mesh_source = faces, f"{how} (rest shape: no mesh recorded)"
        return
    order = np.argsort(times, kind="stable")
    rec.mesh_t = np.asarray(times)[order]
    rec.mesh_local = [local[i] for i in order]
    rec.mesh_faces, rec.mesh_source = surface_faces(rec.cargo_model, rec.cargo_variant,
                                                    rec.mesh_local[0])


def surface_faces(model: str, variant: str, points: np.ndarray) -> tuple[np.ndarray, str]:
    """Triangles over the recorded bag points and how they were found: `boxes` (8 corners a
    part), `tet mesh (resolution R)` (the FEM generator re-run), or `convex hull`."""
    from astrobee_sim.render import box_surface, hull_faces
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
    got = points - points.mean(axis=0)
    for size in sizes:
        size = np.asarray(size, float)
        for res in _resolutions(size, n):
            mesh = bag_mesh(size, handles, res, hl, hh)
            if len(mesh.nodes) != n:
                continue
            rest = mesh.nodes - mesh.nodes.mean(axis=0)
            if float(np.sqrt(np.mean(np.sum((rest - got) ** 2, axis=1)))) < 0.05:
                return boundary_faces(mesh.tets), f"tet mesh (resolution {res})"
    return None


def _scenario(reader: Any, log_window: tuple[float, float] | None) -> Any | None:
    """The last /sim/scenario received before the window's end (latched: it may come before)."""
    if "/sim/scenario" not in reader.topics:
        return None
    end = log_window[1] * 1e9 if log_window else math.inf
    last = None
    for m in reader.messages(["/sim/scenario"]):
        if m.publish_ns <= end:
            last = m.msg
    return last


def _read_scenario(rec: FlightTracks, sc: Any | None) -> None:
    """The bag's model, variant, size, node count and handle points from /sim/scenario."""
    if sc is None or not bool(sc.carrying_bag):
        return
    rec.cargo_model, rec.cargo_variant = str(sc.bag_model), str(sc.bag_variant)
    rec.cargo_nodes = int(sc.bag_nodes)
    size = np.array([sc.bag_size.x, sc.bag_size.y, sc.bag_size.z], float)
    if np.all(np.isfinite(size)) and np.all(size > 0):
        rec.cargo_size = size
        rec.cargo_handles = handle_points(rec.cargo_variant, size)


def handle_points(variant: str, size: np.ndarray) -> list[np.ndarray]:
    """Outer grasp points of the bag's handles in the bag frame (as the sim's bag places them)."""
    from astrobee import config
    from astrobee_sim.bags.base import handle_dirs
    try:
        dirs = handle_dirs(variant or config.bags()["default"]["variant"])
    except Exception:  # noqa: BLE001 - unknown variant: no handle, no swing angle
        return []
    hh = float(config.bags().get("handle_height", 0.04))
    return [h * (size[int(np.argmax(np.abs(h)))] / 2 + hh) for h in dirs]


def rest_surface(model: str, variant: str, size: np.ndarray, nodes: int = 0
                 ) -> tuple[np.ndarray, np.ndarray, str]:
    """The bag's undeformed surface in its frame: the FEM rest mesh (the generator re-run for
    the scenario's node count) or the box of its size; (points, faces, how)."""
    from astrobee_sim.render import CORNERS, box_surface
    if model == "fem" and nodes > 0:
        from astrobee import config
        from astrobee_sim.bags.base import handle_dirs
        from astrobee_sim.bags.mesh import bag_mesh
        from astrobee_sim.render import boundary_faces
        cfg = config.bags()
        try:
            handles = handle_dirs(variant or cfg["default"]["variant"])
            for res in _resolutions(size, nodes):
                mesh = bag_mesh(size, handles, res, float(cfg.get("handle_length", 0.12)),
                                float(cfg.get("handle_height", 0.04)))
                if len(mesh.nodes) == nodes:
                    return (mesh.nodes - mesh.nodes.mean(axis=0), boundary_faces(mesh.tets),
                            f"tet mesh (resolution {res})")
        except Exception:  # noqa: BLE001 - fall back to the box
            pass
    pts, faces = box_surface(CORNERS * (np.asarray(size, float) / 2))
    return pts, faces, "box"


def _resolutions(size: np.ndarray, nodes: int) -> list[int]:
    """Target resolutions whose grid of near-cubic cells can give about `nodes` nodes."""
    out: list[int] = []
    for h in np.geomspace(0.01, float(np.max(size)), 160):
        grid = np.maximum(np.round(np.asarray(size) / h).astype(int), 1) + 1
        res = int(np.prod(grid))
        if 27 <= res <= 4 * nodes and res not in out:
            out.append(res)
    return sorted(out, key=lambda r: abs(r - nodes))


def _read_contacts(rec: FlightTracks, raw: list[tuple[int, Any]], line: "_Timeline") -> None:
    """Clearances and contact points of /sim/contacts on the timeline."""
    if not raw:
        return
    rows = sorted((line.of(ln, _stamp(m.header)), m) for ln, m in raw)
    rec.contact_t = np.array([t for t, _ in rows])
    neg = lambda v: float(v) if float(v) >= 0 else math.nan   # noqa: E731 - negative: unknown
    rec.robot_clearance = np.array([neg(m.robot_clearance) for _, m in rows])
    rec.cargo_clearance = np.array([neg(m.bag_clearance) for _, m in rows])
    rec.contact_points = [np.array([_xyz(c.position) for c in m.contacts], float).reshape(-1, 3)
                          for _, m in rows]


# ---- overlay figures ---------------------------------------------------------------------
def swing_angle(rec: FlightTracks, t: float) -> float | None:
    """The bag's swing about the handle at t (rad), None without a bag state or robot: the
    angle between the direction from the handle to the bag's centre now and at the leg's first
    bag sample (at rest), both in the body frame of the robot holding handle 0. The handle point
    is carried rigidly in that robot's body frame from the first sample (the arm holds it); a
    bag whose handles are unknown swings about the robot's centre instead."""
    if rec.cargo is None or not rec.robots:
        return None
    name = rec.robot_order[0] if rec.robot_order else next(iter(rec.robots))
    robot = rec.robots[name]
    t_rest = float(rec.cargo.t[0])
    p0, q0 = robot.at(t_rest)
    c0, qb0 = rec.cargo.at(t_rest)
    handle = (c0 + rot.rotate(qb0, rec.cargo_handles[0]) if rec.cargo_handles else p0)
    grip = rot.rotate(rot.conjugate(q0), handle - p0)             # in the robot's body frame
    rest = rot.rotate(rot.conjugate(q0), c0 - p0) - grip
    p, q = robot.at(t)
    c, _ = rec.cargo.at(t)
    now = rot.rotate(rot.conjugate(q), c - p) - grip
    n0, n1 = float(np.linalg.norm(rest)), float(np.linalg.norm(now))
    if n0 < 1e-6 or n1 < 1e-6:
        return None
    return float(math.acos(max(-1.0, min(1.0, float(rest @ now) / (n0 * n1)))))


def _contacts_at(rec: FlightTracks, t: float, flash: float) -> tuple[int, float, float, list]:
    """(index of the contact sample at t or -1, robot and bag clearance there (m, nan
    unknown), contact points of the samples in (t - flash, t])."""
    if not len(rec.contact_t):
        return -1, math.nan, math.nan, []
    k = int(np.searchsorted(rec.contact_t, t, side="right")) - 1
    if k < 0:
        return -1, math.nan, math.nan, []
    lo = int(np.searchsorted(rec.contact_t, t - flash, side="right"))
    pts = [p for i in range(lo, k + 1) for p in rec.contact_points[i]]
    return k, float(rec.robot_clearance[k]), float(rec.cargo_clearance[k]), pts
