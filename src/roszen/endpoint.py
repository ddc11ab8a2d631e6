"""What the entities of a node share: the executor's work protocol, the endpoint's key
expression and liveliness token, the incoming size limit and Ctrl-C hand-back from zenoh threads."""
from __future__ import annotations

import inspect
from typing import TYPE_CHECKING, Any, Callable

import zenoh

from . import wire
from .executor import _pending_interrupts
from .qos import QoSProfile
from .sigint import zenoh_callback

if TYPE_CHECKING:
    from .node import Node


def _callback(fn) -> "zenoh.handlers.Callback":
    return zenoh.handlers.Callback(fn, indirect=False)


class _Entity:
    """Something the executor can run: a buffer of pending items and a handler."""
    _scheduled = False

    def _has_work(self) -> bool:
        return bool(self._buf)

    def _run(self, batch: int) -> bool:
        """Handle up to `batch` buffered items on the executor thread; True if any ran."""
        popleft, execute = self._buf.popleft, self._execute
        for i in range(batch):
            try:
                item = popleft()
            except IndexError:
                return i > 0
            execute(item)
        return True


def _max_bytes_default() -> int:
    """Incoming size limit per endpoint: ROSZEN_MAX_MESSAGE_BYTES, default 16 MiB."""
    import os
    try:
        v = int(os.environ.get("ROSZEN_MAX_MESSAGE_BYTES", ""))
        return v if v > 0 else DEFAULT_MAX_BYTES
    except ValueError:
        return DEFAULT_MAX_BYTES


DEFAULT_MAX_BYTES = 16 * 1024 * 1024


def _reraise_on_main(exc: BaseException) -> None:
    """Keep a KeyboardInterrupt/SystemExit caught in a zenoh callback for the spinning thread.

    zenoh-python runs some callbacks on the calling thread (a put/get delivered to a subscriber
    or queryable of the same session runs it inside that call) and swallows what they raise
    ("callback error"): Ctrl-C landing there would be lost. It is raised again once zenoh has
    returned: after the put/get, or by the executor's next step.
    """
    _pending_interrupts.append(exc)


def _guarded(fn: Callable) -> Callable:
    """`fn` for a zenoh callback that may run on the main thread: Ctrl-C is re-delivered, not lost."""
    @zenoh_callback
    def run(*a):
        try:
            fn(*a)
        except (KeyboardInterrupt, SystemExit) as e:
            _reraise_on_main(e)
    return run


class _Endpoint:
    """What publishers, subscriptions, services and clients share: the endpoint's key
    expression, liveliness token and GID (all derived from node, name, type and QoS), the
    token's declaration with graph registration, and undeclaring both on destroy."""

    _zobj: Any = None
    _token: Any = None

    def _init_endpoint(self, node: "Node", kind: str, name: str, sup: Any, qos: QoSProfile) -> None:
        self.node = node
        self._sup = sup
        ctx = node.context
        self._eid = ctx.next_id()
        self.key_expr = wire.topic_keyexpr(ctx.domain_id, name, sup.dds_name, sup.type_hash)
        self.token = wire.endpoint_token(ctx.domain_id, ctx.zid, node._nid, self._eid, kind, node._enclave,
                                         node.namespace, node.name, name, sup.dds_name, sup.type_hash, qos)
        self.gid = wire.gid_of(self.token)

    def _advertise(self, zobj: Any) -> None:
        """Keep the zenoh entity, declare the liveliness token and register it in the graph."""
        self._zobj = zobj
        ctx = self.node.context
        self._token = ctx.session.liveliness().declare_token(self.token)
        ctx.graph.add(self.token)

    def destroy(self) -> None:
        """Undeclare the token and the zenoh entity; the graph forgets the endpoint at once."""
        for obj in (self._token, self._zobj):
            if obj is None:
                continue
            try:
                obj.undeclare()
            except Exception:
                pass
        self.node.context.graph.remove(self.token)


def _arity(fn: Callable) -> int:
    try:
        params = [p for p in inspect.signature(fn).parameters.values()
                  if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD) and p.default is p.empty]
        return len(params)
    except (TypeError, ValueError):
        return 1
