"""The Zenoh router the graph needs (an rmw_zenohd stand-in): embedded or `python -m roszen.router`."""
from __future__ import annotations

import argparse
import signal
import sys
import threading
from typing import Optional, Sequence

import zenoh

from .zconfig import ConfigError, router_config


class Router:
    """A running router session; close() stops it."""

    def __init__(self, listen: Optional[str] = None) -> None:
        self.session = zenoh.open(router_config(listen))

    @property
    def zid(self) -> str:
        return str(self.session.zid())

    def close(self) -> None:
        try:
            self.session.close()
        except Exception:
            pass

    def __enter__(self) -> "Router":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def start_router(listen: Optional[str] = None) -> Router:
    """Run a router inside this process (e.g. tcp/127.0.0.1:7447)."""
    return Router(listen)


def main(argv: Optional[Sequence[str]] = None) -> int:
    ap = argparse.ArgumentParser(prog="roszen.router", description="Zenoh router for rmw_zenoh graphs")
    ap.add_argument("--listen", default=None,
                    help="endpoint(s), comma separated (default tcp/127.0.0.1:7447 or ZENOH_ROUTER_CONFIG_URI)")
    args = ap.parse_args(argv)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    try:
        router = start_router(args.listen)
    except (ConfigError, zenoh.ZError) as e:
        print(f"roszen.router: cannot start: {e}", file=sys.stderr)
        return 1
    print(f"roszen.router: running (zid {router.zid}, listen {args.listen or 'default'})", file=sys.stderr, flush=True)
    try:
        while not stop.wait(0.5):
            pass
    finally:
        router.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
