"""The shared body of a node executable's main(): build the node, spin until Ctrl-C, clean up."""
from __future__ import annotations

import os
import signal
import sys
from typing import Any, Callable


def run(factory: Callable[[list[str]], Any], argv: list[str] | None = None,
        errors: tuple[type[BaseException], ...] = (ValueError,), prog: str | None = None) -> int:
    """Build `factory(argv)` (an object holding a roszen Node as `.node`) and spin it.

    The object's own `spin()` and `close()` are used when it has them, else its node's spin and
    destroy_node. An exception of `errors` while building (a bad parameter) ends the program
    with one line naming the executable (`prog`, else argv[0]) and the cause, exit code 1, no
    traceback; the half-built node's sessions are closed so the process does not hang on
    zenoh's threads. Ctrl-C (SIGINT) at any moment ends the program with exit code 0 and no
    traceback: see `_sigint_handler`."""
    argv = sys.argv if argv is None else argv
    old = _install_sigint()
    try:
        try:
            wrapper = factory(argv)
        except errors as exc:
            name = prog or (os.path.basename(argv[0]) if argv else "node")
            print(f"{name}: error: {exc}", file=sys.stderr, flush=True)
            from . import context
            context.shutdown()
            return 1
        except KeyboardInterrupt:
            from . import context
            context.shutdown()
            return 0
        spin = getattr(wrapper, "spin", None) or wrapper.node.spin
        close = getattr(wrapper, "close", None) or wrapper.node.destroy_node
        try:
            spin()
        except KeyboardInterrupt:
            pass
        finally:
            try:
                close()
            except KeyboardInterrupt:   # a second Ctrl-C while closing: stop closing, quietly
                pass
        return 0
    finally:
        if old is not None:
            signal.signal(signal.SIGINT, old)


def _install_sigint():
    """Make SIGINT a deferred KeyboardInterrupt (see roszen.sigint); the previous handler."""
    from .sigint import install_deferred
    return install_deferred()
