"""Standard visualization messages of the sim's scene, so any ROS viewer (Foxglove, RViz) shows
a run whole without the project's own message types: the cargo bag's surface as a
visualization_msgs/Marker TRIANGLE_LIST and the robots as markers in their body frames.

Transport-free: the functions take and fill message objects of the classes they are given
(sim_node passes roszen's), and never publish. The bag's triangles are found once per bag:
each part's box faces for the rigid-part models (their points are 8 corners per part), the
tet mesh's boundary for the FEM models, else the convex hull of the points.
"""
from __future__ import annotations

import struct
from typing import Any, Callable

import numpy as np

from astrobee import config

TRIANGLE_LIST, CUBE, ADD = 11, 1, 0
BAG_COLOUR = (0.85, 0.55, 0.2, 0.9)        # the cargo bag's tan, as the videos draw it


def bag_faces(bag: Any, points: np.ndarray) -> np.ndarray:
    """(F, 3) vertex indices of the surface of `bag` (a sim Bag) whose points are `points`."""
    from .render import boundary_faces, box_surface, hull_faces
    mesh = getattr(bag, "mesh", None)
    if mesh is not None and getattr(mesh, "tets", None) is not None \
            and len(mesh.nodes) == len(points):
        return boundary_faces(mesh.tets)
    if len(points) % 8 == 0 and getattr(bag, "model", "") in ("rigid", "constraint", "composite"):
        return box_surface(points)[1]
    try:
        return hull_faces(points)
    except Exception:  # noqa: BLE001 - too few or flat points: no surface rather than no sim
        return np.zeros((0, 3), dtype=np.int64)


_SENTINEL = (-1.2345678901234567e-300, 2.718281828459045e-299, -3.141592653589793e-298)
_SENTINEL_BYTES = struct.pack("<3d", *_SENTINEL)


class BagSurface:
    """The cargo bag's Marker (TRIANGLE_LIST, frame `world`), its faces cached per bag object
    (a sim reset builds a new bag)."""

    def __init__(self, marker_cls: Callable[[], Any], point_cls: Callable[..., Any]):
        self.marker_cls, self.point_cls = marker_cls, point_cls
        self._bag: Any = None
        self._faces: np.ndarray | None = None

    def faces(self, bag: Any, points: np.ndarray) -> np.ndarray:
        if bag is not self._bag or self._faces is None or \
                (len(self._faces) and self._faces.max() >= len(points)):
            self._bag, self._faces = bag, np.asarray(bag_faces(bag, points), dtype=np.int64)
        return self._faces

    def marker(self, bag: Any, points: np.ndarray, header: Any) -> Any:
        """A Marker of the bag's surface at `points` (world frame), stamped with `header`."""
        pts = np.asarray(points, dtype=float)
        tri = pts[self.faces(bag, pts).reshape(-1)]
        m = self._base(header)
        P = self.point_cls
        m.points = [P(x, y, z) for x, y, z in tri.tolist()]    # positional: 10x faster
        return m

    def _base(self, header: Any) -> Any:
        """The Marker without its points."""
        m = self.marker_cls()
        m.header.stamp = header.stamp
        m.header.frame_id = "world"
        m.ns, m.id, m.type, m.action = "cargo_bag", 0, TRIANGLE_LIST, ADD
        m.pose.orientation.w = 1.0
        m.scale.x = m.scale.y = m.scale.z = 1.0
        m.color.r, m.color.g, m.color.b, m.color.a = BAG_COLOUR
        return m

    def payload(self, bag: Any, points: np.ndarray, header: Any,
                serialize: Callable[[Any], bytes]) -> bytes:
        """The same Marker as CDR bytes (little-endian), ~10x cheaper than `serialize(marker)`:
        the Marker is serialised with one sentinel point and the triangle vertices are spliced
        in as one float64 array (a Point is three float64, 8-aligned, so what follows the
        sequence keeps its alignment whatever its length)."""
        pts = np.asarray(points, dtype=float)
        tri = pts[self.faces(bag, pts).reshape(-1)]
        m = self._base(header)
        m.points = [self.point_cls(*_SENTINEL)]
        data = serialize(m)
        i = data.index(_SENTINEL_BYTES)
        one = struct.pack("<I", 1)
        j = i - 4 if data[i - 4:i] == one else i - 8       # the count, then 0 or 4 pad bytes
        if data[j:j + 4] != one or data[:2] != b"\x00\x01":
            m.points = [self.point_cls(x, y, z) for x, y, z in tri.tolist()]
            return serialize(m)                              # not the layout expected: slow path
        return b"".join((data[:j], struct.pack("<I", len(tri)), data[j + 4:i],
                         np.ascontiguousarray(tri, dtype="<f8").tobytes(), data[i + 24:]))


def robot_markers(marker_cls: Callable[[], Any], frame: str, first_id: int = 0) -> list:
    """Boxes of one Astrobee (body and the two propulsion modules) in its body frame `frame`
    (the TF child the sim publishes), for viewers without a URDF display; latched once."""
    cfg = config.astrobee()
    bs, ps, py = cfg["body_size"], cfg["propulsion_module_size"], cfg["propulsion_module_y"]
    parts = [(bs, (0.0, 0.0, 0.0), (0.9, 0.9, 0.9)),
             (ps, (0.0, py, 0.0), (0.2, 0.4, 0.8)),
             (ps, (0.0, -py, 0.0), (0.2, 0.4, 0.8))]
    out = []
    for i, (size, xyz, rgb) in enumerate(parts):
        m = marker_cls()
        m.header.frame_id = frame
        m.ns, m.id, m.type, m.action = "robot", first_id + i, CUBE, ADD
        m.pose.position.x, m.pose.position.y, m.pose.position.z = (float(v) for v in xyz)
        m.pose.orientation.w = 1.0
        m.scale.x, m.scale.y, m.scale.z = (float(v) for v in size)
        m.color.r, m.color.g, m.color.b = rgb
        m.color.a = 1.0
        out.append(m)
    return out


def robot_description() -> str:
    """The Astrobee URDF as the sim first loads it (robot.Robot: body mass without the arm,
    nominal centre of mass and inertia), for the latched /robot_description."""
    from .robot import ARM_MASSES, urdf
    cfg = config.astrobee()
    body_mass = float(cfg["mass"]) - (sum(ARM_MASSES.values()) + ARM_MASSES["finger"])
    return urdf(body_mass, list(cfg["com_offset"]),
                (np.asarray(cfg["inertia"], dtype=float) * 0.9).tolist())
