"""`router [--port P | --listen E]`: the Zenoh router (rmw_zenohd equivalent)."""
from __future__ import annotations

import os

from roszen.cli.common import CliError, Parser


def main(argv: list[str], prog: str = "roszen") -> int:
    """Parse the router's options and run it until Ctrl-C."""
    p = Parser(prog=f"{prog} router", description="run the Zenoh router (rmw_zenohd equivalent)")
    p.add_argument("--port", type=int, default=None, help="TCP port on 127.0.0.1 (default 7447)")
    p.add_argument("--listen", default=None, help="zenoh endpoint(s), comma separated")
    args = p.parse_args(argv)
    from roszen import router
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
