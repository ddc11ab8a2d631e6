"""roszen's node API over real rclpy (ROS 2 Jazzy, any RMW): what `roszen.runtime` hands the
nodes when ASTROBEE_RUNTIME=rclpy. Imports rclpy; only roszen.runtime imports this package, when selected."""
from __future__ import annotations

from . import node_main
from .node import Clock, Node, ensure_init, wall_clock


def ok() -> bool:
    import rclpy
    return rclpy.ok()


def shutdown() -> None:
    import rclpy
    rclpy.try_shutdown()


__all__ = ["Clock", "Node", "ensure_init", "node_main", "ok", "shutdown", "wall_clock"]
