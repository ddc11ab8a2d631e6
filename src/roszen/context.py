"""A ROS context: one zenoh session, its id counter and its graph cache."""
from __future__ import annotations

import atexit
import itertools
import threading
import weakref
from typing import Mapping, Optional, Sequence

import zenoh

from .log import Logger
from .zconfig import domain_id as env_domain_id, session_config


_all_contexts: "weakref.WeakSet" = weakref.WeakSet()
# the one wording of "no router" (the context says it once; the CLI verbs do not repeat it)
NO_ROUTER = ("no Zenoh router reachable (start one with `astrobee router` or "
             "`ros2 run rmw_zenoh_cpp rmw_zenohd`); continuing: the graph fills in once one is up")


class Context:
    """One zenoh peer session shared by every node/entity created on it."""

    def __init__(self, env: Optional[Mapping[str, str]] = None, domain_id: Optional[int] = None,
                 args: Optional[Sequence[str]] = None) -> None:
        self.domain_id = env_domain_id(env) if domain_id is None else int(domain_id)
        self.args = list(args) if args else []
        from .sigint import install_guard
        install_guard()      # Ctrl-C is never swallowed by a zenoh callback (as rclpy.init)
        self.session = zenoh.open(session_config(env))
        self.zid = str(self.session.zid()).lower()
        self.router_connected = self._wait_for_router(env)
        self._ids = itertools.count()
        self._id_lock = threading.Lock()
        self._nodes: "weakref.WeakSet" = weakref.WeakSet()
        self._closed = False
        _all_contexts.add(self)
        self.logger = Logger("roszen")
        from .graph import GraphCache
        self.graph = GraphCache(self.session, self.domain_id, self.logger)

    def _wait_for_router(self, env) -> bool:
        """Wait (bounded, ROSZEN_ROUTER_WAIT seconds, default 3) until a router is connected."""
        import os
        import time
        src = os.environ if env is None else env
        try:
            limit = float(src.get("ROSZEN_ROUTER_WAIT", "3"))
        except ValueError:
            limit = 3.0
        end = time.monotonic() + limit
        while True:
            try:
                if list(self.session.info.routers_zid()):
                    return True
            except Exception:
                return False
            if time.monotonic() >= end:
                Logger("roszen").warn(NO_ROUTER)
                return False
            time.sleep(0.01)

    def next_id(self) -> int:
        """nid/eid source: one counter per context starting at 0."""
        with self._id_lock:
            return next(self._ids)

    def ok(self) -> bool:
        return not self._closed

    def _register(self, node) -> None:
        self._nodes.add(node)

    def shutdown(self) -> None:
        """Destroy every node, then close the session."""
        if self._closed:
            return
        for node in list(self._nodes):
            try:
                node.destroy_node()
            except Exception:
                pass
        self._closed = True
        self.graph.close()
        try:
            self.session.close()
        except Exception:
            pass


_default: Optional[Context] = None
_default_lock = threading.Lock()


def init(args: Optional[Sequence[str]] = None, context: Optional[Context] = None, **kw) -> Context:
    """Create the process-wide default context (idempotent, like rclpy.init)."""
    global _default
    with _default_lock:
        if context is not None:
            _default = context
        elif _default is None or not _default.ok():
            _default = Context(args=args, **kw)
        return _default


def get_default_context() -> Context:
    return init()


def ok(context: Optional[Context] = None) -> bool:
    ctx = context or _default
    return ctx is not None and ctx.ok()


def shutdown(context: Optional[Context] = None) -> None:
    global _default
    ctx = context or _default
    if ctx is not None:
        ctx.shutdown()
    if ctx is _default:
        _default = None


def _shutdown_all() -> None:
    """Close every context still open when the program ends (nodes destroyed, sessions closed)."""
    if _default is not None:
        try:
            shutdown()
        except Exception:
            pass
    for ctx in list(_all_contexts):
        try:
            ctx.shutdown()
        except Exception:
            pass


# The interpreter joins non-daemon threads *before* running atexit hooks, and zenoh-python's
# callback threads are non-daemon: a program whose main thread ends without destroying its
# node would wait on them forever. threading's own exit hooks run before that join (the same
# hook concurrent.futures uses), so the session is closed there and its threads end.
try:
    threading._register_atexit(_shutdown_all)  # type: ignore[attr-defined]
except (AttributeError, RuntimeError):
    pass
atexit.register(_shutdown_all)
