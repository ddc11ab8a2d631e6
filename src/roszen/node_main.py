"""The shared body of a node executable's main(): build the node, spin until Ctrl-C, clean up."""
from __future__ import annotations

import os
import signal
import sys
import threading
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
    """Make SIGINT a deferred KeyboardInterrupt (the previous handler, or None off the main thread).

    The default handler raises wherever the main thread is, and that can be inside a zenoh
    callback run on it (a same-session delivery during a put): zenoh prints "callback error ...
    KeyboardInterrupt", swallows it and the node keeps running. Here the first SIGINT is queued
    (roszen.executor.request_interrupt) and raised at the next executor step or publish, on the
    main thread outside zenoh; a second SIGINT raises at once."""
    if threading.current_thread() is not threading.main_thread():
        return None
    from .executor import request_interrupt
    count = [0]

    def handler(signum, frame):  # noqa: ARG001
        count[0] += 1
        if count[0] > 1:
            raise KeyboardInterrupt
        request_interrupt()
    try:
        return signal.signal(signal.SIGINT, handler)
    except ValueError:
        return None
