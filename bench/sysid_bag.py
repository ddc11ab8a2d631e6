"""System identification of the MPC's rollout model A (astrobee_control.sysid) from each bag
model of the simulator, with the identification error on a held-out motion.

For each bag model: record one training excitation (seed 0) and one held-out excitation
(seed 1) of 5 random rest-to-rest moves each (~25 s) in Node 2 with the PD tracker, fit the
handle spring-damper on the training run, report the bag-centre position error (RMS, max) on
both beside the bag's own swing (RMS excursion about its mean body-frame offset: the error of a
rigidly held bag). Writes config/reduced_models.yaml unless --no-write.

    .venv/bin/python bench/sysid_bag.py [--models fem,constraint,rigid] [--no-write]
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import yaml

from astrobee import config
from astrobee_control import mass, sysid
from astrobee_sim.simulation import Simulation

FEM_RESOLUTION = None   # the simulator's default (config/bags.yaml: 400 target, 412 nodes)
SCENARIO = "node2_to_jem_bag"


def identify(model: str, save: str | None = None, load: str | None = None) -> dict:
    t0 = time.perf_counter()
    recs = []
    nodes = None
    if load:
        import pickle
        recs, nodes = pickle.loads(Path(load).read_bytes())
    for seed in (0, 1)[len(recs):]:
        kw = {"bag_resolution": FEM_RESOLUTION} if model == "fem" else {}
        with Simulation(SCENARIO, bag_model=model, **kw) as sim:
            recs.append(sysid.record(sim, mass.robot(), sysid.excitation(seed, moves=5)))
            nodes = sim.bag_info().nodes if model == "fem" else None
    if save:
        import pickle
        Path(save).write_bytes(pickle.dumps((recs, nodes)))
    t1 = time.perf_counter()
    handle = sysid.fit([recs[0]])
    t2 = time.perf_counter()
    train, held = sysid.error(handle, recs[0]), sysid.error(handle, recs[1])
    print(f"{model:10s} {f'({nodes} nodes) ' if nodes else ''}record {t1 - t0:5.1f} s  fit {t2 - t1:5.1f} s  "
          f"train RMS {1e3 * train['rms']:6.1f} mm  held-out RMS {1e3 * held['rms']:6.1f} mm "
          f"(max {1e3 * held['max']:6.1f})  bag swing RMS {1e3 * held['swing_rms']:6.1f} mm")
    r = lambda x: round(float(x), 5)  # noqa: E731
    return {**handle.to_dict(), "bag_mass": r(recs[0].bag_mass),
            "identification": {"scenario": SCENARIO, "train_seed": 0, "held_out_seed": 1,
                               "moves": 5, "fem_nodes": nodes,
                               "train_rms": r(train["rms"]), "held_out_rms": r(held["rms"]),
                               "held_out_max": r(held["max"]),
                               "held_out_swing_rms": r(held["swing_rms"])}}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--models", default="fem,constraint,rigid")
    ap.add_argument("--no-write", action="store_true")
    ap.add_argument("--save", default=None, help="pickle each model's recordings to SAVE.<model>")
    ap.add_argument("--load", default=None, help="fit recordings pickled by --save (LOAD.<model>)")
    a = ap.parse_args()
    print("handle spring-damper identification (bag-centre position error; target: below the "
          "bag's own swing)")
    out = {m: identify(m, a.save and f"{a.save}.{m}", a.load and f"{a.load}.{m}")
           for m in a.models.split(",")}
    if not a.no_write:
        path = Path(config.config_dir()) / "reduced_models.yaml"
        old = yaml.safe_load(path.read_text()) if path.exists() else {}
        handles = {**(old or {}).get("handles", {}), **out}
        text = ("# Rollout model A of the MPC (astrobee_control/reduced_model.py): the bag's handle as a\n"
                "# body-frame spring-damper + drag, identified per bag model by bench/sysid_bag.py\n"
                "# (errors in m on a held-out motion). Regenerate with that script.\n")
        path.write_text(text + yaml.safe_dump({"handles": handles}, sort_keys=False))
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
