"""Node: names, parameters, clock, logger and the factories of its entities over rmw_zenoh.

Each entity has its module (publisher, subscription, service, client, timer), as in rclpy;
they are re-exported here for code that imports them from roszen.node."""
from __future__ import annotations

import threading
from typing import Any, Callable, Optional, Sequence

from . import codec, wire
from .args import load_params_file, parse_args
from .client import Client, ServiceError
from .clock import Clock, ClockSource
from .context import Context, get_default_context
from .endpoint import DEFAULT_MAX_BYTES, _max_bytes_default
from .executor import Executor
from .log import Logger, severity_from_name
from .names import apply_remap, expand_name, normalize_namespace, validate_node_name
from .parameters import (InvalidParameterTypeException, InvalidParameterValueException, Parameter,
                         ParameterAlreadyDeclaredException, ParameterDescriptor,
                         ParameterImmutableException, ParameterNotDeclaredException, ParameterType,
                         SetParametersResult, check_value, coerce, infer_type)
from .publisher import Publisher
from .qos import CLOCK, SERVICES_DEFAULT, QoSProfile, as_qos
from .service import Service
from .subscription import Subscription
from .timer import Rate, Timer

__all__ = ["Client", "DEFAULT_MAX_BYTES", "Node", "Publisher", "Rate", "Service", "ServiceError",
           "Subscription", "Timer", "_max_bytes_default"]


class Node:
    """A ROS 2 node: names, parameters, clock, logger and the entities above."""

    def __init__(self, node_name: str, *, namespace: Optional[str] = None, context: Optional[Context] = None,
                 argv: Optional[Sequence[str]] = None, cli_args: Optional[Sequence[str]] = None,
                 parameter_overrides: Optional[list] = None, use_global_arguments: bool = True,
                 start_parameter_services: bool = True, enable_rosout: bool = True,
                 automatically_declare_parameters_from_overrides: bool = False,
                 allow_undeclared_parameters: bool = False) -> None:
        self.context = context or get_default_context()
        args: list = []
        if use_global_arguments:
            args += list(self.context.args)
        if argv:
            args += list(argv)
        if cli_args:
            args += ["--ros-args", *cli_args] if "--ros-args" not in cli_args else list(cli_args)
        self.user_args, ros = parse_args(args)
        self.name = validate_node_name(ros.node_name or node_name)
        self.namespace = normalize_namespace(ros.namespace if ros.namespace is not None else (namespace or ""))
        self._enclave = ros.enclave or "/"
        self._remaps = ros.remaps_for(self.name)
        self._logger = Logger(self.namespace.strip("/").replace("/", ".") + "." + self.name
                              if self.namespace != "/" else self.name)
        if ros.log_level:
            self._logger.set_level(severity_from_name(ros.log_level))
        self._alive = True
        self._timers: list = []
        self._pubs: list = []
        self._subs: list = []
        self._srvs: list = []
        self._clients: list = []
        self._executor = Executor()
        self._executor.add_node(self)
        self._params: dict = {}
        self._descriptors: dict = {}
        self._param_callbacks: list = []
        self._param_lock = threading.RLock()   # a set from a service and one from code: one at a time
        self._allow_undeclared = allow_undeclared_parameters
        # overrides: files first (in order), then -p, then explicit overrides
        overrides: dict = {}
        for path in ros.params_files:
            overrides.update(load_params_file(path, self.name, self.namespace))
        for node, name, value in ros.params:
            if node in (None, self.name, self.fully_qualified_name):
                overrides[name] = value
        for p in parameter_overrides or []:
            overrides[p.name] = p.value
        self._overrides = overrides
        self._clock = Clock(False)
        self._clock_sub = None
        ctx = self.context
        self._nid = ctx.next_id()
        self.token = wire.node_token(ctx.domain_id, ctx.zid, self._nid, self._enclave, self.namespace, self.name)
        self._token = ctx.session.liveliness().declare_token(self.token)
        ctx.graph.add(self.token)
        ctx._register(self)
        self.declare_parameter("use_sim_time", False)
        if automatically_declare_parameters_from_overrides:
            for k, v in overrides.items():
                if k not in self._params:
                    self.declare_parameter(k, v)
        self._param_services = None
        if start_parameter_services:
            from .param_services import ParameterServices
            try:
                self._param_services = ParameterServices(self)
            except codec.TypeSupportError as e:
                self._logger.debug(f"parameter services not started: {e}")
        self._rosout = None
        if enable_rosout:
            from .rosout import attach_rosout
            self._rosout = attach_rosout(self)

    # -- names --------------------------------------------------------------------------------
    def get_name(self) -> str:
        return self.name

    def get_namespace(self) -> str:
        return self.namespace

    @property
    def fully_qualified_name(self) -> str:
        return (self.namespace.rstrip("/") + "/" + self.name) if self.namespace != "/" else "/" + self.name

    def get_fully_qualified_name(self) -> str:
        return self.fully_qualified_name

    def resolve_topic_name(self, name: str, *, only_expand: bool = False) -> str:
        fq = expand_name(name, self.name, self.namespace)
        return fq if only_expand else apply_remap(fq, self._remaps, self.name, self.namespace)

    resolve_service_name = resolve_topic_name

    def get_logger(self) -> Logger:
        return self._logger

    def get_clock(self) -> Clock:
        return self._clock

    @property
    def executor(self) -> Executor:
        return self._executor

    # -- entities -----------------------------------------------------------------------------
    def _check_alive(self) -> None:
        if not self._alive:
            raise RuntimeError(f"node {self.fully_qualified_name} has been destroyed")

    def create_publisher(self, msg_type: Any, topic: str, qos_profile: "QoSProfile | int" = 10,
                         *, callback_group: Any = None, event_callbacks: Any = None,
                         qos_overriding_options: Any = None) -> Publisher:
        """Publish on `topic` (rclpy's callback_group / event_callbacks / qos_overriding_options
        are accepted and have no effect here; any other keyword is a TypeError)."""
        self._check_alive()
        pub = Publisher(self, _type_name(msg_type), topic, as_qos(qos_profile))
        self._pubs.append(pub)
        return pub

    def create_subscription(self, msg_type: Any, topic: str, callback: Callable,
                            qos_profile: "QoSProfile | int" = 10, *, raw: bool = False,
                            max_bytes: Optional[int] = None, callback_group: Any = None,
                            event_callbacks: Any = None, qos_overriding_options: Any = None
                            ) -> Subscription:
        """Subscribe; samples above `max_bytes` (default ROSZEN_MAX_MESSAGE_BYTES or 16 MiB) are dropped."""
        self._check_alive()
        sub = Subscription(self, _type_name(msg_type), topic, callback, as_qos(qos_profile), raw=raw,
                           max_bytes=max_bytes)
        self._subs.append(sub)
        return sub

    def create_service(self, srv_type: Any, srv_name: str, callback: Callable,
                       qos_profile: "QoSProfile | int" = SERVICES_DEFAULT, *, max_bytes: Optional[int] = None,
                       callback_group: Any = None) -> Service:
        """Serve; requests above `max_bytes` (default as subscriptions) get an error reply."""
        self._check_alive()
        srv = Service(self, _type_name(srv_type, "srv"), srv_name, callback, as_qos(qos_profile),
                      max_bytes=max_bytes)
        self._srvs.append(srv)
        return srv

    def create_client(self, srv_type: Any, srv_name: str,
                      qos_profile: "QoSProfile | int" = SERVICES_DEFAULT, *,
                      callback_group: Any = None) -> Client:
        self._check_alive()
        cli = Client(self, _type_name(srv_type, "srv"), srv_name, as_qos(qos_profile))
        self._clients.append(cli)
        return cli

    def create_timer(self, timer_period_sec: float, callback: Callable, callback_group: Any = None,
                     clock: Any = None) -> Timer:
        self._check_alive()
        t = Timer(self, timer_period_sec, callback, self._clock if clock is None else clock)
        self._timers.append(t)
        self._executor.wake()
        return t

    def create_rate(self, frequency: float) -> "Rate":
        return Rate(self._clock, frequency)

    def _destroy(self, lst: list, ent) -> bool:
        if ent in lst:
            lst.remove(ent)
            ent.destroy()
            return True
        return False

    def destroy_publisher(self, pub: Publisher) -> bool:
        return self._destroy(self._pubs, pub)

    def destroy_subscription(self, sub: Subscription) -> bool:
        return self._destroy(self._subs, sub)

    def destroy_service(self, srv: Service) -> bool:
        return self._destroy(self._srvs, srv)

    def destroy_client(self, cli: Client) -> bool:
        return self._destroy(self._clients, cli)

    def destroy_timer(self, t: Timer) -> bool:
        return self._destroy(self._timers, t)

    def _entities_with_work(self) -> list:
        return [e for e in self._subs + self._srvs if e._has_work()]

    def count_publishers(self, topic: str) -> int:
        return self.context.graph.count_publishers(self.resolve_topic_name(topic))

    def count_subscribers(self, topic: str) -> int:
        return self.context.graph.count_subscribers(self.resolve_topic_name(topic))

    def get_node_names(self) -> list:
        return self.context.graph.get_node_names()

    def get_node_names_and_namespaces(self) -> list:
        return self.context.graph.get_node_names_and_namespaces()

    def get_topic_names_and_types(self) -> list:
        return self.context.graph.get_topic_names_and_types()

    def get_service_names_and_types(self) -> list:
        return self.context.graph.get_service_names_and_types()

    def get_publishers_info_by_topic(self, topic: str) -> list:
        return self.context.graph.get_publishers_info_by_topic(self.resolve_topic_name(topic))

    def get_subscriptions_info_by_topic(self, topic: str) -> list:
        return self.context.graph.get_subscriptions_info_by_topic(self.resolve_topic_name(topic))

    # -- spinning -----------------------------------------------------------------------------
    def spin_once(self, timeout_sec: Optional[float] = None) -> bool:
        return self._executor.spin_once(timeout_sec)

    def spin(self) -> None:
        self._executor.spin()

    def spin_until_future_complete(self, future, timeout_sec: Optional[float] = None) -> None:
        self._executor.spin_until_future_complete(future, timeout_sec)

    def destroy_node(self) -> None:
        """Undeclare every entity and the node token (the graph sees it gone at once)."""
        if not self._alive:
            return
        self._alive = False
        if self._param_services is not None:
            self._param_services = None
        for lst in (self._subs, self._srvs, self._clients, self._pubs, self._timers):
            for ent in list(lst):
                ent.destroy()
            lst.clear()
        if self._clock_sub is not None:
            self._clock_sub.destroy()
            self._clock_sub = None
        try:
            self._token.undeclare()
        except Exception:
            pass
        self.context.graph.remove(self.token)
        self._executor.wake()

    def __enter__(self) -> "Node":
        return self

    def __exit__(self, *exc) -> None:
        self.destroy_node()

    # -- parameters ---------------------------------------------------------------------------
    def declare_parameter(self, name: str, value: Any = None,
                          descriptor: Optional[ParameterDescriptor] = None,
                          ignore_override: bool = False) -> Parameter:
        """Declare a typed parameter; an override from YAML/--ros-args wins over the default."""
        if name in self._params:
            raise ParameterAlreadyDeclaredException(f"parameter {name!r} is already declared")
        if isinstance(value, ParameterType):
            value = None
        desc = descriptor or ParameterDescriptor()
        desc.name = name
        default_type = infer_type(value)
        v = value
        if not ignore_override and name in self._overrides:
            ov = self._overrides[name]
            if default_type != ParameterType.NOT_SET and not desc.dynamic_typing:
                try:
                    v = coerce(ov, default_type)
                except InvalidParameterTypeException as e:
                    raise InvalidParameterTypeException(
                        f"parameter {name!r} override has the wrong type: {e}") from None
            else:
                v = ov
        p = Parameter(name, value=v)
        desc.type = int(p.type_) if not desc.dynamic_typing else desc.type
        self._check_range(p, desc)
        self._params[name] = p
        self._descriptors[name] = desc
        if name == "use_sim_time":
            self._set_sim_time(bool(p.value))
        return p

    def declare_parameters(self, namespace: str, parameters: list) -> list:
        out = []
        for entry in parameters:
            name, value, desc = (tuple(entry) + (None, None))[:3]
            full = f"{namespace}.{name}" if namespace else name
            out.append(self.declare_parameter(full, value, desc))
        return out

    def has_parameter(self, name: str) -> bool:
        return name in self._params

    def get_parameter(self, name: str) -> Parameter:
        if name in self._params:
            return self._params[name]
        if self._allow_undeclared:
            return Parameter(name, ParameterType.NOT_SET, None)
        raise ParameterNotDeclaredException(name)

    def get_parameter_or(self, name: str, alternative_value: Optional[Parameter] = None) -> Parameter:
        return self._params.get(name, alternative_value if alternative_value is not None
                                else Parameter(name, ParameterType.NOT_SET, None))

    def get_parameters(self, names: list) -> list:
        return [self.get_parameter(n) for n in names]

    def get_parameters_by_prefix(self, prefix: str) -> dict:
        pre = prefix + "." if prefix else ""
        return {k[len(pre):]: p for k, p in self._params.items() if k.startswith(pre)}

    def describe_parameter(self, name: str) -> ParameterDescriptor:
        if name not in self._descriptors:
            raise ParameterNotDeclaredException(name)
        return self._descriptors[name]

    def undeclare_parameter(self, name: str) -> None:
        if name not in self._params:
            raise ParameterNotDeclaredException(name)
        if self._descriptors[name].read_only:
            raise ParameterImmutableException(f"parameter {name!r} is read-only")
        del self._params[name]
        del self._descriptors[name]

    def add_on_set_parameters_callback(self, callback: Callable) -> Callable:
        self._param_callbacks.append(callback)
        return callback

    def remove_on_set_parameters_callback(self, callback: Callable) -> None:
        self._param_callbacks.remove(callback)

    def _check_range(self, p: Parameter, desc: ParameterDescriptor) -> None:
        check_value(p, desc)   # range (non-finite is outside), validator

    def _validate(self, p: Parameter) -> Parameter:
        if p.name not in self._params:
            if not self._allow_undeclared:
                raise ParameterNotDeclaredException(p.name)
            return p
        desc = self._descriptors[p.name]
        if desc.read_only:
            raise ParameterImmutableException(f"parameter {p.name!r} is read-only")
        cur = self._params[p.name]
        if not desc.dynamic_typing and cur.type_ != ParameterType.NOT_SET and p.type_ != cur.type_:
            try:
                p = Parameter(p.name, value=coerce(p.value, cur.type_))
            except InvalidParameterTypeException as e:
                raise InvalidParameterTypeException(f"parameter {p.name!r}: {e}") from None
        self._check_range(p, desc)
        return p

    def set_parameters_atomically(self, parameters: list) -> SetParametersResult:
        """Set all or none: every value is validated first; if one `on_change` then refuses,
        those already applied get their old values back and nothing is stored."""
        with self._param_lock:
            try:
                checked = [self._validate(p) for p in parameters]
                if len({p.name for p in checked}) != len(checked):
                    raise InvalidParameterValueException("a parameter is named twice")
            except Exception as e:  # noqa: BLE001 - any refusal is a failed set, never a crash
                return SetParametersResult(False, str(e))
            for cb in self._param_callbacks:
                r = cb(checked)
                if r is not None and not r.successful:
                    return r
            applied: list = []
            for p in checked:
                apply = getattr(self._descriptors.get(p.name), "on_change", None)
                if apply is None or p.type_ == ParameterType.NOT_SET:
                    continue
                try:
                    apply(p.value)
                except Exception as e:  # noqa: BLE001 - a failing apply must not kill the node
                    for name, undo in reversed(applied):
                        try:
                            undo(self._params[name].value)
                        except Exception as e2:  # noqa: BLE001
                            self._logger.error(f"parameter {name!r}: restoring its value failed: {e2}")
                    return SetParametersResult(False, f"parameter {p.name!r} not applied: {e}")
                applied.append((p.name, apply))
            for p in checked:
                if p.type_ == ParameterType.NOT_SET and p.name in self._params:
                    del self._params[p.name]
                    continue
                self._params[p.name] = p
                self._descriptors.setdefault(p.name, ParameterDescriptor(name=p.name, type=int(p.type_)))
                if p.name == "use_sim_time":
                    self._set_sim_time(bool(p.value))
            return SetParametersResult(True, "")

    def set_parameters(self, parameters: list) -> list:
        return [self.set_parameters_atomically([p]) for p in parameters]

    def set_parameter(self, parameter: Parameter) -> SetParametersResult:
        return self.set_parameters_atomically([parameter])

    # -- sim time -----------------------------------------------------------------------------
    def _set_sim_time(self, on: bool) -> None:
        if on and self._clock_sub is None:
            source = ClockSource(self.context.graph, log=self.get_logger().warn)

            def on_clock(msg, gid: bytes) -> None:
                if source.accept(gid):
                    self._clock.set_sim_time(int(msg.clock.sec) * 1_000_000_000 + int(msg.clock.nanosec))
            sub = Subscription(self, "rosgraph_msgs/msg/Clock", "/clock", on_clock, CLOCK, direct=True,
                               with_source=True)
            self._clock_sub = sub
        elif not on and self._clock_sub is not None:
            self._clock_sub.destroy()
            self._clock_sub = None
        self._clock.set_sim_time_active(on)
        for t in self._timers:
            if t.clock is self._clock:   # a timer on its own (wall) clock keeps its schedule
                t._next = self._clock.now_ns() + t.timer_period_ns
        self._executor.wake()


def _type_name(t: Any, kind: str = "msg") -> str:
    if isinstance(t, str):
        return codec.normalize_type_name(t, kind)
    for attr in ("__msgtype__", "_type", "__typename__", "TYPE_NAME"):
        v = getattr(t, attr, None)
        if isinstance(v, str):
            return codec.normalize_type_name(v, kind)
    raise TypeError(f"pass the type as a name like 'pkg/{kind}/Name', got {t!r}")
