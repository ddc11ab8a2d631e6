"""Identify the pair model with the swing (astrobee_control.pair_model) on the FEM bag with its
default grasp (strap), and report held-out open-loop errors at 1, 2 and 5 s.

    python bench/oracle_sysid.py [--nodes 300] [--duration 40] [--write]

Flights: astrobee_lab.flight.Flight in-process, fast FEM bag (--nodes), PD holding the start
pose on truth while random body-wrench pushes (0.8-2.5 s each, up to the nominal box) are added;
train seeds 0, 1, held-out seeds 2, 3. The fit (sysid.fit_pair) uses 2 s windows of the train
seeds under the recorded wrench; --write stores the parameters in config/reduced_models.yaml
(`pair: fem:`), the one owner of the oracle's and the controllers' pair parameters.

    python bench/oracle_sysid.py --bumped [--write]

Bumped flights (the pair-control study's kind: Node 2 -> JEM, strap, truth state, PD, a 0.2 s
bump on the bag at the seeded U(10, 30) s; seeds 100-102 train at 10 / 7.5 / 5 N, 103-105
held out at the same sizes, none of the studies' seeds): the bag swings 50-106 deg against the
robot, where the pushed flights above swing 3 deg. The fit starts from the physical geometry,
frees the bag's grasp point (the pendulum's length) and bounds the joint's damping at 0.3 N m
s/rad (its time constant within the oracle's 0.25 s RK4 steps); windows start after the bump
ends. --write stores it as `pair: fem_bumped:`.
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


def recorded(fl, until: float, plan=()) -> sysid.PairRecording:
    """Fly the reset Flight `fl` to sim time `until`, its law's wrench plus the pushes of `plan`
    ((start, end, body wrench)) boxed per axis, recording each tick's truth and applied wrench."""
    lim = np.concatenate([fl.mode.max_force, fl.mode.max_torque])
    rows = []
    while fl.sim.time < until:
        t = fl.sim.time
        add = sum((w for a, b, w in plan if a <= t < b), np.zeros(6))
        p, q, v, w = fl._truth[fl.names[0]]
        b = fl._bag
        cmd = np.clip(fl._pending[fl.names[0]] + add, -lim, lim)
        rows.append((t, p, v, q, w, b.position, b.orientation, b.omega, cmd))
        fl.step(cmd, mode="replace")
    fl.close()
    t, p, v, q, w, bp, bq, bw, u = (np.array(c, float) for c in zip(*rows))
    return sysid.PairRecording(t, sysid.pair_states(p, v, q, w, bq, bw, u), bp, u)


def record(seed: int, nodes: int, duration: float) -> sysid.PairRecording:
    """PD holding the start pose while `pushes` push (the pushed identification flights)."""
    from astrobee_lab.flight import Flight
    fl = Flight("node2_to_jem_bag", seed=seed, controller="pd", bag_model="fem",
                bag_resolution=nodes, state_source="truth", plan=False,
                task={"time_limit": duration + 10})
    fl.reset()
    return recorded(fl, duration, pushes(seed, duration, np.concatenate([fl.mode.max_force,
                                                                          fl.mode.max_torque])))


def record_bumped(seed: int, nodes: int, magnitude: float, controller: str = "pd",
                  after: float = 75.0) -> tuple[sysid.PairRecording, float]:
    """A flight of the pair-control study's kind (Node 2 -> JEM, strap, truth state, a 0.2 s
    bump of `magnitude` N on the bag at the seeded U(10, 30) s), flown by `controller` for
    `after` s of sim: (the recording, the bump's end time)."""
    from astrobee_lab.flight import Flight
    realism = {"disturbances": [{"target": "bag", "magnitude": float(magnitude), "duration": 0.2,
                                 "t_min": 10.0, "t_max": 30.0}]}
    fl = Flight("node2_to_jem_fem_bag", seed=seed, controller=controller, fem_solver="fast",
                bag_resolution=nodes, state_source="truth", realism=realism,
                task={"time_limit": after + 10})
    fl.reset()
    (pulse,) = fl.sim.disturbance_schedule()
    return recorded(fl, after), float(pulse["time"]) + float(pulse["duration"])


def largest_swing(rec: sysid.PairRecording) -> float:
    """The largest angle (deg) between the bag's frame and the robot's over a recording."""
    c = np.clip(np.abs(np.sum(rec.x[:, pm.Q_R] * rec.x[:, pm.Q_B], 1)), 0, 1)
    return float(np.degrees(2 * np.arccos(c)).max())


def after_bump(rec: sysid.PairRecording, bump_end: float) -> sysid.PairRecording:
    """The recording from the end of its bump on (the model's rollouts know no bump)."""
    k = rec.t >= bump_end + 1e-9
    return sysid.PairRecording(rec.t[k], rec.x[k], rec.bag_position[k], rec.wrench[k])


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--nodes", type=int, default=300)
    ap.add_argument("--duration", type=float, default=40.0)
    ap.add_argument("--write", action="store_true")
    ap.add_argument("--cache", default="", help="npz of the recordings (made if missing)")
    ap.add_argument("--max-nfev", type=int, default=20, help="fit evaluations (0: no fit)")
    ap.add_argument("--bumped", action="store_true", help="identify on bumped flights (docstring)")
    a = ap.parse_args()
    if a.bumped:
        bumped(a.nodes, a.write, a.cache, a.max_nfev)
        return
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
    swing = max(largest_swing(r) for r in held)
    print(f"held-out: largest bag swing relative to the robot {swing:.1f} deg")
    print("| model | robot 1 s | bag 1 s | robot 2 s | bag 2 s | robot 5 s | bag 5 s |")
    print("|---|---|---|---|---|---|---|")
    errs = {}
    for name, p in rows.items():
        e = errs[name] = sysid.pair_errors(p, wheld, substeps=8 if name.startswith("rigid") else 2)
        print(f"| {name} | " + " | ".join(f"{1000 * e[k]:.1f}" for k in
              ("robot_1s", "bag_1s", "robot_2s", "bag_2s", "robot_5s", "bag_5s")) + " |")
    if a.write:
        pm.store("fem", fitted, {
            "scenario": "node2_to_jem_bag", "grasp": "strap (default)", "fem_nodes": a.nodes,
            "train_seeds": [0, 1], "held_out_seeds": [2, 3],
            "duration": round(float(recs[0].t[-1] - recs[0].t[0]), 1),
            "swing_max_deg": round(float(swing), 1),
            **{f"held_out_{k}": round(v, 5) for k, v in errs["pair (fitted)"].items()}})
        print("wrote pair: fem: to config/reduced_models.yaml")


# (seed, bump N): train, held out; none of the studies' seeds (0-39)
BUMPED_TRAIN = ((100, 10.0), (101, 7.5), (102, 5.0))
BUMPED_HELD = ((103, 10.0), (104, 7.5), (105, 5.0))


def bumped(nodes: int, write: bool, cache: str, max_nfev: int) -> None:
    """The pair model identified on bumped flights (module docstring), held-out errors beside
    the pushed flights' fit, the physical defaults and the rigid pair."""
    t0 = time.perf_counter()
    recs = {}
    z = np.load(cache) if cache and os.path.exists(cache) else None
    for seed, mag in BUMPED_TRAIN + BUMPED_HELD:
        if z is not None:
            rec = sysid.PairRecording(z[f"t{seed}"], z[f"x{seed}"], z[f"b{seed}"], z[f"u{seed}"])
            end = float(z[f"e{seed}"])
        else:
            rec, end = record_bumped(seed, nodes, mag)
        recs[seed] = (rec, end)
    if cache and z is None:
        np.savez(cache, **{f"{k}{s}": v for s, (r, e) in recs.items() for k, v in
                           (("t", r.t), ("x", r.x), ("b", r.bag_position), ("u", r.wrench), ("e", e))})
    print(f"recorded {len(recs)} bumped flights in {time.perf_counter() - t0:.0f} s")
    train = [after_bump(*recs[s]) for s, _ in BUMPED_TRAIN]
    held = [after_bump(*recs[s]) for s, _ in BUMPED_HELD]
    swing = [largest_swing(r) for r in held]
    print("held-out: largest bag swing relative to the robot " + ", ".join(f"{s:.0f}" for s in swing) + " deg")
    t1 = time.perf_counter()
    fitted = sysid.fit_pair(pm.PairParams(), sysid.pair_windows(train, 2.0, every=1.0),
                            max_nfev=max_nfev, free_bag=True, damping_max=0.3).with_(bag_drag=0.0)
    print(f"fit {time.perf_counter() - t1:.0f} s: {fitted.to_dict()}")
    rows = {"pair, physical defaults (PairParams())": pm.PairParams(),
            "pair, fitted on pushed flights (`pair: fem`)": pm.load("fem"),
            "**pair, fitted on bumped flights** (`pair: fem_bumped`)": fitted,
            "rigid pair (bumped fit's geometry, stiff joint)":
                fitted.with_(stiffness=(200.0, 200.0, 200.0), damping=(20.0, 20.0, 20.0))}
    wheld = sysid.pair_windows(held, 5.0, every=1.0)
    print("| model (held-out bumped seeds 103-105, after the bump) | robot 1 s | bag 1 s | robot 2 s "
          "| bag 2 s | robot 5 s | bag 5 s |")
    print("|---|---|---|---|---|---|---|")
    keys = ("robot_1s", "bag_1s", "robot_2s", "bag_2s", "robot_5s", "bag_5s")
    errs = {}
    for name, p in rows.items():
        e = errs[name] = sysid.pair_errors(p, wheld, substeps=8 if name.startswith("rigid") else 2)
        print(f"| {name} | " + " | ".join(f"{1000 * e[k]:.1f}" for k in keys) + " |")
    if write:
        e = errs["**pair, fitted on bumped flights** (`pair: fem_bumped`)"]
        pm.store("fem_bumped", fitted, {
            "scenario": "node2_to_jem_fem_bag", "grasp": "strap (default)", "controller": "pd",
            "fem_nodes": nodes, "train": [list(r) for r in BUMPED_TRAIN],
            "held_out": [list(r) for r in BUMPED_HELD], "windows_from": "bump end",
            "damping_max": 0.3, "swing_max_deg": [round(s, 1) for s in swing],
            **{f"held_out_{k}": round(v, 5) for k, v in e.items()}})
        print("wrote pair: fem_bumped: to config/reduced_models.yaml")


if __name__ == "__main__":
    main()
