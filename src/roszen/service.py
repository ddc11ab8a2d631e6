"""Service: a queryable whose handler runs on the executor thread."""
from __future__ import annotations

import collections
import traceback
from typing import TYPE_CHECKING, Callable, Optional

import zenoh

from . import codec, wire
from .endpoint import _arity, _callback, _Endpoint, _Entity, _max_bytes_default, _reraise_on_main
from .qos import QoSProfile
from .sigint import zenoh_callback

if TYPE_CHECKING:
    from .node import Node


class Service(_Entity, _Endpoint):
    """A queryable (complete=true); the handler runs on the executor thread."""

    def __init__(self, node: "Node", srv_type: str, name: str, handler: Callable, qos: QoSProfile,
                 max_bytes: Optional[int] = None) -> None:
        sup = codec.srv_support(srv_type)
        self.srv_type = sup.name
        self.service_name = node.resolve_service_name(name)
        self.handler = handler
        self._two_args = _arity(handler) >= 2
        self._buf: collections.deque = collections.deque()
        self.max_bytes = max_bytes if max_bytes is not None else _max_bytes_default()
        self._warned: set = set()
        self._init_endpoint(node, wire.SERVICE, self.service_name, sup, qos)
        self._advertise(node.context.session.declare_queryable(self.key_expr, _callback(self._on_query),
                                                              complete=True))

    @zenoh_callback
    def _on_query(self, query: "zenoh.Query") -> None:  # zenoh thread (the caller's, for a local client)
        try:
            payload = query.payload
            if payload is not None and len(payload) > self.max_bytes:
                self._fail(query, f"request of {len(payload)} bytes is larger than this service's limit "
                                  f"of {self.max_bytes} bytes", key="oversize")
                query.drop()
                return
            self._buf.append(query)
            if not self._scheduled:
                self.node._executor.schedule(self)
        except (KeyboardInterrupt, SystemExit) as e:
            _reraise_on_main(e)

    def _fail(self, query, reason: str, key: Optional[str] = None) -> None:
        """Answer with a zenoh error reply; log it (once per `key` when one is given: floods)."""
        if key is None or key not in self._warned:
            if key is not None:
                self._warned.add(key)
                reason_log = reason + "; further ones are answered with an error silently"
            else:
                reason_log = reason
            self.node.get_logger().error(f"service {self.service_name}: {reason_log}")
        try:
            query.reply_err(f"{self.service_name}: {reason}")
        except Exception:
            pass

    def _execute(self, query: "zenoh.Query") -> None:
        try:
            att = query.attachment
            if att is None:
                self._fail(query, "request without the rmw_zenoh attachment (client seq + GID); ignored")
                return
            try:
                meta = wire.parse_attachment(att.to_bytes())
            except ValueError as e:
                self._fail(query, f"request with a malformed attachment: {e}")
                return
            payload = query.payload
            data = payload.to_bytes() if payload is not None else b""
            try:
                req = self._sup.request.deserialize(data)
            except Exception as e:
                self._fail(query, f"malformed request ({len(data)} bytes, not a {self.srv_type} request): {e}")
                return
            try:
                if self._two_args:
                    resp = self.handler(req, self._sup.response.cls())
                else:
                    resp = self.handler(req)
            except Exception as e:
                self.node.get_logger().error(
                    f"service {self.service_name} handler raised:\n{traceback.format_exc().rstrip()}")
                self._fail(query, f"handler raised {type(e).__name__}: {e}")
                return
            if not isinstance(resp, self._sup.response.cls):
                self._fail(query, f"handler returned {type(resp).__name__}, expected a {self.srv_type} response")
                return
            try:
                out = self._sup.response.serialize(resp)
            except Exception as e:
                self._fail(query, f"cannot serialise the handler's response: {e}")
                return
            query.reply(query.key_expr, out, attachment=wire.make_attachment(meta.sequence_number, meta.gid))
        finally:
            try:
                query.drop()
            except Exception:
                pass
