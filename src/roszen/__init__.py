"""roszen: a small rclpy-like ROS 2 client library speaking rmw_zenoh (Jazzy) over eclipse-zenoh."""
from __future__ import annotations

from typing import Optional

from .clock import Clock, Duration, Time
from .context import Context, get_default_context, init, ok, shutdown
from .executor import (Executor, SingleThreadedExecutor, spin, spin_once,
                       spin_until_future_complete)
from .log import Logger, LoggingSeverity, get_logger
from .client import Client, ServiceError
from .node import Node
from .publisher import Publisher
from .service import Service
from .subscription import Subscription
from .timer import Rate, Timer
from .parameters import Parameter, ParameterDescriptor, ParameterType, SetParametersResult
from .qos import (CLOCK, LATCHED, SENSOR_DATA, DEFAULT_DEPTH, Durability, DurabilityPolicy, History,
                  HistoryPolicy, Liveliness, QoSProfile, Reliability, ReliabilityPolicy,
                  qos_profile_sensor_data, qos_profile_services_default)


def message_class(name: str) -> type:
    """Class of a message type such as 'geometry_msgs/msg/PoseStamped' (fields defaulted)."""
    from . import typestore
    return typestore.message_class(name)


def request_class(name: str) -> type:
    """Request class of a service type such as 'std_srvs/srv/Trigger'."""
    from . import typestore
    return typestore.request_class(name)


def response_class(name: str) -> type:
    """Response class of a service type such as 'std_srvs/srv/Trigger'."""
    from . import typestore
    return typestore.response_class(name)


def create_node(node_name: str, *, namespace: Optional[str] = None, **kw) -> Node:
    """rclpy.create_node equivalent."""
    return Node(node_name, namespace=namespace, **kw)


__all__ = [
    "Client", "Clock", "Context", "Duration", "Durability", "DurabilityPolicy", "Executor", "History",
    "HistoryPolicy", "LATCHED", "Liveliness", "Logger", "LoggingSeverity", "Node", "Parameter",
    "ParameterDescriptor", "ParameterType", "Publisher", "QoSProfile", "Rate", "Reliability",
    "ReliabilityPolicy", "SENSOR_DATA", "CLOCK", "DEFAULT_DEPTH", "Service", "ServiceError",
    "SetParametersResult", "SingleThreadedExecutor", "Subscription", "Time", "Timer", "create_node",
    "get_default_context", "get_logger", "init", "message_class", "ok", "qos_profile_sensor_data",
    "qos_profile_services_default", "request_class", "response_class", "shutdown", "spin",
    "spin_once", "spin_until_future_complete",
]
