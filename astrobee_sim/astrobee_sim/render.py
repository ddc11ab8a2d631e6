"""Headless renderer: a scene (robots, cargo bag surface, paths) + a camera -> RGB frames.

Solid geometry (the procedural ISS walls, the Astrobee URDF, the cargo bag as a triangle mesh)
is drawn by pybullet's built-in software rasteriser (TinyRenderer, `getCameraImage` in a DIRECT
client): it needs no display or GPU, has a real z-buffer and a perspective camera that can sit
inside a module. Measured on the 2-core VM: a 512x384 chase view inside Node 2 ~80 ms, a
384x384 overview ~15 ms. matplotlib's mplot3d drew the same walls in ~20 ms, but it only orbits
a bounding box (no camera inside the station, no near-plane clipping) and sorts whole polygons
(painter's algorithm), so walls and the robot overlap wrongly; it was not used.

Polylines (planned path, controller candidates, the flown trail) and the text overlay are drawn
afterwards with Pillow on the RGB image, projected with the same view/projection matrices (on
top of the geometry, so a path stays visible through a hatch). Nothing here reads a recording or
imports transport code: `astrobee_bringup.render_recording` feeds it from a recording, and an
environment's `render_mode="rgb_array"` can feed it from a live `Simulation`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .world import World, module_colour

UP = np.array([0.0, 0.0, -1.0])     # ISS frame: +z is nadir (the deck), so "up" on screen is -z
# Farther than this (m) from the origin nothing is drawn: TinyRenderer works in float32, and a
# robot flung 1e7 m off by an exploded simulation (a failed leg) turns its mesh next to the
# chase camera into screen-sized triangles: one frame took over a minute (3e6 m: 10 ms).
MAX_COORD = 1000.0


def drawable(points) -> bool:
    """Finite and within MAX_COORD of the origin (what the renderer can draw in time)."""
    a = np.asarray(points, float)
    return bool(np.all(np.isfinite(a)) and np.all(np.abs(a) <= MAX_COORD))

# A box's 8 corners in rigid_base's order (index 4*ix + 2*iy + iz), for half-extents 1.
CORNERS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)
# Faces of a box whose 8 corners are ordered as rigid_base._CORNERS (index 4*ix + 2*iy + iz).
BOX_FACES = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                      [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])


@dataclass
class Surface:
    """A triangle mesh in the world frame (the cargo bag): (N, 3) vertices, (F, 3) faces."""
    vertices: np.ndarray
    faces: np.ndarray
    rgba: tuple[float, float, float, float] = (0.95, 0.55, 0.15, 1.0)


@dataclass
class Polyline:
    points: np.ndarray                       # (N, 3) world frame
    rgb: tuple[int, int, int] = (40, 200, 60)
    width: int = 2


@dataclass
class Spot:
    """A filled circle over the picture at a world point (a contact flash), radius in pixels."""
    point: np.ndarray
    rgb: tuple[int, int, int] = (255, 30, 30)
    radius: int = 7


@dataclass
class Scene:
    """Everything drawn in one frame (world frame, SI units)."""
    robots: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list)  # (pos, quat xyzw)
    arm_deployed: bool = False
    bag: Surface | None = None
    lines: list[Polyline] = field(default_factory=list)
    spots: list[Spot] = field(default_factory=list)    # drawn on top, as the lines
    text: list[str] = field(default_factory=list)      # overlay lines, top left
    text_rgb: list[tuple[int, int, int] | None] = field(default_factory=list)  # per line


@dataclass
class Camera:
    eye: np.ndarray
    target: np.ndarray
    up: np.ndarray = field(default_factory=lambda: UP.copy())
    fov: float = 60.0          # vertical, degrees
    near: float = 0.05
    far: float = 60.0

    def matrices(self, width: int, height: int) -> tuple[list[float], list[float]]:
        """pybullet's (column-major) view and projection matrices."""
        from .pybullet_import import pybullet
        p = pybullet()
        view = p.computeViewMatrix([float(v) for v in self.eye], [float(v) for v in self.target],
                                   [float(v) for v in self.up])
        proj = p.computeProjectionMatrixFOV(self.fov, width / height, self.near, self.far)
        return list(view), list(proj)


def project(points: np.ndarray, view: list[float], proj: list[float], width: int,
            height: int, near: float) -> list[list[tuple[float, float]]]:
    """Pixel polylines of a 3-D polyline, cut where it passes behind the camera's near plane."""
    pts = np.asarray(points, float).reshape(-1, 3)
    if len(pts) == 0:
        return []
    M = np.asarray(proj, float).reshape(4, 4).T @ np.asarray(view, float).reshape(4, 4).T
    clip = np.c_[pts, np.ones(len(pts))] @ M.T
    w = clip[:, 3]
    runs: list[list[tuple[float, float]]] = []
    cur: list[tuple[float, float]] = []

    def px(c):
        return ((c[0] / c[3] + 1) * 0.5 * width, (1 - c[1] / c[3]) * 0.5 * height)

    for i in range(len(clip)):
        front = w[i] > near
        if i > 0 and front != (w[i - 1] > near):       # crosses the near plane: cut there
            a, b = clip[i - 1], clip[i]
            s = (near - a[3]) / (b[3] - a[3])
            cur.append(px(a + s * (b - a)))
            if not front:
                runs.append(cur)
                cur = []
        if front:
            cur.append(px(clip[i]))
    if cur:
        runs.append(cur)
    return [r for r in runs if len(r) >= 2]


def box_surface(corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Faces of K boxes given as (8K, 3) corners in rigid_base's corner order."""
    k = len(corners) // 8
    faces = (BOX_FACES[None, :, :] + 8 * np.arange(k)[:, None, None]).reshape(-1, 3)
    return np.asarray(corners, float), faces


def boundary_faces(tets: np.ndarray) -> np.ndarray:
    """Triangles of a tet mesh that belong to one tet only (its surface), outward wound for
    positively oriented tets."""
    t = np.asarray(tets)
    f = np.concatenate([t[:, [0, 2, 1]], t[:, [0, 1, 3]], t[:, [1, 2, 3]], t[:, [0, 3, 2]]])
    _, inv, cnt = np.unique(np.sort(f, axis=1), axis=0, return_inverse=True, return_counts=True)
    return f[cnt[inv.reshape(-1)] == 1]


def hull_faces(points: np.ndarray) -> np.ndarray:
    """Convex hull triangles of a point cloud (a node cloud whose mesh is unknown)."""
    from scipy.spatial import ConvexHull
    return ConvexHull(np.asarray(points, float)).simplices


def ceiling_slabs(world: World) -> np.ndarray:
    """Mask of the wall slabs on the zenith (-z) side of a free box: hidden in the overview,
    which looks down on the station from there (a cutaway)."""
    w, f = world.walls, world.free
    xy = (np.all(w[:, None, :2] < f[None, :, 3:5], axis=2)
          & np.all(w[:, None, 3:5] > f[None, :, :2], axis=2))
    touch = np.abs(w[:, None, 5] - f[None, :, 2]) < 1e-6
    return np.any(xy & touch, axis=1)


def _slab_colours(world: World) -> list[tuple[float, float, float]]:
    c = (world.walls[:, :3] + world.walls[:, 3:]) / 2
    fc = (world.free[:, :3] + world.free[:, 3:]) / 2
    near = np.linalg.norm(c[:, None, :] - fc[None, :, :], axis=2).argmin(axis=1)
    return [module_colour(world.modules[i]) for i in near]


class Renderer:
    """One pybullet DIRECT client holding the station's walls (all, or without the zenith-side
    slabs: `cutaway`), the robots and the cargo bag; `render` returns an (H, W, 3) uint8 image."""

    def __init__(self, world: World | None = None, cutaway: bool = False):
        from .pybullet_import import pybullet
        p = pybullet()
        self.p = p
        self.world = world or World.from_config()
        self.client = p.connect(p.DIRECT)
        w = self.world.walls
        hide = ceiling_slabs(self.world) if cutaway else np.zeros(len(w), bool)
        colours = _slab_colours(self.world)
        half = ((w[:, 3:] - w[:, :3]) / 2).tolist()
        pos = ((w[:, 3:] + w[:, :3]) / 2).tolist()
        for k in np.flatnonzero(~hide):
            vis = p.createVisualShape(p.GEOM_BOX, halfExtents=half[k],
                                      rgbaColor=[*colours[k], 1.0], physicsClientId=self.client)
            p.createMultiBody(0, -1, vis, basePosition=pos[k], physicsClientId=self.client)
        self.robots: list = []
        self._arm: bool | None = None
        self._bag_body: int | None = None

    # ---- scene --------------------------------------------------------------------------
    def _set_robots(self, robots, arm_deployed: bool) -> None:
        from .robot import Robot
        while len(self.robots) < len(robots):
            self.robots.append(Robot(self.client))
            self._arm = None
        for k, r in enumerate(self.robots):
            if k < len(robots) and drawable(robots[k][0]) and np.all(np.isfinite(robots[k][1])) \
                    and np.linalg.norm(robots[k][1]) > 1e-9:
                r.set_pose(robots[k][0], robots[k][1])
            else:                       # not in this scene (or not drawable): park it far away
                r.set_pose((500.0, 500.0, 500.0 + 10 * k), (0, 0, 0, 1))
        if self._arm != arm_deployed:
            for r in self.robots:
                r.deploy_arm(arm_deployed, instant=True)
            self._arm = arm_deployed

    def _set_bag(self, bag: Surface | None) -> None:
        p, c = self.p, self.client
        if self._bag_body is not None:
            p.removeBody(self._bag_body, physicsClientId=c)
            self._bag_body = None
        if bag is None or len(bag.faces) == 0 or not drawable(bag.vertices):
            return
        # a fresh visual mesh per frame (~0.3 ms for ~500 triangles): the FEM bag deforms
        vis = p.createVisualShape(p.GEOM_MESH, vertices=np.asarray(bag.vertices, float).tolist(),
                                  indices=np.asarray(bag.faces, int).reshape(-1).tolist(),
                                  rgbaColor=list(bag.rgba), physicsClientId=c)
        self._bag_body = p.createMultiBody(0, -1, vis, physicsClientId=c)

    def render(self, scene: Scene, camera: Camera, width: int, height: int,
               draw_text: bool = True) -> np.ndarray:
        """The scene seen by `camera` as an (height, width, 3) uint8 RGB image."""
        from PIL import Image, ImageDraw
        p = self.p
        self._set_robots(scene.robots, scene.arm_deployed)
        self._set_bag(scene.bag)
        lines = [ln for ln in scene.lines if drawable(ln.points)]
        spots = [sp for sp in scene.spots if drawable(sp.point)]
        if drawable(camera.eye) and drawable(camera.target) \
                and np.linalg.norm(np.subtract(camera.target, camera.eye)) > 1e-9:
            view, proj = camera.matrices(width, height)
            light = (-(np.asarray(camera.target) - np.asarray(camera.eye)) + 0.5 * (-UP)).tolist()
            img = p.getCameraImage(width, height, view, proj, renderer=p.ER_TINY_RENDERER,
                                   lightDirection=light, shadow=0,
                                   flags=p.ER_NO_SEGMENTATION_MASK, physicsClientId=self.client)
            rgb = np.asarray(img[2], dtype=np.uint8).reshape(height, width, 4)[:, :, :3]
        else:                                   # nowhere to look from: a blank picture
            rgb, lines, spots = np.full((height, width, 3), 30, np.uint8), [], []
        if not lines and not spots and not (draw_text and scene.text):
            return np.ascontiguousarray(rgb)
        im = Image.fromarray(np.ascontiguousarray(rgb))
        d = ImageDraw.Draw(im)
        for line in lines:
            for run in project(line.points, view, proj, width, height, camera.near):
                d.line(run, fill=tuple(line.rgb), width=line.width)
        for sp in spots:
            for run in project(np.vstack([sp.point, sp.point]), view, proj, width, height,
                               camera.near):
                (u, v), r = run[0], sp.radius
                d.ellipse([u - r, v - r, u + r, v + r], fill=tuple(sp.rgb), outline=(255, 255, 255))
        if draw_text and scene.text:
            draw_text_box(d, scene.text, max(10, height // 28), colours=scene.text_rgb)
        return np.asarray(im)

    def close(self) -> None:
        if self.client is not None:
            self.p.disconnect(physicsClientId=self.client)
            self.client = None


_FONTS: dict[int, object] = {}


def _font(size: int):
    from PIL import ImageFont
    f = _FONTS.get(size)
    if f is None:
        try:
            f = ImageFont.load_default(size=size)
        except TypeError:                                 # Pillow < 10.1: bitmap font only
            f = ImageFont.load_default()
        _FONTS[size] = f
    return f


def draw_text_box(draw, lines: list[str], size: int, xy=(6, 6),
                  colours: list[tuple[int, int, int] | None] | None = None) -> None:
    """Text (white, or the line's colour) on a dark box (top left)."""
    font = _font(size)
    x, y = xy
    widths = [draw.textlength(s, font=font) for s in lines]
    h = size + 4
    draw.rectangle([x - 4, y - 3, x + max(widths) + 6, y + h * len(lines) + 2], fill=(20, 20, 28))
    for k, s in enumerate(lines):
        rgb = (colours[k] if colours and k < len(colours) else None) or (255, 255, 255)
        draw.text((x, y + k * h), s, fill=tuple(rgb), font=font)


# ---- cameras --------------------------------------------------------------------------
def _unit(v: np.ndarray) -> np.ndarray | None:
    n = float(np.linalg.norm(v))
    return v / n if n > 1e-9 else None


def chase_camera(world: World, position: np.ndarray, heading: np.ndarray | None,
                 distance: float = 1.6, height: float = 0.6, side: float = 0.6,
                 fov: float = 65.0) -> Camera:
    """A camera behind the robot (against `heading`, its direction of travel), above it and
    to one side (a carried cargo bag trails the robot and would hide it from straight behind),
    pulled in towards the robot when that spot would be inside or behind a wall."""
    pos = np.asarray(position, float)
    h = _unit(np.asarray(heading, float)) if heading is not None else None
    if h is None or abs(float(h @ UP)) > 0.95:
        h = np.array([1.0, 0.0, 0.0]) if h is None else _unit(np.cross(UP, [1.0, 0, 0]))
    lateral = _unit(np.cross(UP, h))
    back = -h * distance + UP * height + (lateral * side if lateral is not None else 0.0)
    keep = world.keep_in
    for s in np.linspace(1.0, 0.2, 9):                    # the farthest spot still inside
        pts = pos + np.outer(np.linspace(0.1, 1.0, 8), back * s)
        ok = np.all(np.any(np.all((pts[:, None, :] >= keep[None, :, :3])
                                  & (pts[:, None, :] <= keep[None, :, 3:]), axis=2), axis=1))
        if ok:
            break
    eye = pos + back * s
    return Camera(eye=eye, target=pos + h * 0.4, fov=fov)


def overview_camera(points: np.ndarray, aspect: float = 1.0, fov: float = 50.0,
                    tilt: float = 0.35) -> Camera:
    """A camera above the station (zenith side) framing `points` (robot track, path), tilted
    a little so walls read as walls; the long horizontal extent runs across the image."""
    pts = np.asarray(points, float).reshape(-1, 3)
    lo, hi = pts.min(axis=0) - 1.0, pts.max(axis=0) + 1.0
    centre = (lo + hi) / 2
    span = hi - lo
    # screen "up" along the shorter horizontal axis, so the longer one runs across the image
    up = np.array([-1.0, 0.0, 0.0]) if span[1] >= span[0] else np.array([0.0, 1.0, 0.0])
    across, down = max(span[0], span[1]), min(span[0], span[1])
    half_v = math.radians(fov) / 2
    half_h = math.atan(math.tan(half_v) * aspect)
    dist = max(across / 2 / math.tan(half_h), down / 2 / math.tan(half_v)) * 1.05 + span[2] / 2
    back = _unit(UP + tilt * (-up))                       # from the zenith, a little behind
    return Camera(eye=centre + back * dist, target=centre, up=up, fov=fov,
                  near=0.1, far=dist + 40.0)


class FlightRenderer:
    """Chase view and overview of a scene side by side (or the chase view above the overview:
    `stacked`, a column of a comparison), with the text overlay: the frame renderer of
    `astrobee bag render`. The overview uses a cutaway station."""

    def __init__(self, chase_size=(512, 384), overview_size=(384, 384),
                 world: World | None = None, stacked: bool = False):
        self.world = world or World.from_config()
        self.chase_size, self.overview_size = tuple(chase_size), tuple(overview_size)
        self.stacked = bool(stacked)
        if not self.stacked and self.chase_size[1] != self.overview_size[1]:
            raise ValueError("chase and overview views must have the same height")
        if self.stacked and self.chase_size[0] != self.overview_size[0]:
            raise ValueError("stacked chase and overview views must have the same width")
        self.chase = Renderer(self.world)
        self.overview = Renderer(self.world, cutaway=True)

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) of a composed frame."""
        if self.stacked:
            return self.chase_size[0], self.chase_size[1] + self.overview_size[1]
        return self.chase_size[0] + self.overview_size[0], self.chase_size[1]

    def render(self, scene: Scene, heading: np.ndarray | None, overview: Camera) -> np.ndarray:
        """One (H, W, 3) uint8 frame: chase camera on the first robot | overview."""
        (cw, ch), (ow, oh) = self.chase_size, self.overview_size
        if scene.robots:
            cam = chase_camera(self.world, scene.robots[0][0], heading)
        else:
            cam = Camera(eye=overview.eye, target=overview.target, up=overview.up)
        left = self.chase.render(scene, cam, cw, ch)
        right = self.overview.render(scene, overview, ow, oh, draw_text=False)
        frame = np.concatenate([left, right], axis=0 if self.stacked else 1)
        if self.stacked:
            frame[ch:ch + 2, :] = 30                      # a thin divider
        else:
            frame[:, cw:cw + 2] = 30
        return frame

    def close(self) -> None:
        self.chase.close()
        self.overview.close()
