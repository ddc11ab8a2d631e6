"""A lockstep launch is deterministic for a seed: two `astrobee launch
cargo_transport` runs of the same short hop with the same seed record identical
/loc/truth/pose streams (every stamp and pose, start to end, read from the two recordings);
another seed (the hop has initial position noise) records another flight.

The sim starts paused, the mission resets it once the graph is ready, hands the segment over
at a fixed sim time and runs the sim in chunks that end at ticks the flight fixes
(mission --handover, sim_node start_paused)."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from roszen.testing import free_port

pytestmark = [pytest.mark.graph, pytest.mark.slow]
ROOT = Path(__file__).resolve().parents[2]

pytest.importorskip("astrobee_sim.sim_node")

Q = [0.0, 0.0, -0.7071067811865476, 0.7071067811865476]
HOP = {"description": "hop in Node 2 with a noisy start (determinism tests)",
       "flight_mode": "nominal", "initial_position_noise": 0.01,
       "robots": [{"name": "", "position": [10.95, 0.4, 4.84], "orientation": Q}],
       "bag": None,
       "goal": {"position": [10.95, -0.2, 4.84], "orientation": Q}}


@pytest.fixture(scope="module")
def config_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("det") / "config"
    shutil.copytree(ROOT / "config", d)
    (d / "scenarios" / "det_hop.yaml").write_text(yaml.safe_dump(HOP))
    return d


def launch(run: Path, config_dir: Path, seed: int) -> dict:
    """One whole launch (router, sim, planner, controller, recorder, mission); its summary."""
    env = dict(os.environ, ASTROBEE_CONFIG_DIR=str(config_dir), PYTHONUNBUFFERED="1")
    env.pop("ZENOH_CONFIG_OVERRIDE", None)
    # lockstep_timeout: a loaded machine must never make the sim step on without a command
    proc = subprocess.run(
        [sys.executable, "-m", "astrobee_bringup.cli", "launch", "cargo_transport",
         "scenario:=det_hop", f"seed:={seed}", "lockstep_timeout:=60", "video:=false",
         "--port", str(free_port()), "--run-dir", str(run)],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, env=env,
        text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-3000:]
    return json.loads((run / "summary.json").read_text())


def poses(bag: Path) -> tuple[np.ndarray, np.ndarray]:
    """Every /loc/truth/pose of a recording: stamps (ns) and [x y z qx qy qz qw], in order."""
    from roszen import typestore
    from roszen.bag.reader import BagReader
    stamps, values = [], []
    for m in BagReader(bag).messages(["/loc/truth/pose"]):
        msg = typestore.deserialize(m.data, m.topic.type)
        p, q = msg.pose.position, msg.pose.orientation
        stamps.append(msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec)
        values.append([p.x, p.y, p.z, q.x, q.y, q.z, q.w])
    return np.array(stamps, np.int64), np.array(values)


def test_same_seed_same_recording_other_seed_other_flight(tmp_path, config_dir):
    runs = {name: tmp_path / name for name in ("a", "b", "c")}
    summaries = {name: launch(run, config_dir, 1 if name == "c" else 0)
                 for name, run in runs.items()}
    for name, s in summaries.items():
        assert s["success"], (name, s.get("reason"))
    (ta, pa), (tb, pb), (tc, pc) = (poses(runs[n] / "bag") for n in ("a", "b", "c"))
    assert len(ta) > 200 and ta[0] == 0, (len(ta), ta[:3])     # the flight from t=0, recorded
    assert np.all(np.diff(ta) > 0)                             # one sample per tick
    assert ta.tolist() == tb.tolist()                          # the same ticks, start to end
    assert np.array_equal(pa, pb)                              # bit for bit
    assert summaries["a"]["final_position_error"] == summaries["b"]["final_position_error"]
    # another seed: another start (initial position noise), so another flight
    assert not np.allclose(pa[0, :3], pc[0, :3], atol=1e-4)
    n = min(len(pa), len(pc))
    assert np.abs(pa[:n, :3] - pc[:n, :3]).max() > 1e-3
