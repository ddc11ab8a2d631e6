"""roszen.node_main.run on real rclpy: build the node, spin until Ctrl-C or shutdown, clean up;
a bad start is one line `<prog>: error: ...`, exit 1."""
from __future__ import annotations

import os
import sys
from typing import Any, Callable


def run(factory: Callable[[list[str]], Any], argv: list[str] | None = None,
        errors: tuple[type[BaseException], ...] = (ValueError,), prog: str | None = None) -> int:
    """As roszen.node_main.run (see there); rclpy's own signal handling ends the spin."""
    import rclpy
    from rclpy.executors import ExternalShutdownException
    argv = sys.argv if argv is None else argv
    try:
        try:
            wrapper = factory(argv)
        except errors as exc:
            name = prog or (os.path.basename(argv[0]) if argv else "node")
            print(f"{name}: error: {exc}", file=sys.stderr, flush=True)
            return 1
        except (KeyboardInterrupt, ExternalShutdownException):
            return 0
        spin = getattr(wrapper, "spin", None) or wrapper.node.spin
        close = getattr(wrapper, "close", None) or wrapper.node.destroy_node
        try:
            spin()
        except (KeyboardInterrupt, ExternalShutdownException):
            pass
        finally:
            try:
                close()
            except KeyboardInterrupt:
                pass
        return 0
    finally:
        rclpy.try_shutdown()
