"""The recorder's stop always leaves a complete MCAP (summary and footer, readable by the mcap
library) and ends within a bounded time, even when undeclaring its subscriptions hangs (the
cause of 'recorder ignored SIGINT and SIGTERM: SIGKILL' and footer-less bags at shutdown)."""
from __future__ import annotations

import signal
import sys
import time

import pytest
from mcap.reader import make_reader

from conftest import graph_env

pytestmark = pytest.mark.graph

HANGING_RECORDER = """
import sys, time
import roszen.node
roszen.node.Node.destroy_subscription = lambda self, sub: time.sleep(3600)   # a teardown that hangs
from roszen.cli import main
sys.exit(main(sys.argv[1:]))
"""


@pytest.mark.parametrize("second_signal", [False, True])
def test_stop_completes_the_bag_even_when_teardown_hangs(procs, router, tmp_path, second_signal):
    env = graph_env(router)
    pub = procs([sys.executable, "-m", "roszen.cli", "topic", "pub", "-r", "50", "/chatter",
                 "std_msgs/msg/String", "{data: hello}"], env=env)
    pub.wait_line("publishing #1")
    out = tmp_path / "bag"
    rec = procs([sys.executable, "-c", HANGING_RECORDER, "bag", "record", "-a", "-o", str(out)], env=env)
    rec.wait_line("Subscribed to topic '/chatter'", stream="err")
    time.sleep(1.0)
    t0 = time.monotonic()
    rec.signal(signal.SIGINT)
    if second_signal:
        time.sleep(0.3)
        rec.signal(signal.SIGTERM)
    rc = rec.wait(timeout=20)
    assert rc == 0, rec.err[-5:]
    assert time.monotonic() - t0 < 15          # bounded (the launcher's SIGINT window is 5 s)
    with open(out / "bag_0.mcap", "rb") as f:
        summary = make_reader(f).get_summary()      # needs the summary section and footer
    assert summary is not None and summary.statistics.message_count > 10
    assert (out / "metadata.yaml").read_text().count("/chatter") >= 1


FULL_DISK_RECORDER = """
import builtins, sys
import roszen.bag.writer as w
w.open = lambda path, mode="r", *a, **k: builtins.open("/dev/full", mode, *a, **k)   # ENOSPC at the first flush
from roszen.cli import main
sys.exit(main(sys.argv[1:]))
"""


@pytest.mark.skipif(not __import__("os").path.exists("/dev/full"), reason="no /dev/full")
def test_full_disk_ends_the_recording_at_once_with_one_line(procs, router, tmp_path):
    env = graph_env(router)
    pub = procs([sys.executable, "-m", "roszen.cli", "topic", "pub", "-r", "50", "/chatter",
                 "std_msgs/msg/String", "{data: hello}"], env=env)
    pub.wait_line("publishing #1")
    rec = procs([sys.executable, "-c", FULL_DISK_RECORDER, "bag", "record", "-a", "-o",
                 str(tmp_path / "bag")], env=env)
    rc = rec.wait(timeout=30)            # it stops by itself: no signal sent
    err = "\n".join(rec.err)
    assert rc == 1, err[-2000:]
    assert "No space left on device" in err and "recording stopped" in err
    assert "Traceback" not in err
