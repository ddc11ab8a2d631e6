"""The shared body of a node executable's main(): build the node, spin until Ctrl-C, clean up."""
from __future__ import annotations

import sys
from typing import Any, Callable


def run(factory: Callable[[list[str]], Any], argv: list[str] | None = None) -> int:
    """Build `factory(argv)` (an object holding a roszen Node as `.node`) and spin it."""
    argv = sys.argv if argv is None else argv
    wrapper = factory(argv)
    try:
        wrapper.node.spin()
    except KeyboardInterrupt:
        pass
    finally:
        wrapper.node.destroy_node()
    return 0
