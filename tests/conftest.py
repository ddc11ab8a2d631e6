"""Shared fixtures: a router subprocess on a free port and the env for node processes."""
from __future__ import annotations

import signal

import pytest

# A shell without job control starts background jobs with SIGINT ignored, and an ignored signal
# stays ignored across exec: the node and verb processes the tests spawn (and stop with SIGINT,
# as a user's Ctrl-C) would then never see it. The test session restores the default handler so
# its children start with SIGINT delivered, however the suite itself was launched.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


@pytest.fixture(scope="session")
def router_port():
    """One router process for the whole test session (python -m roszen.router on a free port)."""
    from roszen.testing import router
    with router() as port:
        yield port


_domain = [40]


@pytest.fixture
def router_env(router_port, monkeypatch):
    """Env dict for node processes on the session router, with a fresh ROS_DOMAIN_ID per test.

    The same variables are set in this process, so in-process contexts join the same graph.
    """
    from roszen.testing import zenoh_env
    _domain[0] += 1
    env = zenoh_env(router_port, domain_id=_domain[0] % 200)
    for k in ("ZENOH_CONFIG_OVERRIDE", "ROS_DOMAIN_ID"):
        monkeypatch.setenv(k, env[k])
    yield env
    import roszen
    roszen.shutdown()  # the next test's default context picks up its own domain
