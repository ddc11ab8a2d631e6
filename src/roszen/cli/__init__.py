"""ros2-style command verbs over roszen: topic, service, node, interface, bag, run, router.

`main(argv, prog)` is what `astrobee <verb> ...` (and `python -m roszen.cli`) runs. Syntax and
output follow the `ros2` command so the same habits and scripts work.
"""
from __future__ import annotations

import argparse
import sys

from roszen.cli.common import CliError, Parser, line_buffered

VERBS = ("topic", "service", "node", "param", "interface", "bag", "run", "router")


def build_parser(prog: str) -> argparse.ArgumentParser:
    from roszen.cli import bagcmd, graphcmd, interface, param, service, topic
    p = Parser(prog=prog, description="ros2-style tools over rmw_zenoh")
    sub = p.add_subparsers(dest="verb", metavar="verb")
    sub.required = True
    topic.add_parser(sub)
    service.add_parser(sub)
    graphcmd.add_parser(sub)
    param.add_parser(sub)
    interface.add_parser(sub)
    bagcmd.add_parser(sub)
    _router_args(sub.add_parser("router", help="run the Zenoh router (rmw_zenohd equivalent)"))
    return p


def _router_args(r: argparse.ArgumentParser) -> None:
    r.add_argument("--port", type=int, default=None, help="TCP port on 127.0.0.1 (default 7447)")
    r.add_argument("--listen", default=None, help="zenoh endpoint(s), comma separated")
    r.set_defaults(func=_router)


def _router(args) -> int:
    from roszen import router
    import os

    from roszen.zconfig import ConfigError, parse_override
    listen = args.listen or (f"tcp/127.0.0.1:{args.port}" if args.port else None)
    if listen and os.environ.get("ZENOH_CONFIG_OVERRIDE"):
        # an explicit --port/--listen wins over a session override's endpoints
        try:
            items = parse_override(os.environ["ZENOH_CONFIG_OVERRIDE"])
        except ConfigError as exc:
            raise CliError(str(exc)) from None
        os.environ["ZENOH_CONFIG_OVERRIDE"] = ";".join(
            f"{k}={v}" for k, v in items if k.strip("/") not in ("listen/endpoints",
                                                                 "connect/endpoints"))
    return router.main(["--listen", listen] if listen else [])


def main(argv: list[str] | None = None, prog: str = "roszen", registry=None) -> int:
    """Run one verb; user errors print one line `<prog> <verb>: <reason>` and return 1."""
    line_buffered()
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv and argv[0] == "run":
        return _run(argv[1:], prog, registry)
    try:
        if argv and argv[0] == "router":    # no verb modules needed: starts fast
            parser = Parser(
                prog=f"{prog} router", description="run the Zenoh router (rmw_zenohd equivalent)")
            _router_args(parser)
            args = parser.parse_args(argv[1:])
        else:
            parser = build_parser(prog)
            args = parser.parse_args(argv)
        return int(args.func(args) or 0)
    except CliError as exc:
        verb = " ".join(a for a in argv[:2] if not a.startswith("-"))
        print(f"{prog} {verb}: {exc}" if verb else f"{prog}: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 0
    except BrokenPipeError:
        return 0


def _run(argv: list[str], prog: str, registry) -> int:
    from roszen.cli.run import exec_node, packages
    if not argv or argv[0] in ("-h", "--help"):
        print(f"usage: {prog} run PACKAGE EXECUTABLE [args ...] [--ros-args ...]")
        for pkg, exes in sorted(packages(registry).items()):
            print(f"  {pkg}: {', '.join(sorted(exes))}")
        return 0 if argv else 2
    if len(argv) < 2:
        print(f"{prog} run: missing executable name (usage: {prog} run PACKAGE EXECUTABLE)",
              file=sys.stderr)
        return 2
    try:
        exec_node(argv[0], argv[1], argv[2:], registry)
    except CliError as exc:
        print(f"{prog} run: {exc}", file=sys.stderr)
        return 1
    return 0   # not reached: exec replaced the process
