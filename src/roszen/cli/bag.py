"""`bag record | play | info | reindex`, shaped like `ros2 bag` (rosbag2 directories, MCAP)."""
from __future__ import annotations

import signal
import threading
import time
from pathlib import Path

from roszen.bag.metadata import BagError
from roszen.cli.common import CliError, positive_float


def add_parser(sub) -> None:
    """`bag`: its sub-verbs are the entry points of roszen.bag.verbs (record, play, info, ...)."""
    from roszen.cli import registry
    p = sub.add_parser("bag", help="record and play rosbag2 (MCAP) bags")
    registry.add_sub_verbs(p, "bag")


def add_record(v) -> None:
    """`bag record`."""
    rec = v.add_parser("record", help="record topics into a bag directory")
    rec.add_argument("topics", nargs="*", help="topics to record")
    rec.add_argument("--topics", dest="topics_opt", nargs="+", default=[], metavar="TOPIC")
    rec.add_argument("-a", "--all", action="store_true", help="record every topic")
    rec.add_argument("-e", "--regex", help="record topics matching this regular expression")
    rec.add_argument("-x", "--exclude-regex", help="skip topics matching this expression")
    rec.add_argument("--exclude-topics", nargs="+", default=[], metavar="TOPIC",
                     help="skip these topics")
    rec.add_argument("--use-sim-time", action="store_true",
                     help="stamp messages with the sim time of /clock (a lockstep flight then "
                          "replays at its own pace); the wall receive time stays in the MCAP "
                          "publish_time")
    rec.add_argument("--include-hidden-topics", action="store_true")
    rec.add_argument("-o", "--output", help="bag directory (must not exist; default "
                     "rosbag2_<date>-<time>)")
    rec.add_argument("-s", "--storage", default="mcap", help="storage id (only mcap)")
    rec.add_argument("--max-cache-size", type=int, default=1 << 20,
                     help="bytes buffered per chunk before it is compressed and written "
                          "(default 1 MiB)")
    rec.add_argument("--compression", choices=["zstd", "lz4", "none"], default="zstd",
                     help="MCAP chunk compression (default zstd)")
    rec.add_argument("--flush-interval", type=positive_float, default=1.0,
                     help="seconds between flushes to disk: at most this much is lost on "
                          "SIGKILL (default 1)")
    rec.add_argument("--no-discovery", action="store_true",
                     help="only record topics present at start")
    rec.set_defaults(func=record_cmd)


def add_play(v) -> None:
    """`bag play`."""
    play = v.add_parser("play", help="play back a bag directory")
    play.add_argument("bag", help="bag directory")
    play.add_argument("-r", "--rate", type=positive_float, default=1.0)
    play.add_argument("-l", "--loop", action="store_true")
    play.add_argument("--topics", nargs="+", default=None, metavar="TOPIC")
    play.add_argument("--clock", nargs="?", const=40.0, default=0.0, type=positive_float,
                      metavar="HZ", help="publish /clock at HZ (default 40) with the bag time "
                      "(the recorded /clock is then not republished)")
    play.add_argument("--exclude-topics", nargs="+", default=[], metavar="TOPIC",
                      help="do not play these topics")
    play.add_argument("--exclude-regex", metavar="REGEX",
                      help="do not play topics matching this expression")
    play.add_argument("--start-offset", type=float, default=0.0,
                      help="start this many seconds into the bag")
    play.add_argument("-d", "--delay", type=float, default=0.0,
                      help="seconds to wait before playing")
    play.set_defaults(func=play_cmd)


def add_info(v) -> None:
    """`bag info`."""
    info = v.add_parser("info", help="print information about a bag")
    info.add_argument("bag")
    info.set_defaults(func=info_cmd)


def add_reindex(v) -> None:
    """`bag reindex`."""
    rx = v.add_parser("reindex", help="rebuild a bag whose recorder was killed (MCAP summary "
                      "and metadata.yaml)")
    rx.add_argument("bag")
    rx.set_defaults(func=reindex_cmd)


def _stop_event() -> threading.Event:
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    return stop


def record_cmd(args) -> int:
    import re

    from roszen.bag.recorder import Recorder, StopSignals, log
    from roszen.bag.writer import BagWriter
    topics = [t if t.startswith("/") else "/" + t for t in args.topics + args.topics_opt]
    if not (topics or args.all or args.regex):
        raise CliError("no topics given: pass topic names, -a or -e REGEX")
    if args.storage != "mcap":
        raise CliError(f"storage '{args.storage}' is not supported (only mcap)")
    if args.max_cache_size <= 0:
        raise CliError(f"--max-cache-size must be > 0, got {args.max_cache_size}")
    for rx in (args.regex, args.exclude_regex):
        if rx:
            try:
                re.compile(rx)
            except re.error as exc:
                raise CliError(f"invalid regular expression '{rx}': {exc}") from None
    out = args.output or time.strftime("rosbag2_%Y_%m_%d-%H_%M_%S")
    # SIGINT/SIGTERM served on a thread of their own, whatever the main thread is in (a zenoh
    # call): the first stops the recording, a second ends the process (StopSignals)
    signals = StopSignals()
    stop = signals.stop
    from roszen.cli.common import make_node
    node = make_node("_rosbag2_recorder")     # joins the graph before anything is created
    try:
        try:
            writer = BagWriter(out, compression=args.compression, chunk_size=args.max_cache_size,
                               flush_interval=args.flush_interval)
        except (BagError, OSError) as exc:
            raise CliError(str(exc)) from None
        from roszen import runtime
        on_rclpy = runtime.name() == "rclpy"
        recorder = Recorder(node, writer, topics=topics, regex=args.regex,
                            exclude=args.exclude_regex, exclude_topics=_names(args.exclude_topics),
                            use_sim_time=args.use_sim_time and not on_rclpy,
                            include_hidden=args.include_hidden_topics,
                            discovery=not args.no_discovery)
        if args.use_sim_time and on_rclpy:     # /clock through an rclpy subscription
            from roszen.rclpy_backend.record import RclpySimStamp
            recorder.sim = RclpySimStamp(node, writer.write)
        signals.on_second = recorder.stop_now     # before: a second signal exits at once
        try:
            recorder.spin(stop)
        finally:
            # the bag is completed before anything that could hang (Recorder.finish); a second
            # SIGINT/SIGTERM at any moment ends the process at once (the bag completed first,
            # within a bounded time: Recorder.stop_now)
            try:
                meta = recorder.finish()
            except BagError as exc:
                raise CliError(f"{exc}; the bag in {out} holds what was written before "
                               f"(astrobee bag reindex {out})") from None
            log(f"Recording stopped: {meta.message_count} messages on {len(meta.topics)} "
                f"topics in {out}")
    finally:
        node.destroy_node()
    return 0


def _names(topics: list[str]) -> list[str]:
    return [t if t.startswith("/") else "/" + t for t in topics]


def _check_regex(rx: str | None) -> None:
    import re
    if rx:
        try:
            re.compile(rx)
        except re.error as exc:
            raise CliError(f"invalid regular expression '{rx}': {exc}") from None


def _reader(path: str):
    from roszen.bag.reader import BagReader
    try:
        return BagReader(path)
    except BagError as exc:
        raise CliError(str(exc)) from None


def play_cmd(args) -> int:
    from roszen.bag.player import Player, log
    if args.start_offset < 0:
        raise CliError(f"--start-offset must be >= 0, got {args.start_offset}")
    if args.delay < 0:
        raise CliError(f"--delay must be >= 0, got {args.delay}")
    reader = _reader(args.bag)
    try:
        reader.metadata()
    except BagError as exc:
        raise CliError(str(exc)) from None
    topics = [t if t.startswith("/") else "/" + t for t in args.topics] if args.topics else None
    _check_regex(args.exclude_regex)
    stop = _stop_event()
    from roszen.cli.common import make_node
    node = make_node("_rosbag2_player")
    try:
        try:
            player = Player(node, reader, rate=args.rate, loop=args.loop, topics=topics,
                            clock_hz=args.clock, start_offset=args.start_offset,
                            delay=args.delay, exclude_topics=_names(args.exclude_topics),
                            exclude_regex=args.exclude_regex)
            player.play(stop)
        except BagError as exc:
            raise CliError(str(exc)) from None
        log(f"Played {player.published} messages")
    finally:
        node.destroy_node()
    return 0


def info_cmd(args) -> int:
    from roszen.bag.reader import info_text
    _reader(args.bag)
    try:
        print(info_text(args.bag))
    except BagError as exc:
        raise CliError(str(exc)) from None
    return 0


def reindex_cmd(args) -> int:
    from roszen.bag.reader import reindex
    _reader(args.bag)
    try:
        meta = reindex(args.bag)
    except BagError as exc:
        raise CliError(str(exc)) from None
    print(f"reindexed {Path(args.bag)}: {meta.message_count} messages on "
          f"{len(meta.topics)} topics")
    return 0
