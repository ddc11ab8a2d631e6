"""System identification of the MPC's rollout model A (astrobee_control.sysid) from each bag
model of the simulator, with the identification error on a held-out motion.

For each bag model: record one training excitation (seed 0) and one held-out excitation
(seed 1) of 5 random rest-to-rest moves each (~25 s) in Node 2 with the PD tracker (the FEM bag
at the simulator's default solver and resolution), then identify both kinds of model A on the
training run and report them on both runs:
- spring: the bag a point mass on a body-frame spring-damper (least squares), the robot's
  attitude taken from the reference;
- rigid_body: robot + bag one torque-limited rigid body (parameter: the mean bag offset).
Two errors, in mm: `body` = bag-centre error when the recorded robot motion drives the bag
model alone (beside the bag's own swing about its mean body-frame offset), and `horizon` =
bag-centre (and robot) world error of 5 s closed-loop rollouts with the PD law on the recorded
reference, started every 1 s from the recorded state (what the MPC relies on). The kind with
the lower held-out horizon error is written to config/reduced_models.yaml unless --no-write.

    .venv/bin/python bench/sysid_bag.py [--models fem,constraint,rigid] [--kinds spring,rigid_body]
                                        [--no-write] [--save PREFIX | --load PREFIX]
"""
from __future__ import annotations

import argparse
import pickle
import time
from pathlib import Path

import yaml

from astrobee import config, flight_modes
from astrobee_control import mass, sysid
from astrobee_sim.simulation import Simulation

FEM_RESOLUTION = None   # the simulator's default (config/bags.yaml: 400 target, 412 nodes)
SCENARIO = "node2_to_jem_bag"
KINDS = {"spring": lambda recs: sysid.fit([recs[0]]), "rigid_body": lambda recs: sysid.rigid_body([recs[0]])}


def record(model: str, save: str | None, load: str | None) -> tuple[list, int | None]:
    if load:
        return pickle.loads(Path(load).read_bytes())
    recs, nodes = [], None
    for seed in (0, 1):
        kw = {"bag_resolution": FEM_RESOLUTION} if model == "fem" else {}
        with Simulation(SCENARIO, bag_model=model, **kw) as sim:
            recs.append(sysid.record(sim, mass.robot(), sysid.excitation(seed, moves=5)))
            nodes = sim.bag_info().nodes if model == "fem" else None
    if save:
        Path(save).write_bytes(pickle.dumps((recs, nodes)))
    return recs, nodes


def identify(model: str, kinds: list[str], save: str | None = None,
             load: str | None = None) -> dict:
    t0 = time.perf_counter()
    recs, nodes = record(model, save, load)
    fm = flight_modes.get("nominal")
    print(f"{model} ({f'{nodes} nodes, ' if nodes else ''}record {time.perf_counter() - t0:.0f} s)")
    r = lambda x: round(float(x), 5)  # noqa: E731
    best = None
    for kind in kinds:
        t1 = time.perf_counter()
        handle = KINDS[kind](recs)
        t2 = time.perf_counter()
        train, held = sysid.error(handle, recs[0]), sysid.error(handle, recs[1])
        h_train, h_held = (sysid.horizon_error(handle, x, fm) for x in recs)
        print(f"  {kind:10s} fit {t2 - t1:5.1f} s | body: train RMS {1e3 * train['rms']:6.1f}  "
              f"held-out RMS {1e3 * held['rms']:6.1f} (max {1e3 * held['max']:6.1f})  swing RMS "
              f"{1e3 * held['swing_rms']:6.1f} | 5 s horizon, bag: train RMS "
              f"{1e3 * h_train['bag_rms']:6.1f}  held-out RMS {1e3 * h_held['bag_rms']:6.1f} "
              f"(max {1e3 * h_held['bag_max']:6.1f}), robot held-out RMS "
              f"{1e3 * h_held['robot_rms']:6.1f} mm")
        entry = {**handle.to_dict(), "bag_mass": r(recs[0].bag_mass),
                 "identification": {"scenario": SCENARIO, "train_seed": 0, "held_out_seed": 1,
                                    "moves": 5, "fem_nodes": nodes,
                                    "train_rms": r(train["rms"]), "held_out_rms": r(held["rms"]),
                                    "held_out_max": r(held["max"]),
                                    "held_out_swing_rms": r(held["swing_rms"]),
                                    "horizon": 5.0, "horizon_train_rms": r(h_train["bag_rms"]),
                                    "horizon_held_out_rms": r(h_held["bag_rms"]),
                                    "horizon_held_out_max": r(h_held["bag_max"]),
                                    "horizon_robot_held_out_rms": r(h_held["robot_rms"])}}
        if best is None or h_held["bag_rms"] < best[0]:
            best = (h_held["bag_rms"], entry)
    print(f"  kept: {best[1].get('kind', 'spring')}")
    return best[1]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--models", default="fem,constraint,rigid")
    ap.add_argument("--kinds", default="spring,rigid_body")
    ap.add_argument("--no-write", action="store_true")
    ap.add_argument("--save", default=None, help="pickle each model's recordings to SAVE.<model>")
    ap.add_argument("--load", default=None, help="use recordings pickled by --save (LOAD.<model>)")
    a = ap.parse_args()
    print("rollout model A identification (bag-centre errors in mm; target: below the bag's "
          "own swing, and small beside the MPC's 5 cm clearance margin over its 5 s horizon)")
    kinds = a.kinds.split(",")
    out = {m: identify(m, kinds, a.save and f"{a.save}.{m}", a.load and f"{a.load}.{m}")
           for m in a.models.split(",")}
    if not a.no_write:
        path = Path(config.config_dir()) / "reduced_models.yaml"
        old = yaml.safe_load(path.read_text()) if path.exists() else {}
        handles = {**(old or {}).get("handles", {}), **out}
        text = ("# Rollout model A of the MPC (astrobee_control/reduced_model.py) per bag model:\n"
                "# kind rigid_body (robot + bag one torque-limited rigid body) or a body-frame\n"
                "# spring-damper + drag (no kind), identified by bench/sysid_bag.py (errors in m on\n"
                "# a held-out motion; horizon_*: 5 s closed-loop rollouts). Regenerate with it.\n")
        path.write_text(text + yaml.safe_dump({"handles": handles}, sort_keys=False))
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
