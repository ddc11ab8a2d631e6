"""Fly one flight of a study again and print what the law saw and did, every so often.

The traces quoted in docs/results/pair_control_followup.md section 17 come from here, e.g. the
clamp's contact flight (gov_uwm, 5 N, seed 437) and a late-bump overshoot (seed 472):

    python studies/trace_flight.py studies/unwind_margin.yaml --label gov_uwm --block h30_clamp \
        --seed 437 --every 1
    python studies/trace_flight.py studies/unwind_margin_replication.yaml --label gov_uwm \
        --block h31_5 --seed 472 --from 20 --every 2

Columns (CSV): sim time; the attitude error to the reference (rad); the position error (m); the
robot's velocity (m/s, world); the bag's least wall clearance (m) and contact samples; the
commanded body wrench (N, N m). For pair_gov carrying a bag also the law's predicted clearance
(m; the clearance weight is (clearance / it)^2) and the position loop's wanted body force (N),
which the allocation bends or clips into the wrench.
"""
from __future__ import annotations

import argparse
import csv
import sys
from typing import Iterator

import numpy as np

from astrobee import rotations as rot
from astrobee_lab.flight import Flight
from astrobee_lab.study.spec import StudyError, build_scenario, load_study, task_keywords

WRENCH = ("fx", "fy", "fz", "tx", "ty", "tz")
FIELDS = ("t", "attitude_error", "position_error", "vx", "vy", "vz", "bag_clearance", "contacts",
          *WRENCH, "predicted_clearance", "want_fx", "want_fy", "want_fz")


def select(study_path: str, label: str, seed: int, block: str | None = None) -> dict:
    """The spec of the study's flight with this controller label and seed (in `block`; needed
    only when the label flies that seed in several blocks)."""
    st = load_study(study_path)
    found = [f for f in st.flights if f.label == label and f.spec["seed"] == seed
             and (block is None or f.block == block)]
    where = f" in block {block!r}" if block is not None else ""
    if not found:
        raise StudyError(f"study {study_path}: no flight with label {label!r} and seed {seed}"
                         f"{where}")
    if len(found) > 1:
        raise StudyError(f"study {study_path}: label {label!r} flies seed {seed} in blocks "
                         f"{', '.join(f.block for f in found)}: name one with --block")
    return found[0].spec


def trace(spec: dict, every: float, start: float = 0.0, until: float = float("inf"),
          verdict: dict | None = None) -> Iterator[dict]:
    """One row every `every` s of sim time in [start, until], and every tick with a contact;
    `verdict` (if given) gets the flight's success and cause once it ends."""
    with Flight(build_scenario(spec), seed=spec["seed"], controller=spec["controller"],
                controller_params=spec["params"], state_source=spec.get("state_source", "ekf"),
                task=task_keywords(spec) or None) as f:
        f.reset()
        n = f.names[0]
        gov = getattr(f.laws[n], "pd", None)
        seen = {}
        if gov is not None and hasattr(gov, "predicted_clearance"):
            step = gov.step

            def recorded(state, ref, dt):      # the position loop's wanted force, as it steps
                out = step(state, ref, dt)
                seen.update(state=state, ref=ref, want=gov.figures()[0] * np.asarray(out.accel))
                return out
            gov.step = recorded
        last = -np.inf
        while not f.finished():
            obs, s = f.step()
            if s.t > until:
                break
            if s.t < start or (s.t - last < every and s.contacts == 0):
                continue
            last = s.t
            ro = obs.robots[n]
            row = {"t": round(s.t, 2),
                   "attitude_error": round(rot.angle_between(ro.state.orientation,
                                                             ro.reference.orientation), 3),
                   "position_error": round(float(np.linalg.norm(
                       np.asarray(ro.reference.position) - ro.state.position)), 3),
                   **{k: round(float(v), 3) for k, v in zip(("vx", "vy", "vz"),
                                                            ro.state.velocity)},
                   "bag_clearance": round(s.bag_clearance, 3), "contacts": s.contacts,
                   **{k: round(float(v), 3) for k, v in zip(WRENCH, ro.nominal)}}
            if seen and gov.bag is not None and gov.bag.mass > 0:
                row["predicted_clearance"] = round(
                    gov.predicted_clearance(seen["state"], seen["ref"]), 3)
                row.update({k: round(float(v), 3)
                            for k, v in zip(("want_fx", "want_fy", "want_fz"), seen["want"])})
            yield row
        if verdict is not None:
            r = f.result(0.0, 0.0)
            verdict.update(success=r.success, cause=r.cause)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("study", help="the study YAML the flight belongs to")
    ap.add_argument("--label", required=True, help="its controller label")
    ap.add_argument("--block", help="its block (when the label flies the seed in several)")
    ap.add_argument("--seed", type=int, required=True)
    ap.add_argument("--every", type=float, default=1.0, help="s of sim time between rows")
    ap.add_argument("--from", dest="start", type=float, default=0.0, help="first sim time (s)")
    ap.add_argument("--until", type=float, default=float("inf"), help="last sim time (s)")
    a = ap.parse_args(argv)
    if not a.every > 0:
        ap.error(f"--every must be > 0, got {a.every}")
    try:
        spec = select(a.study, a.label, a.seed, a.block)
    except (OSError, StudyError) as e:
        print(f"trace_flight: {e}", file=sys.stderr)
        return 2
    w = csv.DictWriter(sys.stdout, FIELDS)
    w.writeheader()
    verdict: dict = {}
    for row in trace(spec, a.every, a.start, a.until, verdict):
        w.writerow(row)
        sys.stdout.flush()
    if verdict:
        print(f"trace_flight: {'success' if verdict['success'] else 'failed'}: "
              f"{verdict['cause']}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
