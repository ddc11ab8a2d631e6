"""`bag record` on real rclpy (`python -m roszen.rclpy_backend.record -a [--use-sim-time] -o DIR`):
roszen's Recorder and BagWriter (the same rosbag2 MCAP bags) fed by raw rclpy subscriptions
(rosbag2 itself is not on PyPI). The graph is looked at once a second (rclpy has no graph
listener here); a publisher's advertised RIHS01 hash is checked as on roszen; /clock is
followed from any publisher (no GID on a raw sample)."""
from __future__ import annotations

import argparse
import sys
import threading
import time
from typing import Any

from ..bag.recorder import Recorder, SimStamp, StopSignals, log
from ..bag.writer import BagWriter
from ..qos import CLOCK


class NoGraphEvents:
    """The `context.graph` the Recorder registers its change listener with: none come (it
    looks again every REDISCOVER_PERIOD)."""

    def add_listener(self, cb: Any) -> None:
        pass

    def remove_listener(self, cb: Any) -> None:
        pass


class RclpySimStamp(SimStamp):
    """SimStamp on the rclpy node's /clock subscription (every publisher's samples accepted)."""

    def __init__(self, node: Any, write: Any, patience: float = 60.0,
                 max_pending: int = 100_000) -> None:
        self.write = write
        self._lock = threading.Lock()
        self.patience = patience
        self.max_pending = max_pending
        self.started = time.monotonic()
        self.offset, self.last, self.wall, self.pending, self.resets = 0, None, False, [], 0
        self.source = _AcceptAll()
        self._node = node
        self._sub = node.create_subscription("rosgraph_msgs/msg/Clock", "/clock",
                                             lambda msg: self._on_clock(msg, b""), CLOCK)

    def close(self) -> None:
        self.flush_pending()
        self._node.destroy_subscription(self._sub)


class _AcceptAll:
    """A clock source that follows every /clock publisher."""

    def accept(self, gid: bytes) -> bool:
        return True


def main(argv: list[str] | None = None) -> int:
    """Record until SIGINT/SIGTERM; the bag is completed before the process ends."""
    from rclpy.signals import SignalHandlerOptions
    from . import ensure_init
    from .node import Node
    p = argparse.ArgumentParser(prog="record", description=__doc__.splitlines()[0])
    p.add_argument("topics", nargs="*")
    p.add_argument("-a", "--all", action="store_true")
    p.add_argument("-o", "--output", default=time.strftime("rosbag2_%Y_%m_%d-%H_%M_%S"))
    p.add_argument("--use-sim-time", action="store_true")
    p.add_argument("--exclude-regex", default=None)
    args = p.parse_args(sys.argv[1:] if argv is None else argv)
    if not (args.topics or args.all):
        p.error("no topics given: pass topic names or -a")
    signals = StopSignals()     # SIGINT/SIGTERM on a thread of their own (see StopSignals)
    stop = signals.stop
    ensure_init(None, signal_handler_options=SignalHandlerOptions.NO)
    node = Node("_rosbag2_recorder", start_parameter_services=False, enable_rosout=False)
    node.context = type("Ctx", (), {"graph": NoGraphEvents()})()
    try:
        writer = BagWriter(args.output)
        recorder = Recorder(node, writer, topics=[t if t.startswith("/") else "/" + t
                                                  for t in args.topics],
                            exclude=args.exclude_regex)
        if args.use_sim_time:
            recorder.sim = RclpySimStamp(node, writer.write)
        signals.on_second = recorder.stop_now
        try:
            recorder.spin(stop)
        finally:
            meta = recorder.finish()
            log(f"Recording stopped: {meta.message_count} messages on {len(meta.topics)} "
                f"topics in {args.output}")
    finally:
        node.destroy_node()
        import rclpy
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
