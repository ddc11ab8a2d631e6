"""Identify the pair model with the swing (astrobee_control.pair_model) on the FEM bag with its
default grasp (strap), and report held-out open-loop errors at 1, 2 and 5 s.

    python bench/oracle_sysid.py [--nodes 300] [--duration 40] [--write]

Flights: astrobee_lab.flight.Flight in-process, fast FEM bag (--nodes), PD holding the start
pose on truth while random body-wrench pushes (0.8-2.5 s each, up to the nominal box) are added;
train seeds 0, 1, held-out seeds 2, 3. The fit (sysid.fit_pair) uses 2 s windows of the train
seeds under the recorded wrench; --write stores the parameters in config/reduced_models.yaml
(`pair: fem:`), the one owner of the oracle's and the controllers' pair parameters.
"""
from __future__ import annotations

import argparse
import os
import time

import numpy as np

from astrobee import rotations as rot
from astrobee_control import pair_model as pm
from astrobee_control import sysid


def pushes(seed: int, duration: float, lim: np.ndarray) -> list[tuple[float, float, np.ndarray]]:
    """(start, end, body wrench) pushes: a random wrench within 60% of the box every few s."""
    rng = np.random.default_rng(1000 + seed)
    out, t = [], 1.0
    while t < duration - 1.0:
        d = float(rng.uniform(0.8, 2.5))
        out.append((t, t + d, rng.uniform(-0.6, 0.6, 6) * lim))
        t += d + float(rng.uniform(0.5, 3.0))
    return out


def record(seed: int, nodes: int, duration: float) -> sysid.PairRecording:
    from astrobee_lab.flight import Flight
    fl = Flight("node2_to_jem_bag", seed=seed, controller="pd", bag_model="fem",
                bag_resolution=nodes, state_source="truth", plan=False,
                task={"time_limit": duration + 10})
    fl.reset()
    lim = np.concatenate([fl.mode.max_force, fl.mode.max_torque])
    plan = pushes(seed, duration, lim)
    rows = []
    while fl.sim.time < duration:
        t = fl.sim.time
        add = sum((w for a, b, w in plan if a <= t < b), np.zeros(6))
        p, q, v, w = fl._truth[fl.names[0]]
        b = fl._bag
        cmd = np.clip(fl._pending[fl.names[0]] + add, -lim, lim)
        rows.append((t, p, v, q, w, b.position, b.orientation, b.omega, cmd))
        fl.step(cmd, mode="replace")
    fl.close()
    t, p, v, q, w, bp, bq, bw, u = (np.array(c, float) for c in zip(*rows))
    x = sysid.pair_states(p, v, q, w, bq, bw, u)
    return sysid.PairRecording(t, x, bp, u)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--nodes", type=int, default=300)
    ap.add_argument("--duration", type=float, default=40.0)
    ap.add_argument("--write", action="store_true")
    ap.add_argument("--cache", default="", help="npz of the recordings (made if missing)")
    ap.add_argument("--max-nfev", type=int, default=20, help="fit evaluations (0: no fit)")
    a = ap.parse_args()
    t0 = time.perf_counter()
    if a.cache and os.path.exists(a.cache):
        z = np.load(a.cache)
        recs = {s: sysid.PairRecording(z[f"t{s}"], z[f"x{s}"], z[f"b{s}"], z[f"u{s}"]) for s in range(4)}
    else:
        recs = {s: record(s, a.nodes, a.duration) for s in (0, 1, 2, 3)}
        if a.cache:
            np.savez(a.cache, **{f"{k}{s}": getattr(r, f) for s, r in recs.items()
                                 for k, f in (("t", "t"), ("x", "x"), ("b", "bag_position"), ("u", "wrench"))})
    print(f"recorded 4 x {recs[0].t[-1] - recs[0].t[0]:.0f} s in {time.perf_counter() - t0:.0f} s")
    train, held = [recs[0], recs[1]], [recs[2], recs[3]]
    rest = np.mean([np.einsum("tji,tj->ti", pm.rotation(r.x[:, pm.Q_R]),
                              r.bag_position - r.x[:, pm.P_R]).mean(0) for r in train], 0)
    base = pm.load("fem")
    g = np.asarray(base.grasp_robot)
    base = base.with_(grasp_bag=tuple(g - rest))
    wtrain = sysid.pair_windows(train, 2.0, every=1.0)
    t1 = time.perf_counter()
    fitted = sysid.fit_pair(base, wtrain, max_nfev=a.max_nfev) if a.max_nfev > 0 else base
    # the fit puts ~4.9 N s/m of drag on the bag's velocity; no external force takes momentum
    # from the FEM bag (measured: held-out errors equal or lower without it), and the oracle must
    # not get free damping of a bump's momentum: kept at 0
    fitted = fitted.with_(bag_drag=0.0)
    print(f"fit {time.perf_counter() - t1:.0f} s: {fitted.to_dict()}")
    rigid = fitted.with_(stiffness=(200.0, 200.0, 200.0), damping=(20.0, 20.0, 20.0))
    wheld = sysid.pair_windows(held, 5.0, every=1.0)
    rows = {"pair (strap figures)": base, "pair (fitted)": fitted, "rigid pair (same code, stiff joint)": rigid}
    swing = max(np.degrees(2 * np.arccos(np.clip(np.abs(np.sum(r.x[:, pm.Q_R] * r.x[:, pm.Q_B], 1)), 0, 1))).max()
                for r in held)
    print(f"held-out: largest bag swing relative to the robot {swing:.1f} deg")
    print("| model | robot 1 s | bag 1 s | robot 2 s | bag 2 s | robot 5 s | bag 5 s |")
    print("|---|---|---|---|---|---|---|")
    errs = {}
    for name, p in rows.items():
        e = errs[name] = sysid.pair_errors(p, wheld, substeps=8 if name.startswith("rigid") else 2)
        print(f"| {name} | " + " | ".join(f"{1000 * e[k]:.1f}" for k in
              ("robot_1s", "bag_1s", "robot_2s", "bag_2s", "robot_5s", "bag_5s")) + " |")
    if a.write:
        from astrobee import config
        import yaml
        path = config.config_dir() / "reduced_models.yaml"
        data = yaml.safe_load(path.read_text())
        d = fitted.to_dict()
        d["identification"] = {"scenario": "node2_to_jem_bag", "grasp": "strap (default)",
                               "fem_nodes": a.nodes, "train_seeds": [0, 1], "held_out_seeds": [2, 3],
                               "duration": round(float(recs[0].t[-1] - recs[0].t[0]), 1), "swing_max_deg": round(float(swing), 1),
                               **{f"held_out_{k}": round(v, 5) for k, v in errs["pair (fitted)"].items()}}
        data.setdefault("pair", {})["fem"] = d
        path.write_text(path.read_text().split("\npair:")[0].rstrip() + "\n" +
                        yaml.safe_dump({"pair": data["pair"]}, sort_keys=False))
        print("wrote", path)


if __name__ == "__main__":
    main()
