"""Node: roszen's Node API (the part the project's nodes use) over a real rclpy node, so the
same node code runs on any RMW of a ROS 2 Jazzy install or on the PyPI wheels.

Types are named as on roszen ('pkg/msg/Name'); messages are roszen's objects, crossing to rclpy
as CDR (raw publish and raw subscriptions; services through rclpy.serialization). Callbacks run
on the thread that spins the node (one SingleThreadedExecutor per node: rclpy 7.1.6's
EventsExecutor.spin busy-loops); one that raises is logged with its traceback, never ends the
spin. Graph queries are rclpy's, endpoint infos carrying `node_fqn` as roszen's do."""
from __future__ import annotations

from typing import Any, Callable, Optional, Sequence

from .. import codec
from ..clock import Time
from ..endpoint import _arity
from ..qos import CLOCK
from .bridge import (decode, from_rosidl, guarded, rclpy_qos, rosidl_class, to_rosidl,
                     type_name_of)
from .params import RclpyParameters


def ensure_init(argv: Optional[Sequence[str]] = None, **kw: Any) -> None:
    """rclpy.init once per process, with the process's --ros-args (remaps, -p, params files)."""
    import rclpy
    if not rclpy.ok():
        rclpy.init(args=list(argv) if argv else None, **kw)


def make_executor() -> Any:
    """One executor per node: SingleThreadedExecutor, or rclpy's EventsExecutor with
    ASTROBEE_RCLPY_EXECUTOR=events (driven by spin_once only: its spin() busy-loops in 7.1.6)."""
    import os
    if os.environ.get("ASTROBEE_RCLPY_EXECUTOR", "") == "events":
        from rclpy.experimental import EventsExecutor
        return EventsExecutor()
    from rclpy.executors import SingleThreadedExecutor
    return SingleThreadedExecutor()


class Clock:
    """A node's clock (rclpy's: sim time with use_sim_time) with roszen's `now()` (roszen Time,
    whose to_msg() is a roszen message) and `add_listener(cb(ns))` on each /clock sample."""

    def __init__(self, rclock: Any, node: "Optional[Node]" = None) -> None:
        self._rclock = rclock
        self._node = node
        self._listeners: list = []
        self._sub = None

    def now(self) -> Time:
        return Time(nanoseconds=self._rclock.now().nanoseconds)

    def add_listener(self, cb: Callable[[int], None]) -> None:
        self._listeners.append(cb)
        if self._sub is None and self._node is not None:
            def on_clock(msg: Any) -> None:
                ns = int(msg.clock.sec) * 1_000_000_000 + int(msg.clock.nanosec)
                for listener in list(self._listeners):
                    listener(ns)
            self._sub = self._node.create_subscription("rosgraph_msgs/msg/Clock", "/clock",
                                                       on_clock, CLOCK)


def wall_clock(use_sim_time: bool = False) -> Clock:
    """roszen's `Clock(False)`: a clock on wall time (rclpy's steady clock, for timers)."""
    from rclpy.clock import Clock as RclpyClock, ClockType
    if use_sim_time:
        raise ValueError("a sim-time clock is a node's: node.get_clock()")
    return Clock(RclpyClock(clock_type=ClockType.STEADY_TIME))


class EndpointInfo:
    """rclpy's TopicEndpointInfo with roszen's `node_fqn`, `namespace`, `ros_type`, `gid`, `qos`
    (a roszen profile; what DDS discovery does not tell, roszen's defaults), `type_hash` (the
    advertised RIHS01 string) and `token` (a key naming the endpoint)."""

    def __init__(self, info: Any, topic: str = "") -> None:
        from ..qos import Durability, QoSProfile, Reliability
        self.info = info
        ns = info.node_namespace.rstrip("/")
        self.node_fqn = f"{ns}/{info.node_name}"
        self.namespace = info.node_namespace
        self.gid = bytes(info.endpoint_gid)
        self.ros_type = info.topic_type
        q = info.qos_profile
        rel, dur = int(q.reliability), int(q.durability)
        self.qos = QoSProfile(depth=max(int(q.depth), 1),
                              reliability=Reliability(rel) if rel in (1, 2) else Reliability.RELIABLE,
                              durability=Durability(dur) if dur in (1, 2) else Durability.VOLATILE)
        h = str(getattr(info, "topic_type_hash", ""))
        self.type_hash = h if h.startswith("RIHS01_") else ""
        self.token = f"{self.node_fqn} {topic}"

    def __getattr__(self, name: str) -> Any:
        return getattr(self.info, name)


class Publisher:
    """Publishes roszen messages (serialised by the typestore) or CDR bytes."""

    def __init__(self, node: "Node", type_name: str, topic: str, qos: Any) -> None:
        self.msg_type = type_name
        self.qos_profile = qos
        self._serialize = codec.msg_support(type_name).serialize
        self._pub = node._rnode.create_publisher(rosidl_class(type_name), topic, rclpy_qos(qos))
        self.topic_name = self._pub.topic_name

    def publish(self, msg: Any) -> None:
        data = msg if isinstance(msg, bytes) else bytes(self._serialize(msg))
        self._pub.publish(data)

    def get_subscription_count(self) -> int:
        return self._pub.get_subscription_count()


class Client:
    """A service client: call_async(roszen request) -> a future of the roszen response."""

    def __init__(self, node: "Node", type_name: str, name: str) -> None:
        self._sup = codec.srv_support(type_name)     # `_sup`: as roszen's Client (ParameterClient)
        self._cls = rosidl_class(type_name, "srv")
        self._cli = node._rnode.create_client(self._cls, name)
        self._node = node

    def wait_for_service(self, timeout_sec: Optional[float] = None) -> bool:
        return self._cli.wait_for_service(timeout_sec=timeout_sec)

    def service_is_ready(self) -> bool:
        return self._cli.service_is_ready()

    def call_async(self, request: Any) -> "Future":
        req = to_rosidl(request, self._sup.request, self._cls.Request)
        return Future(self._cli.call_async(req), self._sup.response)

    def call(self, request: Any, timeout_sec: Optional[float] = None) -> Any:
        """Spin this node until the answer comes (TimeoutError after timeout_sec)."""
        fut = self.call_async(request)
        self._node.spin_until_future_complete(fut, timeout_sec)
        if not fut.done():
            raise TimeoutError(f"no answer from {self._cli.srv_name} in {timeout_sec} s")
        return fut.result()


class Future:
    """rclpy's future with the response converted to roszen's message."""

    def __init__(self, fut: Any, support: codec.MsgSupport) -> None:
        self._fut, self._support = fut, support

    def done(self) -> bool:
        return self._fut.done()

    def result(self) -> Any:
        r = self._fut.result()
        return None if r is None else from_rosidl(r, self._support)


class Node(RclpyParameters):
    """roszen's Node API over an rclpy node (see the module)."""

    def __init__(self, node_name: str, *, namespace: Optional[str] = None,
                 argv: Optional[Sequence[str]] = None, cli_args: Optional[Sequence[str]] = None,
                 **kw: Any) -> None:
        import rclpy.node
        from ..args import parse_args
        ensure_init(argv)
        self.user_args, _ = parse_args(list(argv or []))
        self._descriptors: dict = {}
        self._rnode = rclpy.node.Node(node_name, namespace=namespace or "",
                                      cli_args=list(cli_args) if cli_args else None, **kw)
        self._install_parameter_callback()
        self._runs = [0]               # callbacks run (spin_once's "did something")
        self._executor = make_executor()
        self._executor.add_node(self._rnode)
        self._clock = Clock(self._rnode.get_clock(), self)
        self._alive = True

    # -- names and helpers ------------------------------------------------------------------
    def get_name(self) -> str:
        return self._rnode.get_name()

    def get_namespace(self) -> str:
        return self._rnode.get_namespace()

    def get_fully_qualified_name(self) -> str:
        return self._rnode.get_fully_qualified_name()

    fully_qualified_name = property(get_fully_qualified_name)

    def resolve_topic_name(self, name: str, *, only_expand: bool = False) -> str:
        return self._rnode.resolve_topic_name(name, only_expand=only_expand)

    resolve_service_name = resolve_topic_name

    def get_logger(self) -> Any:
        return self._rnode.get_logger()

    def get_clock(self) -> Clock:
        return self._clock

    # -- entities ---------------------------------------------------------------------------
    def create_publisher(self, msg_type: Any, topic: str, qos_profile: Any = 10,
                         **_: Any) -> Publisher:
        return Publisher(self, type_name_of(msg_type), topic, qos_profile)

    def create_subscription(self, msg_type: Any, topic: str, callback: Callable,
                            qos_profile: Any = 10, *, raw: bool = False, **_: Any) -> Any:
        """Subscribe (raw: the callback gets the CDR bytes, else a roszen message; a
        malformed payload is logged at ERROR and dropped)."""
        name = type_name_of(msg_type)
        support = codec.msg_support(name)
        log = self.get_logger()
        if raw:
            cb = callback
        else:
            def cb(data: bytes) -> None:
                try:
                    msg = decode(support, data)
                except Exception as exc:  # noqa: BLE001 - drop and say so, as roszen does
                    log.error(f"dropped a sample on {topic}: malformed CDR payload "
                              f"({len(data)} bytes) for {name}: {exc}")
                    return
                callback(msg)
        return self._rnode.create_subscription(
            rosidl_class(name), topic, guarded(cb, log, f"subscription {topic}", self._runs),
            rclpy_qos(qos_profile), raw=True)

    def create_service(self, srv_type: Any, srv_name: str, callback: Callable,
                       qos_profile: Any = None, **_: Any) -> Any:
        """Serve: the handler gets a roszen request (and response) object. One that raises is
        logged and answered with the default response (rclpy has no error reply)."""
        name = type_name_of(srv_type, "srv")
        support = codec.srv_support(name)
        cls = rosidl_class(name, "srv")
        handler = guarded(callback, self.get_logger(), f"service {srv_name}", self._runs)
        two_args = _arity(callback) >= 2          # handler(req, resp) or handler(req), as roszen

        def serve(request: Any, response: Any) -> Any:
            req = from_rosidl(request, support.request)
            out = handler(req, support.response.cls()) if two_args else handler(req)
            return response if out is None else to_rosidl(out, support.response, cls.Response)
        return self._rnode.create_service(cls, srv_name, serve)

    def create_client(self, srv_type: Any, srv_name: str, qos_profile: Any = None,
                      **_: Any) -> Client:
        return Client(self, type_name_of(srv_type, "srv"), srv_name)

    def create_timer(self, timer_period_sec: float, callback: Callable, callback_group: Any = None,
                     clock: Any = None) -> Any:
        rclock = clock._rclock if isinstance(clock, Clock) else clock
        return self._rnode.create_timer(
            timer_period_sec, guarded(callback, self.get_logger(), "timer", self._runs),
            callback_group, clock=rclock)

    def destroy_subscription(self, sub: Any) -> bool:
        return self._rnode.destroy_subscription(sub)

    def destroy_publisher(self, pub: Any) -> bool:
        return self._rnode.destroy_publisher(pub._pub if isinstance(pub, Publisher) else pub)

    def destroy_client(self, client: Any) -> bool:
        return self._rnode.destroy_client(client._cli if isinstance(client, Client) else client)

    # -- graph ------------------------------------------------------------------------------
    def count_publishers(self, topic: str) -> int:
        return self._rnode.count_publishers(topic)

    def count_subscribers(self, topic: str) -> int:
        return self._rnode.count_subscribers(topic)

    def get_node_names(self) -> list:
        return self._rnode.get_node_names()

    def get_node_names_and_namespaces(self) -> list:
        return self._rnode.get_node_names_and_namespaces()

    def get_topic_names_and_types(self) -> list:
        return self._rnode.get_topic_names_and_types()

    def get_service_names_and_types(self) -> list:
        return self._rnode.get_service_names_and_types()

    def get_publishers_info_by_topic(self, topic: str) -> list:
        topic = self.resolve_topic_name(topic)
        return [EndpointInfo(i, topic) for i in self._rnode.get_publishers_info_by_topic(topic)]

    def get_subscriptions_info_by_topic(self, topic: str) -> list:
        topic = self.resolve_topic_name(topic)
        return [EndpointInfo(i, topic) for i in self._rnode.get_subscriptions_info_by_topic(topic)]

    # -- spinning ---------------------------------------------------------------------------
    def spin_once(self, timeout_sec: Optional[float] = None) -> bool:
        """Run at most one ready callback, waiting up to timeout_sec; whether one ran."""
        before = self._runs[0]
        self._executor.spin_once(timeout_sec=timeout_sec)
        return self._runs[0] != before

    def spin(self) -> None:
        import rclpy
        while self._alive and rclpy.ok():
            self._executor.spin_once(timeout_sec=0.25)

    def spin_until_future_complete(self, future: Any, timeout_sec: Optional[float] = None) -> None:
        import time
        end = None if timeout_sec is None else time.monotonic() + timeout_sec
        while not future.done():
            left = None if end is None else end - time.monotonic()
            if left is not None and left <= 0:
                return
            self._executor.spin_once(timeout_sec=0.05 if left is None else min(left, 0.05))

    def destroy_node(self) -> None:
        if not self._alive:
            return
        self._alive = False
        self._executor.remove_node(self._rnode)
        self._executor.shutdown(timeout_sec=0)
        self._rnode.destroy_node()

    def __enter__(self) -> "Node":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.destroy_node()
