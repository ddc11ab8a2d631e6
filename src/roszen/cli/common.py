"""Shared pieces of the command verbs: the one-line error type and line-buffered output."""
from __future__ import annotations

import argparse
import re
import sys


class CliError(Exception):
    """A user error: printed as one line `<prog>: <message>`, exit status 1."""


def line_buffered() -> None:
    """Flush stdout at every newline (tests and pipes read the output line by line)."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.reconfigure(line_buffering=True)
        except (AttributeError, ValueError):
            pass


def positive_float(text: str) -> float:
    """argparse type: a float > 0 (rates, periods)."""
    try:
        value = float(text)
    except ValueError:
        raise CliError(f"not a number: {text!r}") from None
    if not value > 0.0 or value == float("inf"):
        raise CliError(f"must be a positive number, got {text!r}")
    return value


def positive_int(text: str) -> int:
    """argparse type: an integer > 0 (windows, counts)."""
    try:
        value = int(text)
    except ValueError:
        raise CliError(f"not an integer: {text!r}") from None
    if value <= 0:
        raise CliError(f"must be a positive integer, got {text!r}")
    return value


def non_negative_int(text: str) -> int:
    """argparse type: an integer >= 0."""
    try:
        value = int(text)
    except ValueError:
        raise CliError(f"not an integer: {text!r}") from None
    if value < 0:
        raise CliError(f"must be >= 0, got {text!r}")
    return value


_NEGATIVE = re.compile(r"^-(\d|\.\d|inf|nan)", re.IGNORECASE)


class Parser(argparse.ArgumentParser):
    """An ArgumentParser for the verbs: a bad argument is one line naming it (CliError, exit 1),
    never a usage dump; an option's value may be a negative number even where the parser also
    has options like `-1` (argparse would take `-r -5` for two options; the type then refuses
    the value and says which argument it was)."""

    def parse_known_args(self, args=None, namespace=None):
        if args is not None:
            args = self._join_negative_values(list(args))
        return super().parse_known_args(args, namespace)

    def _join_negative_values(self, args: list) -> list:
        out: list = []
        i = 0
        while i < len(args):
            tok = args[i]
            action = self._option_string_actions.get(tok)
            if (action is not None and action.nargs is None and action.option_strings
                    and i + 1 < len(args) and _NEGATIVE.match(args[i + 1])):
                out.append(f"{tok}={args[i + 1]}" if tok.startswith("--") else tok + args[i + 1])
                i += 2
                continue
            if tok == "--":
                out.extend(args[i:])
                break
            out.append(tok)
            i += 1
        return out

    def _get_value(self, action, arg_string):
        try:
            return super()._get_value(action, arg_string)
        except CliError as exc:
            name = "/".join(action.option_strings) or action.dest
            raise CliError(f"argument {name}: {exc}") from None

    def error(self, message: str):
        raise CliError(message.replace("\n", " "))


def add_qos_args(p, default_reliability: str | None = None) -> None:
    """--qos-profile/-depth/-history/-reliability/-durability like `ros2 topic`."""
    p.add_argument("--qos-profile", choices=["system_default", "sensor_data", "services_default",
                                             "parameters", "parameter_events", "action_status_default"],
                   help="QoS preset")
    p.add_argument("--qos-depth", type=int, help="queue size (KEEP_LAST)")
    p.add_argument("--qos-history", choices=["system_default", "keep_last", "keep_all"])
    p.add_argument("--qos-reliability", choices=["system_default", "reliable", "best_effort"],
                   default=default_reliability)
    p.add_argument("--qos-durability", choices=["system_default", "transient_local", "volatile"])


def qos_from_args(args, base=None):
    """The QoSProfile chosen by the --qos-* options on top of `base` (default: depth 10)."""
    from roszen.qos import Durability, History, QoSProfile, Reliability
    q = base or QoSProfile(depth=10)
    if args.qos_profile == "sensor_data":
        q = QoSProfile(depth=5, reliability=Reliability.BEST_EFFORT)
    elif args.qos_profile in ("parameter_events",):
        q = QoSProfile(depth=1000)
    elif args.qos_profile == "parameters":
        q = QoSProfile(depth=1000)
    kw = {}
    if args.qos_depth is not None:
        if args.qos_depth < 0:
            raise CliError(f"--qos-depth must be >= 0, got {args.qos_depth}")
        kw["depth"] = args.qos_depth
    if args.qos_history:
        kw["history"] = History[args.qos_history.upper()]
    if args.qos_reliability:
        kw["reliability"] = Reliability[args.qos_reliability.upper()]
    if args.qos_durability:
        kw["durability"] = Durability[args.qos_durability.upper()]
    return q.with_(**kw) if kw else q


def make_node(prefix: str = "_roszen_cli", name: str | None = None):
    """A hidden helper node for one command (named `name` if given), graph ready (the discovery
    `get` answered), on the runtime ASTROBEE_RUNTIME picks (roszen.runtime): on rclpy,
    roszen.rclpy_backend.cli's node, the verbs' code unchanged over it."""
    import os

    from roszen import runtime
    try:
        on_rclpy = runtime.name() == "rclpy"
    except ValueError as exc:
        raise CliError(str(exc)) from None
    if on_rclpy:
        try:
            import rclpy.node  # noqa: F401 - rclpy itself, before anything is built on it
            from roszen.rclpy_backend.cli import make_node as rclpy_node
        except ImportError as exc:
            raise CliError(f"ASTROBEE_RUNTIME=rclpy but rclpy is not importable here ({exc}); "
                           "make install-rclpy, or source a ROS 2 Jazzy install") from None
        try:
            return rclpy_node(name or f"{prefix}_{os.getpid()}")
        except Exception as exc:  # rcl cannot start (bad domain id, RMW missing, ...)
            raise CliError(f"cannot join the ROS graph: {exc}".replace("\n", " ")) from None
    from roszen.node import Node
    from roszen.zconfig import ConfigError
    try:
        node = Node(name or f"{prefix}_{os.getpid()}", start_parameter_services=False,
                    enable_rosout=False)
    except ConfigError as exc:
        raise CliError(str(exc)) from None
    except Exception as exc:   # zenoh cannot open the session (router unreachable, bad config)
        raise CliError(f"cannot join the ROS graph: {exc}") from None
    node.context.graph.wait_ready(3.0)
    if name is not None:       # a node named by the user (topic pub -n): as before, not primed
        return node
    # no router: the context has said so once (roszen.context.NO_ROUTER), not repeated here
    prime_graph(node)
    return node


def prime_graph(node, quiet: float = 0.1, limit: float = 1.0) -> None:
    """Fill the node's graph cache with the tokens that existed before it joined.

    A liveliness `get` sent right after the session opens can miss tokens the router has not
    yet propagated; a liveliness subscriber with history receives all of them. Returns once
    no token arrived for `quiet` seconds (bounded by `limit`).
    """
    import time

    import zenoh
    graph = node.context.graph
    last = [time.monotonic()]

    def on_sample(sample) -> None:
        last[0] = time.monotonic()
        key = str(sample.key_expr)
        if sample.kind == zenoh.SampleKind.DELETE:
            graph.remove(key)
        else:
            graph.add(key)

    node._cli_graph_sub = node.context.session.liveliness().declare_subscriber(
        f"@ros2_lv/{node.context.domain_id}/**",
        zenoh.handlers.Callback(on_sample, indirect=False), history=True)
    start = time.monotonic()
    while time.monotonic() - start < limit and time.monotonic() - last[0] < quiet:
        time.sleep(0.01)


def fq_name(name: str) -> str:
    """Topic/service names on the command line are taken as absolute ('/x' for 'x'); CliError
    for a name the ROS 2 rules refuse (checked before joining the graph)."""
    from roszen.names import InvalidNameError, expand_name
    name = name.strip()
    if not name:
        raise CliError("empty name")
    name = name if name.startswith("/") else "/" + name
    try:
        expand_name(name, "cli", "/")
    except InvalidNameError as exc:
        raise CliError(str(exc)) from None
    return name


def parse_yaml_values(text: str | None, type_name: str, factory):
    """Build a message from the YAML of the command line; CliError naming the bad part."""
    from roszen import yamltext
    try:
        data = yamltext.load(text, "the passed value") if text and text.strip() else {}
    except yamltext.YamlError as exc:
        raise CliError(str(exc)) from None
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise CliError(f"the passed value must be a YAML mapping of the fields of {type_name}, "
                       f"got {data!r}")
    try:
        return factory(data)
    except (ValueError, TypeError, KeyError, AttributeError, OverflowError) as exc:
        raise CliError(f"Failed to populate field of {type_name}: {exc}".replace("\n", " ")) \
            from None


def spin_until(node, done, timeout: float | None = None) -> bool:
    """Spin `node` until done() is true (or timeout); True when done."""
    import time
    deadline = None if timeout is None else time.monotonic() + timeout
    while not done():
        left = None if deadline is None else deadline - time.monotonic()
        if left is not None and left <= 0:
            return False
        node.spin_once(timeout_sec=0.05 if left is None else min(0.05, left))
    return True
