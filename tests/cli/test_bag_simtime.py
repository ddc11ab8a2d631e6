"""Bags on sim time: `bag record --use-sim-time` stamps with /clock (a lockstep
flight replays at its own pace; a reset does not run the bag's time backwards), `bag play
--clock` is the only time base on /clock and it never goes back, `--exclude-topics` and
`--exclude-regex` in record and play."""
from __future__ import annotations

import signal
import sys

import pytest

from conftest import ASTROBEE, HERE, graph_env

pytestmark = pytest.mark.graph


def _record_fake(procs, env, out, *extra):
    fake = procs([sys.executable, str(HERE / "fake_lockstep.py"), "20"], env=env)
    fake.wait_line("waiting")
    rec = procs([ASTROBEE, "bag", "record", "-a", "-o", str(out), *extra], env=env)
    rec.wait_line("Recording...", stream="err")
    fake.wait_line("done", timeout=60)
    rec.signal(signal.SIGINT)
    assert rec.wait(timeout=30) == 0, rec.err[-5:]
    fake.kill()


def _messages(bag, topic):
    from roszen import typestore
    from roszen.bag.reader import BagReader
    return [(m.log_time_ns, m.publish_time_ns, typestore.deserialize(m.data, m.topic.type))
            for m in BagReader(bag).messages([topic])]


def test_sim_time_recording_and_single_clock_playback(procs, router, tmp_path):
    env = graph_env(router)
    bag = tmp_path / "sim"
    _record_fake(procs, env, bag, "--use-sim-time")
    ticks = _messages(bag, "/tick")
    assert len(ticks) == 30
    first, second = ticks[:20], ticks[20:]
    # stamped on the sim clock (not the wall clock: that would be ~1.8e18 ns), never before
    # the tick's own sim time (a busy recorder may stamp later: receive time), within the
    # 3 s of sim time the run spans
    for log_ns, wall_ns, msg in first:
        assert msg.data * 1_000_000 <= log_ns <= 3_000_000_000
        assert wall_ns > 1_000_000_000_000_000_000      # the wall receive time kept beside
    # the reset (sim time back to 0) does not run the bag's time backwards: the second run's
    # ticks continue after the first run's 2 s (its last tick, 1.0 s, at 3.0 s or later)
    logs = [t for t, _, _ in ticks]
    assert logs == sorted(logs)
    assert second[0][0] >= first[-1][0] and second[0][0] >= 2_100_000_000
    assert second[-1][0] >= 3_000_000_000

    # play with --clock: the player's /clock is the only one, and it never goes back
    echo = procs([ASTROBEE, "topic", "echo", "/clock", "rosgraph_msgs/msg/Clock", "--csv"],
                 env=env)
    info_seen = []
    play = procs([ASTROBEE, "bag", "play", str(bag), "--clock", "50", "-r", "0.5"], env=env)
    play.wait_line("not republishing the recorded /clock", stream="err")
    echo.wait_line(lambda l: l.strip() != "", timeout=30)
    import subprocess
    info = subprocess.run([ASTROBEE, "topic", "info", "/clock"], env=env, capture_output=True,
                          text=True, timeout=30)
    info_seen.append(info.stdout)
    assert play.wait(timeout=90) == 0, play.err[-5:]
    echo.signal(signal.SIGINT)
    echo.wait(timeout=20)
    assert "Publisher count: 1" in info_seen[0], info_seen
    stamps = [int(a) * 1_000_000_000 + int(b) for a, b in
              (l.split(",")[:2] for l in echo.lines if l.count(",") >= 1)]
    assert len(stamps) > 10
    assert stamps == sorted(stamps)
    start = min(t for t, _, _ in _messages(bag, "/clock"))
    assert stamps[0] >= start and stamps[-1] <= logs[-1] + 1_000_000_000


def test_exclude_topics_in_record_and_play(procs, router, tmp_path):
    env = graph_env(router)
    bag = tmp_path / "ex"
    _record_fake(procs, env, bag, "--exclude-topics", "/rosout", "-x", "^/param")
    from roszen.bag.reader import BagReader
    names = {t.name for t in BagReader(bag).metadata().topics}
    assert {"/tick", "/clock"} <= names
    assert "/rosout" not in names and not any(n.startswith("/param") for n in names)
    counts = {t.name: t.count for t in BagReader(bag).metadata().topics}
    play = procs([ASTROBEE, "bag", "play", str(bag), "-r", "20", "--exclude-topics", "/tick"],
                 env=env)
    assert play.wait(timeout=60) == 0
    played = int(play.wait_line("Played", stream="err").split("Played ")[1].split()[0])
    assert played == sum(counts.values()) - counts["/tick"]
    play = procs([ASTROBEE, "bag", "play", str(bag), "-r", "20", "--exclude-regex", "ti.k$"],
                 env=env)
    assert play.wait(timeout=60) == 0
    played = int(play.wait_line("Played", stream="err").split("Played ")[1].split()[0])
    assert played == sum(counts.values()) - counts["/tick"]
