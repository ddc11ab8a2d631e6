"""The graph cache is queried by a node's thread while zenoh's liveliness thread adds and
removes entities: every query reads a snapshot (a recorder once died of "dictionary changed
size during iteration" in a loaded two-robot launch)."""
import threading

from roszen import wire
from roszen.graph import GraphCache
from roszen.qos import QoSProfile

HASH = "RIHS01_" + "0" * 64


def _cache() -> GraphCache:
    """A GraphCache without a zenoh session (only its bookkeeping)."""
    g = object.__new__(GraphCache)
    g._log, g.domain_id = None, 0
    g._entities, g._cond, g._ready = {}, threading.Condition(), threading.Event()
    g._listeners, g._bad_tokens = [], set()
    return g


def test_queries_while_entities_come_and_go():
    g = _cache()
    tokens = [wire.endpoint_token(0, "z", 1, k, wire.PUB, "/", "/", "n", f"/t{k}",
                                  "std_msgs::msg::dds_::String_", HASH, QoSProfile(depth=1))
              for k in range(200)]
    stop = threading.Event()
    errors = []

    def churn():
        while not stop.is_set():
            for t in tokens:
                g.add(t)
            for t in tokens:
                g.remove(t)

    def query():
        try:
            for _ in range(3000):
                g.get_topic_names_and_types()
                g.count_publishers("/t7")
                g.service_is_available("/s")
                g.get_publishers_info_by_topic("/t3")
        except RuntimeError as exc:      # dictionary changed size during iteration
            errors.append(exc)

    writer = threading.Thread(target=churn)
    writer.start()
    try:
        query()
    finally:
        stop.set()
        writer.join()
    assert not errors, errors[0]
    g.add(tokens[0])
    assert g.get_topic_names_and_types() == [("/t0", ["std_msgs/msg/String"])]
    assert g.count_publishers("/t0") == 1
