"""Failed-leg video benchmark: `astrobee bag render` (render_recording.render, the default 896x384
frame, x4, 10 fps) on what a failed leg records: a robot flung 1e7 m off by an exploded
simulation, NaN poses, zero quaternions, a single pose, and a healthy 4 s hop for comparison.
Prints wall and CPU time and the frames written (or the one-line reason it was refused).

Usage: python bench/render_failed_leg_bench.py
Reference (before the fix, same machine): the robot flung 1e7 m off took over 60 s of CPU for
ONE chase frame (TinyRenderer's float32 turns its mesh next to the camera into screen-sized
triangles; 3e6 m: 10 ms); the interleaved stamps made 4 s of flight 904 s of timeline (2260
frames, minutes); a 4 s leg is 11 frames, ~1-2 s.
"""
from __future__ import annotations

import math
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "cli"))
from test_render_degenerate import Q, START, write_poses  # noqa: E402

from astrobee_bringup import render_recording as rb  # noqa: E402
from astrobee_bringup.render_tracks import RenderError  # noqa: E402


def cases() -> dict[str, list]:
    hop = [(0.1 * k, START + [0, -0.02 * k, 0], Q) for k in range(41)]
    return {
        "healthy hop, 4 s": hop,
        "robot flung to 1e7 m after 1 s": hop[:11] + [(1.0 + 0.1 * k, START + [0, 1e7, 0], Q)
                                                       for k in range(1, 31)],
        "NaN poses after 1 s": hop[:11] + [(1.0 + 0.1 * k, [math.nan] * 3, Q)
                                           for k in range(1, 31)],
        "zero quaternions": [(t, p, [0, 0, 0, 0]) for t, p, _ in hop],
        "one pose": hop[:1],
        "stamps of two clocks interleaved": [(t + (45.0 if k % 2 else 0.0), p, q)
                                             for k, (t, p, q) in enumerate(hop)],
    }


def main() -> int:
    print(f"{'recording':<34}{'wall s':>9}{'CPU s':>9}  result")
    with tempfile.TemporaryDirectory() as d:
        for name, samples in cases().items():
            bag = Path(d) / name.replace(" ", "_").replace(",", "")
            write_poses(bag, samples, log_s=[0.1 * k for k in range(len(samples))])
            t, c = time.perf_counter(), time.process_time()
            try:
                res = rb.render(bag, bag.with_suffix(".mp4"))
                out = f"{res.frames} frames, {res.sim_seconds:.1f} s of flight"
            except RenderError as exc:
                out = f"refused: {str(exc).split(': ', 1)[-1]}"
            print(f"{name:<34}{time.perf_counter() - t:>9.2f}{time.process_time() - c:>9.2f}  {out}")
    print("reference before the fix: the flung robot > 60 s CPU for ONE frame; the interleaved "
          "stamps 2260 frames")
    return 0


if __name__ == "__main__":
    sys.exit(main())
