"""The learned baseline: a residual policy on top of the PD tracker, trained with
Stable-Baselines3 (PPO) for a fixed budget on AstrobeeCargo-v0 with a reduced bag and the
realism knobs on, then evaluated beside PD alone on the same seeds. Prints one table.

Needs the optional extra (it pulls torch): `pip install -e .[rl]`. Not part of `make test` or
`make bench` (bench/run_all.py skips it: it trains for minutes).

    .venv/bin/python bench/train_residual.py [--steps 50000] [--episodes 10] [--bag constraint]
        [--realism astrobee] [--envs 2] [--save policy.zip]

Episodes: random hops of 0.5-2 m in the planner's safe set (random_start_goal), residual scaled
to 25% of the flight mode's limits; evaluation seeds 10_000.. are never trained on.
"""
from __future__ import annotations

import argparse
import math
import sys
import time

import numpy as np


def make_env(bag: str, realism: str, seed_offset: int = 0):
    import gymnasium as gym
    import astrobee_lab  # noqa: F401  (registers AstrobeeCargo-v0)
    return gym.make("AstrobeeCargo-v0", scenario="node2_to_jem_bag", bag_model=bag,
                    realism=realism, action_mode="residual", random_start_goal=True,
                    hop_distance=(0.5, 2.0))


def evaluate(env, policy, seeds: list[int]) -> dict[str, float]:
    """Success rate, contacts, clearance and RMS tracking error over the seeds; policy None
    flies PD alone (zero residual)."""
    rows = []
    for seed in seeds:
        obs, _ = env.reset(seed=seed)
        done = False
        while not done:
            action = (np.zeros(6, np.float32) if policy is None
                      else policy.predict(obs, deterministic=True)[0])
            obs, _, term, trunc, info = env.step(action)
            done = term or trunc
        m = env.unwrapped.flight.monitor.metrics()
        rows.append((bool(info["success"]), m["contacts"], m["min_robot_clearance"],
                     m["min_bag_clearance"], m["rms_position_error"], m["duration"]))
    a = np.array(rows, float)
    return {"success": a[:, 0].mean(), "contact_episodes": float((a[:, 1] > 0).sum()),
            "min_robot_clearance": float(np.nanmin(a[:, 2])),
            "min_bag_clearance": float(np.nanmin(a[:, 3])),
            "rms_error_mm": 1e3 * float(np.sqrt(np.nanmean(a[:, 4] ** 2))),
            "mean_duration": float(a[:, 5].mean())}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=50_000, help="training budget (env steps)")
    ap.add_argument("--episodes", type=int, default=10, help="evaluation episodes (seeds)")
    ap.add_argument("--bag", default="constraint", help="bag model (a reduced one: rigid, "
                                                          "constraint, composite)")
    ap.add_argument("--realism", default="astrobee", help="realism preset (config/realism.yaml)")
    ap.add_argument("--envs", type=int, default=2, help="parallel training envs (async workers)")
    ap.add_argument("--save", default="", help="save the trained policy here")
    a = ap.parse_args()
    try:
        from stable_baselines3 import PPO
        from stable_baselines3.common.env_util import make_vec_env
        from stable_baselines3.common.vec_env import SubprocVecEnv
    except ImportError:
        print("train_residual: stable-baselines3 is not installed (pip install -e .[rl]); skipped")
        return 0
    import torch
    torch.set_num_threads(1)      # the envs need the cores; the MLP is small
    seeds = list(range(10_000, 10_000 + a.episodes))
    env = make_env(a.bag, a.realism)
    t0 = time.perf_counter()
    pd = evaluate(env, None, seeds)
    t_pd = time.perf_counter() - t0

    venv = make_vec_env(lambda: make_env(a.bag, a.realism), n_envs=a.envs, seed=0,
                        vec_env_cls=SubprocVecEnv if a.envs > 1 else None)
    model = PPO("MlpPolicy", venv, n_steps=1024, batch_size=256, learning_rate=3e-4,
                gamma=0.995, ent_coef=0.0, policy_kwargs={"log_std_init": -2.0}, seed=0,
                device="cpu", verbose=0)
    t0 = time.perf_counter()
    model.learn(total_timesteps=a.steps)
    t_train = time.perf_counter() - t0
    venv.close()
    if a.save:
        model.save(a.save)
    t0 = time.perf_counter()
    learned = evaluate(env, model, seeds)
    t_eval = time.perf_counter() - t0
    env.close()

    print(f"\nresidual policy (PPO, {a.steps} steps, {t_train:.0f} s on {a.envs} workers) vs PD "
          f"alone; bag {a.bag}, realism {a.realism}, {a.episodes} random 0.5-2 m hops "
          f"(seeds {seeds[0]}..{seeds[-1]}, not trained on)")
    cols = ("success", "contact_episodes", "min_robot_clearance", "min_bag_clearance",
            "rms_error_mm", "mean_duration")
    print(f"{'controller':<14}" + "".join(f"{c:>21}" for c in cols))
    for name, r in (("PD", pd), ("PD + residual", learned)):
        print(f"{name:<14}" + "".join(f"{r[c]:>21.3f}" if not math.isnan(r[c]) else f"{'-':>21}"
                                      for c in cols))
    print(f"evaluation wall time: PD {t_pd:.0f} s, PD + residual {t_eval:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
