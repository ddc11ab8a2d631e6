"""`astrobee bag render`: a recorded run -> MP4 or GIF, headless (chase view + overview), or two
runs side by side (`--compare A B`: two recordings, or two legs of one, on one timeline with the
same overview camera, each column labelled).

Every robot of the leg and the cargo bag (its recorded surface, or its rest shape when no mesh
was recorded: render_tracks) are drawn at every frame, with the planned path, the controller's
candidates and the flown trail. The overlay gives the time, the robot's speed, the bag's swing
about the handle, its clearance to the walls, and contacts when they happen (the line turns red
and a red spot flashes at each contact point).

Swing angle (render_tracks.swing_angle): the angle between the direction from the handle to the
bag's centre now and at the leg's first bag sample (at rest), both in the body frame of the robot
holding handle 0; 0 deg: the bag hangs as at the start.

`render_demo_legs(run_dir)` writes one video per leg of a demo run (summary.json's wall-clock
windows). Reading the recording: render_tracks; drawing: astrobee_sim.render.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from astrobee import rotations as rot
from astrobee_bringup.render_tracks import (FlightTracks, RenderError, Track, _contacts_at,
                                            read_tracks, swing_angle)

DEFAULT_FPS = 10
DEFAULT_SPEED = 4.0                    # sim seconds per video second
MAX_FRAMES = 3000                      # a longer video is refused (5 min at 10 fps; a leg ~110)
PATH_RGB, TRAIL_RGB, CAND_RGB = (40, 210, 70), (80, 160, 255), (235, 80, 200)
CONTACT_RGB = (255, 30, 30)
FLASH = 0.3                            # sim s a contact's spot stays on (at least a frame's)


def _fmt_m(v: float) -> str:
    return f"{v:.2f} m" if math.isfinite(v) else "-"


# ---- scenes --------------------------------------------------------------------------------
def scene_at(rec: FlightTracks, t: float, speed: float, t0: float, flash: float = FLASH):
    """The render.Scene of time t (every robot, the cargo bag, paths, overlay), and the first
    robot's direction of travel."""
    from astrobee_sim.render import Polyline, Scene, Spot, Surface
    sc = Scene()
    order = rec.robot_order or list(rec.robots)
    for name in order:
        sc.robots.append(rec.robots[name].at(t))
    first = rec.robots[order[0]]
    vel = first.velocity(t)
    heading = vel if np.linalg.norm(vel) > 0.02 else _heading_from_path(rec, t, first)
    if rec.cargo is not None or rec.mesh_local:
        sc.arm_deployed = True
        if rec.mesh_local and rec.mesh_faces is not None:
            k = max(int(np.searchsorted(rec.mesh_t, t, side="right")) - 1, 0)
            pts = rec.mesh_local[k]
            if rec.cargo is not None:
                c, q = rec.cargo.at(t)
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
    k, robot_clear, bag_clear, touching = _contacts_at(rec, t, flash)
    if rec.cargo is not None:
        swing = swing_angle(rec, t)
        what = f"cargo bag ({rec.cargo_model})" if rec.cargo_model else "cargo bag"
        text.append(f"{what}: swing {math.degrees(swing):4.1f} deg" if swing is not None
                    else what)
        text.append(f"bag to wall {_fmt_m(bag_clear)}   robot to wall {_fmt_m(robot_clear)}")
    elif k >= 0:
        text.append(f"robot to wall {_fmt_m(robot_clear)}")
    colours: list = [None] * len(text)
    if touching:
        text.append(f"CONTACT ({len(touching)} point{'s' if len(touching) > 1 else ''})")
        colours.append(CONTACT_RGB)
        sc.spots = [Spot(np.asarray(p, float), CONTACT_RGB) for p in touching]
    sc.text, sc.text_rgb = text, colours
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


def _heading_from_path(rec: FlightTracks, t: float, track: Track) -> np.ndarray | None:
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
    cargo_surface: str


def render(recording: str | os.PathLike, out: str | os.PathLike, *, fps: float = DEFAULT_FPS,
           speed: float = DEFAULT_SPEED, scale: float = 1.0,
           log_window: tuple[float, float] | None = None, start: float = 0.0,
           duration: float | None = None, title: str = "",
           progress: Callable[[int, int], None] | None = None,
           max_frames: int = MAX_FRAMES) -> RenderResult:
    """Render a recording to `out` (.mp4 through ffmpeg, .gif through Pillow). `speed` is sim
    seconds per video second; `start`/`duration` (sim s from the first pose) cut the flight;
    `scale` multiplies the default 896x384 frame; more than `max_frames` frames is refused."""
    from astrobee_sim.render import FlightRenderer, overview_camera
    out, kind = _output(out, fps, speed, scale)
    rec = read_tracks(recording, log_window)
    t_first, t0, t1 = _cut(rec, start, duration)
    n = frame_count(t1 - t0, fps, speed, max_frames)
    times = t0 + np.arange(n) * speed / fps
    even = lambda v: max(16, int(round(v * scale / 16)) * 16)   # noqa: E731 - codec blocks
    fr = FlightRenderer((even(512), even(384)), (even(384), even(384)))
    ov = overview_camera(_extent(rec), aspect=1.0)
    flash = max(FLASH, speed / fps)

    def frame(t: float) -> np.ndarray:
        scene, heading = scene_at(rec, t, speed, t_first, flash)
        _title(scene, title)
        return fr.render(scene, heading, ov)

    try:
        _write(out, kind, fr.size, fps, [float(t) for t in times], frame, progress)
    finally:
        fr.close()
    return RenderResult(out, n, fr.size, float(t1 - t0), rec.mesh_source or "none")


@dataclass
class Source:
    """One side of a comparison: a recording, optionally one leg's wall-clock window, a label."""
    recording: Path
    window: tuple[float, float] | None = None
    label: str = ""


def render_compare(sources: list[Source], out: str | os.PathLike, *, fps: float = DEFAULT_FPS,
                   speed: float = DEFAULT_SPEED, scale: float = 1.0, start: float = 0.0,
                   duration: float | None = None,
                   progress: Callable[[int, int], None] | None = None,
                   max_frames: int = MAX_FRAMES) -> RenderResult:
    """Two (or more) recordings side by side on one timeline (sim s since each one's first
    pose; one that ends first holds its last frame), each a column of chase view over overview,
    the overview camera the same for all (framing every robot's track), each labelled."""
    from astrobee_sim.render import FlightRenderer, overview_camera
    if len(sources) < 2:
        raise RenderError("--compare needs two recordings (or two legs)")
    out, kind = _output(out, fps, speed, scale)
    recs = [read_tracks(s.recording, s.window) for s in sources]
    cuts = [_cut(r, start, duration) for r in recs]
    length = max(t1 - t0 for _, t0, t1 in cuts)
    n = frame_count(length, fps, speed, max_frames)
    even = lambda v: max(16, int(round(v * scale / 16)) * 16)   # noqa: E731 - codec blocks
    col = (even(448), even(320))
    frs = [FlightRenderer(col, col, stacked=True) for _ in recs]
    ov = overview_camera(np.vstack([_extent(r) for r in recs]), aspect=col[0] / col[1])
    flash = max(FLASH, speed / fps)

    def frame(k: float) -> np.ndarray:
        cols = []
        for s, rec, (t_first, t0, _), fr in zip(sources, recs, cuts, frs):
            scene, heading = scene_at(rec, t0 + k, speed, t_first, flash)
            _title(scene, s.label)
            cols.append(fr.render(scene, heading, ov))
            cols.append(np.full((cols[-1].shape[0], 4, 3), 255, np.uint8))   # divider
        return np.concatenate(cols[:-1], axis=1)

    size = (sum(fr.size[0] for fr in frs) + 4 * (len(frs) - 1), frs[0].size[1])
    if size[0] % 16:                          # codec blocks: pad the divider's share
        pad = 16 - size[0] % 16
        inner = frame
        frame = lambda k: np.pad(inner(k), ((0, 0), (0, pad), (0, 0)))  # noqa: E731
        size = (size[0] + pad, size[1])
    try:
        _write(out, kind, size, fps, [float(k) for k in np.arange(n) * speed / fps], frame,
               progress)
    finally:
        for fr in frs:
            fr.close()
    return RenderResult(out, n, size, float(length),
                        " | ".join(r.mesh_source or "none" for r in recs))


def _output(out: str | os.PathLike, fps: float, speed: float, scale: float) -> tuple[Path, str]:
    if not all(math.isfinite(v) and v > 0 for v in (fps, speed, scale)):
        raise RenderError("--fps, --speed and --scale must be > 0")
    out = Path(out)
    kind = out.suffix.lower()
    if kind not in (".mp4", ".gif"):
        raise RenderError(f"output must end in .mp4 or .gif, got '{out.name}'")
    if not out.parent.is_dir():
        raise RenderError(f"output directory does not exist: {out.parent}")
    return out, kind


def _cut(rec: FlightTracks, start: float, duration: float | None) -> tuple[float, float, float]:
    """(first pose time, first frame time, last frame time) of a recording cut by --start and
    --duration."""
    t_first, t_last = rec.span
    t0 = t_first + max(start, 0.0)
    t1 = t_last if duration is None else min(t_last, t0 + duration)
    if t1 < t0:
        raise RenderError(f"--start {start:g} s is past the end of the flight "
                          f"({t_last - t_first:.1f} s)")
    return t_first, t0, t1


def _extent(rec: FlightTracks) -> np.ndarray:
    """Points the overview frames: every robot's track and the plans."""
    return np.vstack([tr.pos for tr in rec.robots.values()] + [p for _, p in rec.paths])


def _title(scene: Any, title: str) -> None:
    if title:
        scene.text.insert(0, title)
        scene.text_rgb.insert(0, None)


def _write(out: Path, kind: str, size: tuple[int, int], fps: float, times: list[float],
           frame: Callable[[float], np.ndarray],
           progress: Callable[[int, int], None] | None) -> None:
    sink = _Mp4(out, size, fps) if kind == ".mp4" else _Gif(out, fps)
    try:
        for k, t in enumerate(times):
            sink.add(frame(t))
            if progress:
                progress(k + 1, len(times))
        sink.close()
    except BaseException:
        sink.abort()
        raise


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
def render_demo_legs(run_dir: str | os.PathLike, recording: str | os.PathLike | None = None,
                     **options: Any) -> list[Path]:
    """One video per leg of a run (runs/<t>/video_<scenario>.mp4, or video.mp4 for one leg),
    each leg cut from the recording by its wall-clock window in summary.json; the file name is
    noted in the leg's entry of summary.json. A leg that cannot be rendered (a failed leg with
    no usable pose, an empty window, too long a flight) gets `video_error`, one line, instead.
    Returns the videos written."""
    from astrobee_bringup.summary import write_json
    run_dir = Path(run_dir)
    recording = Path(recording) if recording else run_dir / "bag"
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
            render(recording, run_dir / name, log_window=window,
                   title=str(leg.get("scenario", "")), **options)
        except (RenderError, ValueError, ArithmeticError) as exc:
            leg["video_error"] = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            continue
        leg["video"] = name
        written.append(run_dir / name)
    write_json(path, data)
    return written


def render_demo_compare(run_dir: str | os.PathLike, scenarios: tuple[str, str],
                        recording: str | os.PathLike | None = None, name: str = "video_compare.mp4",
                        **options: Any) -> Path | None:
    """The two legs of a run flown in `scenarios` side by side (render_compare) into
    run_dir/name, noted in summary.json as `comparison` ({video, legs} or {error, legs}); None
    when the run has not both legs or they cannot be rendered."""
    from astrobee_bringup.summary import write_json
    run_dir = Path(run_dir)
    recording = Path(recording) if recording else run_dir / "bag"
    path = run_dir / "summary.json"
    data = json.loads(path.read_text())
    legs = {leg.get("scenario"): leg for leg in data.get("legs", [])}
    if not all(s in legs and legs[s].get("wall_t0") is not None
               and legs[s].get("wall_t1") is not None for s in scenarios):
        return None
    sources = [Source(recording, (float(legs[s]["wall_t0"]), float(legs[s]["wall_t1"])), s)
               for s in scenarios]
    note: dict[str, Any] = {"legs": list(scenarios)}
    out = None
    try:
        render_compare(sources, run_dir / name, **options)
        note["video"], out = name, run_dir / name
    except (RenderError, ValueError, ArithmeticError) as exc:
        note["error"] = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    data["comparison"] = note
    write_json(path, data)
    return out


# ---- the command -----------------------------------------------------------------------------
def main(argv: list[str]) -> int:
    """`astrobee bag render RECORDING -o flight.mp4 [--gif] ...` or `astrobee bag render
    --compare A B -o compare.mp4` (A, B: a recording, or RECORDING:N for its leg N); bad
    arguments exit 1 with one line."""
    p = _Parser(
        prog="astrobee bag render",
        description="Render a recorded run to video, headless: chase camera + overview, "
                    "every robot, the cargo bag (swing about the handle, clearance, contacts), "
                    "planned path, controller candidates; or two runs side by side (--compare).")
    p.add_argument("recording", nargs="?", help="rosbag2 directory (e.g. runs/<t>/bag)")
    p.add_argument("-o", "--output", help="output file (.mp4 or .gif; default flight.mp4, "
                   "flight.gif with --gif, compare.mp4 with --compare)")
    p.add_argument("--gif", action="store_true", help="write an animated GIF")
    p.add_argument("--fps", type=float, default=DEFAULT_FPS, help=f"video frames per second "
                   f"(default {DEFAULT_FPS})")
    p.add_argument("--speed", type=float, default=DEFAULT_SPEED,
                   help=f"sim seconds per video second (default {DEFAULT_SPEED:g})")
    p.add_argument("--scale", type=float, default=1.0, help="frame size factor (1 = 896x384; "
                   "912x640 with --compare)")
    p.add_argument("--start", type=float, default=0.0, help="sim seconds to skip")
    p.add_argument("--duration", type=float, help="sim seconds to render (default: all)")
    p.add_argument("--leg", type=int, help="render only leg N (0-based) of the run whose "
                   "summary.json sits beside the recording")
    p.add_argument("--compare", nargs=2, metavar=("A", "B"),
                   help="two recordings side by side on one timeline, same overview camera; "
                   "RECORDING:N takes leg N of a run (runs/<t>/bag:1 runs/<t>/bag:2)")
    p.add_argument("--labels", help="with --compare: the two columns' labels, comma-separated "
                   "(default: each leg's scenario, or the run folder's name)")
    try:
        a = p.parse_args(argv)
    except SystemExit as exc:                     # -h
        return 0 if exc.code == 0 else 1
    except RenderError as exc:
        return _fail(str(exc))
    if a.compare and (a.recording or a.leg is not None):
        return _fail("--compare takes its two recordings itself (no RECORDING, no --leg)")
    if not a.compare and not a.recording:
        return _fail("give a recording (or --compare A B)")
    default = "compare" if a.compare else "flight"
    out = Path(a.output or (f"{default}.gif" if a.gif else f"{default}.mp4"))
    if a.gif and out.suffix.lower() != ".gif":
        return _fail(f"--gif needs an output ending in .gif, got '{out.name}'")
    opts = dict(fps=a.fps, speed=a.speed, scale=a.scale, start=a.start, duration=a.duration)
    try:
        if a.compare:
            sources = [_source(x) for x in a.compare]
            if a.labels is not None:
                labels = [x.strip() for x in a.labels.split(",")]
                if len(labels) != len(sources):
                    raise RenderError(f"--labels needs {len(sources)} labels, got {len(labels)}")
                for s, lab in zip(sources, labels):
                    s.label = lab
            res = render_compare(sources, out, **opts)
        else:
            window, title = None, ""
            if a.leg is not None:
                window, title = _leg_window(Path(a.recording), a.leg)
            res = render(a.recording, out, log_window=window, title=title, **opts)
    except RenderError as exc:
        return _fail(str(exc))
    except (ValueError, ArithmeticError) as exc:  # a damaged record that decoded to nonsense
        return _fail(f"cannot render: {type(exc).__name__}: {exc}")
    except KeyboardInterrupt:
        return _fail("interrupted")
    print(f"{res.path}: {res.frames} frames {res.size[0]}x{res.size[1]}, "
          f"{res.sim_seconds:.1f} s of flight, cargo bag surface: {res.cargo_surface}")
    return 0


def _source(spec: str) -> Source:
    """A --compare argument: RECORDING or RECORDING:N (leg N of the run beside it)."""
    path, _, leg = spec.rpartition(":")
    if path and leg.isdigit() and not Path(spec).exists():
        window, scenario = _leg_window(Path(path), int(leg))
        return Source(Path(path), window, f"leg {leg}: {scenario}" if scenario else f"leg {leg}")
    recording = Path(spec)
    run = recording.resolve().parent.name if recording.name == "bag" else recording.name
    return Source(recording, None, run)


class _Parser(argparse.ArgumentParser):
    """argparse whose errors are one line (raised, printed by main) instead of usage + exit 2."""

    def error(self, message: str):
        raise RenderError(message)


def _leg_window(recording: Path, leg: int) -> tuple[tuple[float, float], str]:
    summary = recording.resolve().parent / "summary.json"
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
    one_line = " ".join(msg.split())        # a parser's message may span lines (YAML marks)
    print(f"astrobee bag render: {one_line}", file=sys.stderr)
    return 1
