"""roszen.peers.PublisherWatch: a topic's publishers named, and on their loss whether their node
left the graph (lost) or only stopped publishing."""
from __future__ import annotations

import pytest

import roszen
from roszen.peers import PeerLost, PeerWatch, PublisherLoss, PublisherWatch
from roszen.testing import wait_until


def _node(name: str) -> roszen.Node:
    return roszen.Node(name, use_global_arguments=False, start_parameter_services=False,
                       enable_rosout=False)


def test_stopped_publishing_then_node_left(router_env):
    watcher, talker = _node("watcher"), _node("talker")
    try:
        watch = PublisherWatch(watcher, "chatter", settle=0.0)
        assert watch.loss() is not None and watch.who == "its publisher"   # none seen yet
        pub = talker.create_publisher("std_msgs/msg/String", "/chatter", 10)
        assert wait_until(lambda: watch.loss() is None, 5.0)
        assert watch.names == ["/talker"] and watch.topic == "/chatter"
        talker.destroy_publisher(pub)                  # the node stays: it only stopped
        assert wait_until(lambda: watch.loss() is not None, 5.0)
        assert watch.loss() == PublisherLoss(node_left=False, who="talker")
        talker.destroy_node()                          # now the node has left too
        assert wait_until(lambda: watch.loss().node_left, 5.0)
        assert watch.loss().who == "talker" and not watch.loss().pending
    finally:
        watcher.destroy_node()


def test_a_publisher_node_still_there_is_pending_while_it_settles(router_env):
    watcher, talker = _node("watcher2"), _node("talker2")
    try:
        watch = PublisherWatch(watcher, "/chatter2", settle=3600.0)
        pub = talker.create_publisher("std_msgs/msg/String", "/chatter2", 10)
        assert wait_until(lambda: watch.loss() is None, 5.0)
        talker.destroy_publisher(pub)
        assert wait_until(lambda: watch.loss() is not None, 5.0)
        assert watch.loss().pending and not watch.loss().node_left
    finally:
        talker.destroy_node()
        watcher.destroy_node()


def test_peer_watch_names_a_lost_node(router_env):
    watcher, sim = _node("watcher3"), _node("sim_like")
    try:
        watch = PeerWatch(watcher, nodes=["sim_like", "never_started"])
        assert wait_until(lambda: "node sim_like" not in watch.missing(), 5.0)
        watch.check()                                  # never_started is missing, not lost
        sim.destroy_node()
        assert wait_until(lambda: watch.lost() == ["node sim_like"], 5.0)
        with pytest.raises(PeerLost, match="^lost node sim_like$"):
            watch.check()
    finally:
        watcher.destroy_node()
