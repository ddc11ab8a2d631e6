"""roszen.peers.PeerWatch: a node killed with SIGKILL is reported lost (by name and
as its topic's publisher) without any timeout; a peer not yet started is missing, not lost."""
from __future__ import annotations

import os
import time

import pytest

import roszen
from roszen.peers import PeerLost, PeerWatch
from roszen.testing import kill9, python_cmd, read_until, spawn, stop

pytestmark = pytest.mark.graph
PEER = os.path.join(os.path.dirname(__file__), "..", "runtime", "peer.py")


def wait(cond, timeout=20.0):
    end = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > end:
            return False
        time.sleep(0.02)
    return True


def test_killed_node_is_reported_lost(router_env):
    node = roszen.Node("mission_watch")
    sim = spawn(python_cmd(PEER, "talker", "/loc/truth/pose", "latched", "--ros-args",
                           "-r", "__node:=sim_node"), router_env)
    try:
        watch = PeerWatch(node, nodes=["sim_node", "planner_node"], topics=["/loc/truth/pose"])
        assert watch.lost() == []                       # nothing seen yet: nothing lost
        read_until(sim, "PUBLISHED", timeout=30)
        assert wait(lambda: watch.missing() == ["node planner_node"])
        watch.check()                                   # all seen are there: no error
        assert watch.lost() == []
        kill9(sim)
        assert wait(lambda: bool(watch.lost()))
        assert wait(lambda: len(watch.lost()) == 2)
        assert watch.lost() == ["node sim_node", "publisher of /loc/truth/pose"]
        with pytest.raises(PeerLost, match="^lost node sim_node, publisher of /loc/truth/pose$"):
            watch.check()
    finally:
        stop(sim)
        node.destroy_node()


def test_fully_qualified_names_match_their_namespace_only(router_env):
    node = roszen.Node("mission_watch2")
    peer = spawn(python_cmd(PEER, "talker", "chatter", "latched", "--ros-args",
                            "-r", "__node:=sim_node", "-r", "__ns:=/bumble"), router_env)
    try:
        read_until(peer, "PUBLISHED", timeout=30)
        here = PeerWatch(node, nodes=["/bumble/sim_node", "sim_node"])
        other = PeerWatch(node, nodes=["/honey/sim_node"])
        assert wait(lambda: here.missing() == [])
        assert other.missing() == ["node honey/sim_node"]
    finally:
        stop(peer)
        node.destroy_node()
