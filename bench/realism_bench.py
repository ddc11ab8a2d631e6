"""What the realism knobs cost the simulator's library loop (astrobee.realism presets).

The same PD-driven loop as sim_rtf.py (physics + the per-tick state queries sim_node makes),
rigid and constraint bags, with realism off / astrobee / harsh, runs interleaved so machine
load hits each alike; the figure is the median CPU real-time factor (sim s per CPU s).
Target: off costs nothing (the step loop is the old one when every knob is off); on, the
actuation noise, lag and pulses run in their own Python loop: within 1.5x of off.

    .venv/bin/python bench/realism_bench.py
"""
from __future__ import annotations

import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import astrobee_sim.simulation as simulation  # noqa: E402
from sim_rtf import library_rtf  # noqa: E402

PRESETS = (None, "astrobee", "harsh")
MODELS = ("rigid", "constraint")
REPEATS = 3
SECONDS = 8.0


def main() -> None:
    base_init = simulation.Simulation.__init__
    cpu: dict = {}
    try:
        for _ in range(REPEATS):
            for model in MODELS:
                for preset in PRESETS:
                    def init(self, *a, _p=preset, **kw):
                        kw["realism"] = _p
                        base_init(self, *a, **kw)
                    simulation.Simulation.__init__ = init
                    cpu.setdefault((model, preset), []).append(library_rtf(model, 0, SECONDS)[1])
    finally:
        simulation.Simulation.__init__ = base_init
    print("\nrealism knobs: library loop CPU real-time factor (median of "
          f"{REPEATS}, {SECONDS:g} s sim each, PD driving the bag)")
    print(f"{'model':<12}{'realism':<10}{'cpu RTF':>9}{'vs off':>8}  target")
    for model in MODELS:
        off = statistics.median(cpu[(model, None)])
        for preset in PRESETS:
            m = statistics.median(cpu[(model, preset)])
            target = "the loop of before (no extra cost)" if preset is None else ">= 0.67x of off"
            print(f"{model:<12}{preset or 'off':<10}{m:>8.1f}x{m / off:>7.2f}x  {target}")


if __name__ == "__main__":
    main()
