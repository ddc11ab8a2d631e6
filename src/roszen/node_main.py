"""The shared body of a node executable's main(): build the node, spin until Ctrl-C, clean up."""
from __future__ import annotations

import os
import sys
from typing import Any, Callable


def run(factory: Callable[[list[str]], Any], argv: list[str] | None = None,
        errors: tuple[type[BaseException], ...] = (ValueError,), prog: str | None = None) -> int:
    """Build `factory(argv)` (an object holding a roszen Node as `.node`) and spin it.

    The object's own `spin()` and `close()` are used when it has them, else its node's spin and
    destroy_node. An exception of `errors` while building (a bad parameter) ends the program
    with one line naming the executable (`prog`, else argv[0]) and the cause, exit code 1, no
    traceback; the half-built node's sessions are closed so the process does not hang on
    zenoh's threads."""
    argv = sys.argv if argv is None else argv
    try:
        wrapper = factory(argv)
    except errors as exc:
        name = prog or (os.path.basename(argv[0]) if argv else "node")
        print(f"{name}: error: {exc}", file=sys.stderr, flush=True)
        from . import context
        context.shutdown()
        return 1
    spin = getattr(wrapper, "spin", None) or wrapper.node.spin
    close = getattr(wrapper, "close", None) or wrapper.node.destroy_node
    try:
        spin()
    except KeyboardInterrupt:
        pass
    finally:
        close()
    return 0
