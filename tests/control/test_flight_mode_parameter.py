"""The controller's flight_mode parameter shows the mode in effect: a mode announced
on /mob/flight_mode (or a segment's) is what `param get` says; the parameter stays settable, and
a set is not undone by the same mode announced again (the latched sample), only by a change."""
from __future__ import annotations

import time

import roszen
from astrobee import msgconv as mc
from astrobee_control import registry
from astrobee_control.controller_node import ControllerNode


def _controller() -> ControllerNode:
    law = registry.get("pd")
    return ControllerNode(law.make_law, "mode_ctl", dict(law.params()))


def _announce(node: ControllerNode, name: str) -> None:
    msg = roszen.message_class("astrobee_msgs/msg/FlightMode")()
    msg.name = name
    node._on_flight_mode(msg)


def _shown(node: ControllerNode) -> str:
    return node.node.get_parameter("flight_mode").value


def test_the_parameter_follows_the_announced_mode_and_stays_settable(router_env):
    node = _controller()
    try:
        assert _shown(node) == "nominal" and node.law.flight_mode.name == "nominal"
        _announce(node, "quiet")                 # the sim changes the mode
        assert _shown(node) == "quiet" and node.law.flight_mode.name == "quiet"
        r = node.node.set_parameter(roszen.Parameter("flight_mode", value="precision"))
        assert r.successful and node.law.flight_mode.name == "precision"
        _announce(node, "quiet")                 # the latched sample again: not a change
        assert _shown(node) == "precision" and node.law.flight_mode.name == "precision"
        _announce(node, "difficult")             # the sim changes the mode: it wins
        assert _shown(node) == "difficult" and node.law.flight_mode.name == "difficult"
        _announce(node, "warp")                  # unknown: logged, nothing changes
        assert _shown(node) == "difficult" and node.law.flight_mode.name == "difficult"
    finally:
        node.node.destroy_node()


def test_a_latched_mode_on_the_graph_shows_in_param_get(router_env):
    """Over the graph: a latched /mob/flight_mode publisher (as sim_node's) and the controller
    spinning: the node's parameter (what `param get` is served) shows the mode."""
    node = _controller()
    pub_node = roszen.Node("mode_announcer")
    try:
        pub = pub_node.create_publisher("astrobee_msgs/msg/FlightMode", mc.FLIGHT_MODE,
                                        roszen.LATCHED)
        msg = roszen.message_class("astrobee_msgs/msg/FlightMode")()
        msg.name = "quiet"
        pub.publish(msg)
        deadline = time.monotonic() + 15.0
        while _shown(node) != "quiet" and time.monotonic() < deadline:
            roszen.spin_once(node.node, timeout_sec=0.1)
        assert _shown(node) == "quiet" and node.law.flight_mode.name == "quiet"
    finally:
        pub_node.destroy_node()
        node.node.destroy_node()
