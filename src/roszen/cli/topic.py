"""`topic list | info | echo | hz | bw | pub | type | find`, shaped like `ros2 topic`."""
from __future__ import annotations

import math
import sys
import threading
import time

from roszen.cli.common import (CliError, add_qos_args, fq_name, make_node, non_negative_int,
                               parse_yaml_values, positive_float, positive_int, qos_from_args,
                               spin_until)


def add_parser(sub) -> None:
    p = sub.add_parser("topic", help="inspect and publish topics")
    v = p.add_subparsers(dest="cmd", metavar="command")
    v.required = True

    ls = v.add_parser("list", help="output a list of available topics")
    ls.add_argument("-t", "--show-types", action="store_true")
    ls.add_argument("-c", "--count-topics", action="store_true")
    ls.set_defaults(func=list_cmd)

    info = v.add_parser("info", help="print information about a topic")
    info.add_argument("topic_name")
    info.add_argument("-v", "--verbose", action="store_true")
    info.set_defaults(func=info_cmd)

    ty = v.add_parser("type", help="print a topic's type")
    ty.add_argument("topic_name")
    ty.set_defaults(func=type_cmd)

    find = v.add_parser("find", help="topics of a given type")
    find.add_argument("topic_type")
    find.set_defaults(func=find_cmd)

    echo = v.add_parser("echo", help="output messages from a topic")
    echo.add_argument("topic_name")
    echo.add_argument("message_type", nargs="?")
    add_qos_args(echo)
    echo.add_argument("--once", action="store_true", help="print the first message and exit")
    echo.add_argument("--field", help="echo a selected field (dotted path, e.g. pose.position)")
    echo.add_argument("--raw", action="store_true", help="print the serialised bytes")
    echo.add_argument("--no-arr", action="store_true", help="don't print array fields")
    echo.add_argument("--no-str", action="store_true", help="don't print string fields")
    echo.add_argument("--flow-style", action="store_true", help="YAML flow style")
    echo.add_argument("--csv", action="store_true", help="comma-separated values")
    echo.add_argument("--timeout", type=positive_float, default=None,
                      help="stop after this many seconds (an error if no message arrived)")
    echo.add_argument("--discovery-timeout", type=positive_float, default=3.0,
                      help="seconds to wait for the topic to appear when no type is given")
    echo.set_defaults(func=echo_cmd)

    hz = v.add_parser("hz", help="print the average publishing rate")
    hz.add_argument("topic_name")
    hz.add_argument("-w", "--window", type=positive_int, default=10000)
    hz.add_argument("--discovery-timeout", type=positive_float, default=3.0)
    hz.set_defaults(func=hz_cmd)

    bw = v.add_parser("bw", help="print the bandwidth used by a topic")
    bw.add_argument("topic_name")
    bw.add_argument("-w", "--window", type=positive_int, default=100)
    bw.add_argument("--discovery-timeout", type=positive_float, default=3.0)
    bw.set_defaults(func=bw_cmd)

    pub = v.add_parser("pub", help="publish a message to a topic")
    pub.add_argument("topic_name")
    pub.add_argument("message_type")
    pub.add_argument("values", nargs="?", default="{}", help="YAML of the message fields")
    pub.add_argument("-r", "--rate", type=positive_float, default=1.0, help="Hz (default 1)")
    pub.add_argument("-p", "--print", type=non_negative_int, default=1, dest="print_nth",
                     help="print every N-th message (0: none)")
    pub.add_argument("-1", "--once", action="store_true", help="publish one message and exit")
    pub.add_argument("-t", "--times", type=non_negative_int, default=0, help="publish N messages and exit")
    pub.add_argument("-w", "--wait-matching-subscriptions", type=non_negative_int, default=None)
    pub.add_argument("--keep-alive", type=float, default=0.1,
                     help="seconds to stay after the last message (default 0.1)")
    pub.add_argument("-n", "--node-name", help="name of the publishing node")
    add_qos_args(pub)
    pub.set_defaults(func=pub_cmd)


# ------------------------------------------------------------------------------- graph queries
def _hidden(name: str) -> bool:
    return any(part.startswith("_") for part in name.split("/") if part)


def list_cmd(args) -> int:
    node = make_node()
    try:
        topics = node.get_topic_names_and_types()
    finally:
        node.destroy_node()
    if args.count_topics:
        print(len(topics))
        return 0
    for name, types in topics:
        print(f"{name} [{', '.join(types)}]" if args.show_types else name)
    return 0


def _types_of(node, topic: str) -> list[str]:
    for name, types in node.get_topic_names_and_types():
        if name == topic:
            return types
    return []


def _wait_types(node, topic: str, timeout: float) -> list[str]:
    graph = node.context.graph
    graph.wait_for(lambda: bool(_types_of(node, topic)), timeout)
    return _types_of(node, topic)


def type_cmd(args) -> int:
    node = make_node()
    try:
        types = _types_of(node, fq_name(args.topic_name))
    finally:
        node.destroy_node()
    if not types:
        raise CliError(f"Unknown topic '{fq_name(args.topic_name)}'")
    print("\n".join(types))
    return 0


def find_cmd(args) -> int:
    node = make_node()
    try:
        for name, types in node.get_topic_names_and_types():
            if args.topic_type in types:
                print(name)
    finally:
        node.destroy_node()
    return 0


def _duration_text(sec: float) -> str:
    return "Infinite" if not sec else f"{int(sec * 1e9)} nanoseconds"


def _qos_lines(q) -> list[str]:
    depth = f" ({q.depth})" if q.history.name == "KEEP_LAST" else ""
    return ["QoS profile:",
            f"  Reliability: {q.reliability.name}",
            f"  History (Depth): {q.history.name}{depth}",
            f"  Durability: {q.durability.name}",
            f"  Lifespan: {_duration_text(q.lifespan)}",
            f"  Deadline: {_duration_text(q.deadline)}",
            f"  Liveliness: {q.liveliness.name}",
            f"  Liveliness lease duration: {_duration_text(q.liveliness_lease_duration)}"]


def _gid_text(gid: bytes) -> str:
    return ".".join(f"{b:02x}" for b in gid)


def info_cmd(args) -> int:
    topic = fq_name(args.topic_name)
    node = make_node()
    try:
        types = _types_of(node, topic)
        pubs = node.get_publishers_info_by_topic(topic)
        subs = node.get_subscriptions_info_by_topic(topic)
    finally:
        node.destroy_node()
    if not types:
        raise CliError(f"Unknown topic '{topic}'")
    print(f"Type: {', '.join(types)}")
    for title, kind, ents in (("Publisher", "PUBLISHER", pubs),
                              ("Subscription", "SUBSCRIPTION", subs)):
        if args.verbose:
            print()
        print(f"{title} count: {len(ents)}")
        if not args.verbose:
            continue
        for e in ents:
            print()
            print(f"Node name: {e.node_name}")
            print(f"Node namespace: {e.namespace}")
            print(f"Topic type: {e.ros_type}")
            print(f"Topic type hash: {e.type_hash}")
            print(f"Endpoint type: {kind}")
            print(f"GID: {_gid_text(e.gid)}")
            print("\n".join(_qos_lines(e.qos)))
    return 0


# ------------------------------------------------------------------------------- subscribing
def _resolve_topic_type(node, topic: str, given: str | None, timeout: float) -> str:
    from roszen.cli.interface import resolve_type
    if given:
        return _check_given_type(node, topic, resolve_type(given, "msg"), timeout)
    types = _wait_types(node, topic, timeout)
    if not types:
        raise CliError(f"Could not determine the type for the passed topic '{topic}' "
                       f"(no publisher or subscription seen in {timeout:g} s)")
    if len(types) > 1:
        raise CliError(f"The passed topic '{topic}' has more than one type: "
                       f"{', '.join(types)}; pass the type explicitly")
    return resolve_type(types[0], "msg")


def _check_given_type(node, topic: str, type_name: str, timeout: float) -> str:
    """An explicit type, checked against the topic's publishers after the discovery wait:
    published under other types only -> error (nothing would ever arrive); no publisher ->
    one warning on stderr, then the echo waits for one (as ros2 topic echo does)."""
    graph = node.context.graph
    graph.wait_for(lambda: bool(node.get_publishers_info_by_topic(topic)), timeout)
    pubs = node.get_publishers_info_by_topic(topic)
    if not pubs:
        print(f"[WARN] no publisher on '{topic}' yet (waited {timeout:g} s); waiting for one "
              f"of type {type_name}", file=sys.stderr, flush=True)
        return type_name
    theirs = sorted({e.ros_type for e in pubs})
    if type_name not in theirs:
        raise CliError(f"'{topic}' is published as {', '.join(theirs)}, not {type_name}")
    return type_name


def adapted_qos(node, topic: str, user=None):
    """A subscription QoS that matches the publishers (ros2 topic echo's rule)."""
    from roszen.qos import Durability, QoSProfile, Reliability
    pubs = node.get_publishers_info_by_topic(topic)
    q = QoSProfile(depth=10)
    if pubs:
        if all(e.qos.durability == Durability.TRANSIENT_LOCAL for e in pubs):
            q = q.with_(durability=Durability.TRANSIENT_LOCAL,
                        depth=max(10, max(e.qos.effective_depth for e in pubs)))
        if any(e.qos.reliability == Reliability.BEST_EFFORT for e in pubs):
            q = q.with_(reliability=Reliability.BEST_EFFORT)
    return q


def _select_field(data, path: str):
    for part in path.split("."):
        if isinstance(data, dict) and part in data:
            data = data[part]
        else:
            raise CliError(f"Invalid field '{path}': '{part}' is not a field of the message")
    return data


def _prune(data, no_arr: bool, no_str: bool):
    if isinstance(data, dict):
        out = {}
        for k, v in data.items():
            if no_arr and isinstance(v, (list, tuple)):
                out[k] = "<sequence type: omitted>"
            elif no_str and isinstance(v, str):
                out[k] = "<string type: omitted>"
            else:
                out[k] = _prune(v, no_arr, no_str)
        return out
    return data


def _csv(data) -> str:
    out: list[str] = []

    def walk(v):
        if isinstance(v, dict):
            for x in v.values():
                walk(x)
        elif isinstance(v, (list, tuple)):
            for x in v:
                walk(x)
        else:
            out.append(str(v).lower() if isinstance(v, bool) else str(v))
    walk(data)
    return ",".join(out)


def format_message(msg, args) -> str:
    """The text `topic echo` prints for one message (before the '---' line)."""
    import yaml

    from roszen import typestore
    if args.raw:
        return repr(bytes(msg))
    data = typestore.to_dict(msg)
    if args.field:
        data = _select_field(data, args.field)
    if args.no_arr or args.no_str:
        data = _prune(data, args.no_arr, args.no_str)
    if args.csv:
        return _csv(data)
    if not isinstance(data, (dict, list)):
        return yaml.safe_dump(data, default_flow_style=False).removesuffix("\n...\n").rstrip("\n")
    if args.flow_style:
        return yaml.safe_dump(data, default_flow_style=True, sort_keys=False, width=10**9).rstrip()
    if not args.field and not (args.no_arr or args.no_str):
        return typestore.to_yaml(msg).rstrip("\n")
    return yaml.safe_dump(data, default_flow_style=False, sort_keys=False).rstrip("\n")


def echo_cmd(args) -> int:
    topic = fq_name(args.topic_name)
    if args.field is not None and not args.field.strip("."):
        raise CliError("--field must name a field")
    node = make_node()
    try:
        type_name = _resolve_topic_type(node, topic, args.message_type, args.discovery_timeout)
        qos = qos_from_args(args, adapted_qos(node, topic))
        count = [0]
        error: list[CliError] = []

        def on_msg(msg):
            if args.once and count[0]:
                return
            if args.raw:
                text = format_message(msg, args)
            else:
                try:
                    text = format_message(msg, args)
                except CliError as exc:
                    error.append(exc)
                    return
            sys.stdout.write(text + "\n" + ("---\n" if not args.csv else ""))
            sys.stdout.flush()
            count[0] += 1

        sub = [node.create_subscription(type_name, topic, on_msg, qos, raw=args.raw)]
        # no publisher seen yet: the QoS was chosen blind (volatile); once discovery shows the
        # publishers, adapt to them, so a latched publisher's history is asked for (a one-shot
        # latched sample would otherwise never arrive, while the next run got it at once)
        blind = [not node.get_publishers_info_by_topic(topic)
                 and not (args.qos_profile or args.qos_durability)]

        def finished() -> bool:
            if blind[0] and node.get_publishers_info_by_topic(topic):
                blind[0] = False
                seen = qos_from_args(args, adapted_qos(node, topic))
                if seen.durability != sub[0].qos_profile.durability:
                    node.destroy_subscription(sub[0])
                    sub[0] = node.create_subscription(type_name, topic, on_msg, seen, raw=args.raw)
            return bool(error) or (args.once and count[0] > 0)
        done = spin_until(node, finished, args.timeout)
        if error:
            raise error[0]
        if not done and args.timeout is not None:
            if count[0] == 0:
                raise CliError(f"no message on '{topic}' within {args.timeout:g} s")
        return 0
    finally:
        node.destroy_node()


def _raw_subscribe(node, topic, timeout, cb):
    types = _wait_types(node, topic, timeout)
    if not types:
        raise CliError(f"Could not determine the type for the passed topic '{topic}'")
    from roszen.cli.interface import resolve_type
    type_name = resolve_type(types[0], "msg")
    return node.create_subscription(type_name, topic, cb, adapted_qos(node, topic).with_(
        depth=1000), raw=True)


def hz_cmd(args) -> int:
    topic = fq_name(args.topic_name)
    node = make_node()
    stamps: list[float] = []
    lock = threading.Lock()

    def on_msg(_data):
        with lock:
            stamps.append(time.monotonic())
            del stamps[:-args.window - 1]
    try:
        _raw_subscribe(node, topic, args.discovery_timeout, on_msg)
        next_print = time.monotonic() + 1.0
        while True:
            node.spin_once(timeout_sec=0.05)
            if time.monotonic() < next_print:
                continue
            next_print += 1.0
            with lock:
                s = list(stamps)
            if len(s) < 2:
                print("no new messages")
                continue
            d = [b - a for a, b in zip(s, s[1:])]
            mean = sum(d) / len(d)
            std = math.sqrt(sum((x - mean) ** 2 for x in d) / len(d))
            print(f"average rate: {1.0 / mean:.3f}\n\tmin: {min(d):.3f}s max: {max(d):.3f}s "
                  f"std dev: {std:.5f}s window: {len(s)}")
    finally:
        node.destroy_node()


def _size(n: float) -> str:
    if n < 1000:
        return f"{n:.0f} B"
    if n < 1e6:
        return f"{n / 1e3:.2f} KB"
    return f"{n / 1e6:.2f} MB"


def bw_cmd(args) -> int:
    topic = fq_name(args.topic_name)
    node = make_node()
    samples: list[tuple[float, int]] = []

    def on_msg(data):
        samples.append((time.monotonic(), len(data)))
        del samples[:-args.window]
    try:
        _raw_subscribe(node, topic, args.discovery_timeout, on_msg)
        print(f"Subscribed to [{topic}]")
        next_print = time.monotonic() + 1.0
        while True:
            node.spin_once(timeout_sec=0.05)
            if time.monotonic() < next_print:
                continue
            next_print += 1.0
            s = list(samples)
            if len(s) < 2:
                continue
            span = max(time.monotonic() - s[0][0], 1e-9)
            sizes = [n for _, n in s]
            print(f"{_size(sum(sizes) / span)}/s from {len(s)} messages\n\tMessage size mean: "
                  f"{_size(sum(sizes) / len(sizes))} min: {_size(min(sizes))} "
                  f"max: {_size(max(sizes))}")
    finally:
        node.destroy_node()


# ------------------------------------------------------------------------------- publishing
def pub_cmd(args) -> int:
    from roszen import typestore
    from roszen.cli.interface import resolve_type
    topic = fq_name(args.topic_name)
    type_name = resolve_type(args.message_type, "msg")
    msg = parse_yaml_values(args.values, type_name,
                            lambda d: typestore.from_dict(type_name, d))
    qos = qos_from_args(args)
    times = 1 if args.once else args.times
    if times < 0:
        raise CliError(f"--times must be >= 0, got {times}")
    wait_subs = args.wait_matching_subscriptions
    if wait_subs is None:
        wait_subs = 1 if times else 0
    if args.node_name:
        from roszen.names import InvalidNameError, validate_node_name
        try:
            validate_node_name(args.node_name)     # before joining the graph
        except InvalidNameError as exc:
            raise CliError(str(exc)) from None
        node = make_node(name=args.node_name)
    else:
        node = make_node()
    try:
        pub = node.create_publisher(type_name, topic, qos)
        if wait_subs:
            spin_until(node, lambda: pub.get_subscription_count() >= wait_subs)
        print("publisher: beginning loop")
        period = 1.0 / args.rate
        n = 0
        next_t = time.monotonic()
        while True:
            pub.publish(msg)
            n += 1
            if args.print_nth and n % args.print_nth == 0:
                print(f"publishing #{n}: {msg!r}\n")
            if times and n >= times:
                break
            next_t += period
            while True:
                left = next_t - time.monotonic()
                if left <= 0:
                    break
                node.spin_once(timeout_sec=min(left, 0.05))
        end = time.monotonic() + max(0.0, args.keep_alive)
        while time.monotonic() < end:
            node.spin_once(timeout_sec=0.02)
        return 0
    finally:
        node.destroy_node()
