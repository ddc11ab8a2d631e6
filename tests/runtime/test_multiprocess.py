"""Two or three processes (plus the router) exchange topics and services and see each other in the graph."""
from __future__ import annotations

import os
import time

import pytest

import roszen
from roszen.testing import kill9, python_cmd, read_until, spawn, stop

PEER = os.path.join(os.path.dirname(__file__), "peer.py")
pytestmark = pytest.mark.graph


def peer(env, *args):
    return spawn(python_cmd(PEER, *args), env)


def test_topic_between_processes(router_env):
    lis = peer(router_env, "listener", "/chatter")
    tal = None
    try:
        read_until(lis, "READY")
        tal = peer(router_env, "talker", "chatter")
        lines = read_until(lis, "GOT msg-3", timeout=15)
        got = [ln.split()[1] for ln in lines if ln.startswith("GOT")]
        # in order, no gaps once started
        idx = [int(g.split("-")[1]) for g in got]
        assert idx == list(range(idx[0], idx[0] + len(idx)))
    finally:
        for p in (tal, lis):
            if p:
                stop(p)


def test_service_between_processes(router_env):
    srv = peer(router_env, "server", "/calc/add")
    cli = None
    try:
        read_until(srv, "READY")
        cli = peer(router_env, "client", "/calc/add")
        lines = read_until(cli, "SUM", timeout=15)
        assert lines[-1] == "SUM 42"
    finally:
        for p in (cli, srv):
            if p:
                stop(p)


def test_transient_local_late_joiner(router_env):
    tal = peer(router_env, "talker", "/latched_topic", "latched")
    lis = None
    try:
        read_until(tal, "PUBLISHED latched-0")
        time.sleep(0.3)  # the sample is in the publisher's cache before anyone subscribes
        lis = peer(router_env, "listener", "/latched_topic", "latched")
        lines = read_until(lis, "GOT latched-0", timeout=15)
        assert "GOT latched-0" in lines
    finally:
        for p in (lis, tal):
            if p:
                stop(p)


def test_graph_seen_from_third_process_and_kill9(router_env):
    lis = peer(router_env, "listener", "/graph_topic", "--ros-args", "-r", "__ns:=/g1")
    srv = peer(router_env, "server", "/graph_srv", "--ros-args", "-r", "__node:=adder")
    try:
        read_until(lis, "READY")
        read_until(srv, "READY")
        ctx = roszen.Context()
        try:
            g = ctx.graph
            assert g.wait_ready(5.0)
            assert g.wait_for(lambda: ("adder", "/") in g.get_node_names_and_namespaces()
                              and ("peer_listener", "/g1") in g.get_node_names_and_namespaces()
                              and g.count_subscribers("/graph_topic") == 1 and g.count_services("/graph_srv") == 1,
                              10)
            topics = dict(g.get_topic_names_and_types())
            assert topics["/graph_topic"] == ["std_msgs/msg/String"]
            services = dict(g.get_service_names_and_types())
            assert services["/graph_srv"] == ["example_interfaces/srv/AddTwoInts"]
            assert g.count_subscribers("/graph_topic") == 1
            (info,) = g.get_subscriptions_info_by_topic("/graph_topic")
            assert (info.node_name, info.namespace, info.qos.depth) == ("peer_listener", "/g1", 10)
            assert info.type_hash.startswith("RIHS01_")
            # a crash: the graph drops the node within a few seconds, the other keeps serving
            kill9(lis)
            assert g.wait_for(lambda: ("peer_listener", "/g1") not in g.get_node_names_and_namespaces(), 10)
            # each token's deletion arrives on its own: the endpoint may trail the node token
            assert g.wait_for(lambda: g.count_subscribers("/graph_topic") == 0, 10)
            assert srv.poll() is None
            assert ("adder", "/") in g.get_node_names_and_namespaces()
            cli = peer(router_env, "client", "/graph_srv")
            try:
                assert read_until(cli, "SUM", timeout=15)[-1] == "SUM 42"
            finally:
                stop(cli)
        finally:
            ctx.shutdown()
    finally:
        stop(lis)
        stop(srv)
