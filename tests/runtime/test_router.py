"""The router: `python -m roszen.router` on loopback, ZENOH_ROUTER_CONFIG_URI honoured, embedded use."""
from __future__ import annotations

import os

import pytest

import roszen
from roszen.router import start_router
from roszen.testing import free_port, python_cmd, spawn, stop, wait_port, zenoh_env


@pytest.mark.graph
def test_router_config_file(tmp_path):
    port = free_port()
    cfg = tmp_path / "router.json5"
    cfg.write_text('{ mode: "router", listen: { endpoints: ["tcp/127.0.0.1:%d"] },'
                   ' scouting: { multicast: { enabled: false } } }' % port)
    env = dict(os.environ, ZENOH_ROUTER_CONFIG_URI=str(cfg))
    p = spawn(python_cmd("-m", "roszen.router"), env)
    try:
        assert wait_port(port, 10)
    finally:
        assert stop(p) == 0  # SIGTERM is a clean shutdown


def test_router_bad_config_exits_nonzero(tmp_path):
    env = dict(os.environ, ZENOH_ROUTER_CONFIG_URI=str(tmp_path / "missing.json5"))
    p = spawn(python_cmd("-m", "roszen.router"), env)
    try:
        p.wait(20)
        assert p.returncode == 1
        assert "ZENOH_ROUTER_CONFIG_URI" in p.stderr.read()
    finally:
        stop(p)


def test_embedded_router_serves_a_graph(monkeypatch):
    port = free_port()
    with start_router(f"tcp/127.0.0.1:{port}"):
        env = zenoh_env(port, domain_id=199)
        for k in ("ZENOH_CONFIG_OVERRIDE", "ROS_DOMAIN_ID"):
            monkeypatch.setenv(k, env[k])
        a, b = roszen.Context(), roszen.Context()
        try:
            assert a.router_connected and b.router_connected
            n = roszen.Node("embedded_peer", context=a)
            assert b.graph.wait_for(lambda: ("embedded_peer", "/") in b.graph.get_node_names_and_namespaces(), 10)
            n.destroy_node()
            assert b.graph.wait_for(lambda: not b.graph.get_node_names(), 10)
        finally:
            a.shutdown()
            b.shutdown()
