"""Client: calls a service (a zenoh querier); ServiceError when the server fails the call."""
from __future__ import annotations

import concurrent.futures
import itertools
import threading
from typing import TYPE_CHECKING, Any, Optional

import zenoh

from . import codec, wire
from .endpoint import _Endpoint, _guarded
from .executor import _pending_interrupts, raise_pending
from .qos import QoSProfile

if TYPE_CHECKING:
    from .node import Node


def _collect(replies, on_reply, on_done) -> None:
    """Hand each reply of one call to on_reply, then call on_done (the query's end)."""
    try:
        for reply in replies:
            on_reply(reply)
    finally:
        on_done()


class ServiceError(RuntimeError):
    """The service server failed the request (handler raised, malformed request, no server)."""


class Client(_Endpoint):
    """Service client: zenoh get (ALL_COMPLETE, no consolidation) with the request attachment."""

    def __init__(self, node: "Node", srv_type: str, name: str, qos: QoSProfile,
                 query_timeout: float = 600.0) -> None:
        sup = codec.srv_support(srv_type)
        self.srv_type = sup.name
        self.srv_name = node.resolve_service_name(name)
        self._init_endpoint(node, wire.CLIENT, self.srv_name, sup, qos)
        self._seq = itertools.count(1)
        self._querier = node.context.session.declare_querier(
            self.key_expr, target=zenoh.QueryTarget.ALL_COMPLETE,
            consolidation=zenoh.ConsolidationMode.NONE, timeout=query_timeout)
        self._advertise(self._querier)

    def service_is_ready(self) -> bool:
        return self.node.context.graph.service_is_available(self.srv_name, self._sup.dds_name, self._sup.type_hash)

    def wait_for_service(self, timeout_sec: Optional[float] = None) -> bool:
        """True once a server of this name and type is in the graph."""
        return self.node.context.graph.wait_for(self.service_is_ready, timeout_sec)

    def call_async(self, request: Any) -> "concurrent.futures.Future":
        """Send the request; the Future resolves (on the call's reader thread) to the response or a ServiceError."""
        if not isinstance(request, self._sup.request.cls):
            raise TypeError(f"client {self.srv_name} expects a {self.srv_type} request, got {type(request).__name__}")
        data = self._sup.request.serialize(request)
        seq = next(self._seq)
        fut: concurrent.futures.Future = concurrent.futures.Future()
        fut.set_running_or_notify_cancel()
        errors: list = []
        sup = self._sup

        def on_reply(reply: "zenoh.Reply") -> None:
            if fut.done():
                return
            if reply.ok is None:
                try:
                    errors.append(reply.err.payload.to_bytes().decode(errors="replace"))
                except Exception:
                    errors.append("error reply")
                return
            sample = reply.ok
            att = sample.attachment
            try:
                meta = wire.parse_attachment(att.to_bytes()) if att is not None else None
            except ValueError:
                meta = None
            if meta is not None and (meta.sequence_number != seq or meta.gid != self.gid):
                return  # not ours
            try:
                resp = sup.response.deserialize(sample.payload.to_bytes())
            except Exception as e:
                errors.append(f"malformed response: {e}")
                return
            try:
                fut.set_result(resp)
            except concurrent.futures.InvalidStateError:
                pass

        def on_done() -> None:
            if not fut.done():
                why = "; ".join(errors) if errors else "no service server replied"
                try:
                    fut.set_exception(ServiceError(f"{self.srv_name}: {why}"))
                except concurrent.futures.InvalidStateError:
                    pass

        # the replies through zenoh's own channel, read by a thread per call: a Python callback
        # would be dropped on zenoh's thread under the session's lock when the query ends,
        # taking the GIL there, and a node undeclaring an entity meanwhile (holding the GIL,
        # waiting for that lock) deadlocks (as roszen.graph's start-up query did)
        token = zenoh.CancellationToken()    # call() ends the query (and its thread) on timeout
        fut.cancel_query = token.cancel      # type: ignore[attr-defined]
        replies = self._querier.get(payload=data, attachment=wire.make_attachment(seq, self.gid),
                                    cancellation_token=token)
        threading.Thread(target=_collect, args=(replies, _guarded(on_reply), _guarded(on_done)),
                         name=f"roszen-client{self.srv_name}", daemon=True).start()
        if _pending_interrupts:
            raise_pending()
        return fut

    def call(self, request: Any, timeout_sec: Optional[float] = None) -> Any:
        """Blocking call; raises TimeoutError or ServiceError. Safe inside callbacks."""
        fut = self.call_async(request)
        try:
            return fut.result(timeout=timeout_sec)
        except concurrent.futures.TimeoutError:
            fut.cancel_query()
            raise TimeoutError(f"service {self.srv_name} did not answer within {timeout_sec} s") from None
