"""Subscriber: loss accounting from sequences and indices, join snapshot, over loopback."""

from __future__ import annotations

import numpy as np
import pytest
from avard.core.errors import ConfigError, NetworkError
from avard.core.io import frames as F
from avard.daemon.net.publisher import Publisher, RequestServer
from avard.daemon.net.subscriber import LossTracker, Subscriber, request_endpoint_for
from hypothesis import given, settings
from hypothesis import strategies as st

LOCAL = "tcp://127.0.0.1:*"


def _raw(run: str, seq: int, i0: int, n: int = 32) -> dict:
    return F.raw_record(run, seq, i0, np.zeros((n, 3), dtype=np.int32), 0.0, 0.0)


def test_tracker_counts_transport_loss_service_gaps_and_restarts() -> None:
    t = LossTracker()
    assert t.observe("raw", _raw("a", 5, 160)).new_run          # joined late: no loss yet
    assert t.observe("raw", _raw("a", 6, 192)).lost == 0
    m = t.observe("raw", _raw("a", 9, 288))                      # seq 7, 8 lost in transport
    assert (m.lost, m.missing) == (2, [(224, 64)])
    t.observe("event", F.gap_record("a", 0, 320, 100, 0.0, 0.0, "overrun"))
    m = t.observe("raw", _raw("a", 10, 420))                     # the service's own gap
    assert (m.lost, m.missing) == (0, [])
    m = t.observe("raw", _raw("a", 11, 500))                     # unannounced hole
    s = t.stats
    assert (s.samples_received, s.samples_lost, s.samples_service_gap,
            s.samples_unexplained) == (5 * 32, 64, 100, 48)
    assert s.topics["raw"].lost == 2 and s.messages_lost == 2
    m = t.observe("raw", _raw("b", 0, 0))                        # restart: a new run
    assert m.new_run and t.stats.runs == 2 and t.stats.topics["raw"].received == 6
    assert (m.lost, t.stats.topics["raw"].first_seq) == (0, 0)  # sequences start afresh
    t.observe("raw", _raw("b", 1, 0))                            # repeated block
    assert t.stats.samples_repeated == 32


def test_request_endpoint_default_is_port_plus_one() -> None:
    assert request_endpoint_for("tcp://10.0.0.2:5556") == "tcp://10.0.0.2:5557"
    with pytest.raises(ConfigError):
        request_endpoint_for("ipc:///tmp/x")
    with pytest.raises(ConfigError, match="unknown topic"):
        Subscriber("tcp://127.0.0.1:1", topics=["raw", "secrets"])


def test_stream_end_to_end_with_join_snapshot() -> None:
    """Every message arrives once, a service gap is attributed to the service, and the join
    snapshot arrives with its arrays as numpy."""
    snapshot = {"tau": np.array([0.008, 0.016, 0.032]), "avar": np.ones((3, 3)) * 1e-8,
                "n_samples": 4096}
    handlers = {"snapshot": lambda a: snapshot, "header": lambda a: {"rate_hz": 125.0}}
    with Publisher(LOCAL, "run-e") as pub, RequestServer(LOCAL, handlers) as srv:
        sub = Subscriber(pub.endpoint, request_endpoint=srv.endpoint,
                         request_timeout_s=20.0).connect()
        try:
            np.testing.assert_array_equal(sub.snapshot["tau"], snapshot["tau"])
            assert sub.snapshot["avar"].shape == (3, 3) and sub.header == {"rate_hz": 125.0}
            for _ in range(500):  # PUB drops until the subscription has arrived
                pub.publish("status", F.status_record("", 0, {}, 0.0, 0.0))
                if sub.recv(0.01) is not None:
                    break
            i0 = 0
            for k in range(100):
                if k == 50:
                    pub.publish(None, F.gap_record("", 0, i0, 40, 0.0, 0.0, "bus_error"))
                    i0 += 40
                pub.publish(None, _raw("", 0, i0))
                if k % 10 == 0:
                    pub.publish(None, F.temp_record("", 0, i0, ["plate"], [21.5], 0.0, 0.0))
                i0 += 32
            raw = 0
            while raw < 100:
                m = sub.recv(3.0)
                assert m is not None
                raw += m.topic == "raw"
            s = sub.stats
            assert s.samples_received == 3200 and s.samples_service_gap == 40
            assert s.samples_lost == 0 == s.samples_unexplained == s.messages_lost
            assert s.topics["temp"].received == 10 and s.bad_messages == 0
            assert s.to_dict()["messages_lost"] == 0
        finally:
            sub.close()


def test_request_timeout_and_error_replies() -> None:
    with RequestServer(LOCAL, {"status": lambda a: {}}) as srv:
        sub = Subscriber("tcp://127.0.0.1:1", request_endpoint=srv.endpoint,
                         request_timeout_s=20.0)
        try:
            with pytest.raises(NetworkError, match=r"refused.*unknown op"):
                sub.request("snapshot")
            assert sub.request("status") == {}
        finally:
            sub.close()
    dead = Subscriber("tcp://127.0.0.1:1", request_endpoint="tcp://127.0.0.1:9",
                      request_timeout_s=0.2)
    try:
        with pytest.raises(NetworkError, match="no reply"):
            dead.request("status")
        dead.connect()  # joining a dead service only warns
        assert dead.snapshot is None
    finally:
        dead.close()


def test_garbage_from_a_publisher_is_counted_not_fatal() -> None:
    import zmq

    ctx = zmq.Context()
    pub = ctx.socket(zmq.XPUB)
    pub.setsockopt(zmq.LINGER, 0)
    pub.bind(LOCAL)
    sub = Subscriber(pub.getsockopt_string(zmq.LAST_ENDPOINT)).connect(join=False)
    try:
        for _ in F.TOPICS:  # one subscription message per topic
            assert pub.poll(5000)
            pub.recv()
        pub.send_multipart([b"raw", b"\xc1garbage"])
        pub.send_multipart([b"raw", b"a", b"b"])
        pub.send_multipart([b"raw", F.encode(F.status_record("r", 0, {}, 0.0, 0.0))[:-3]])
        pub.send_multipart([b"raw", F.encode(_raw("r", 0, 0))])
        m = sub.recv(5.0)
        assert m is not None and m.record["kind"] == "raw"
        assert sub.stats.bad_messages == 3 and sub.stats.samples_received == 32
    finally:
        sub.close()
        pub.close()
        ctx.term()


def test_command_line_client_arguments(tmp_path) -> None:
    import argparse

    from avard.daemon.net.subscriber import add_client_arguments, subscriber_from_args

    parser = argparse.ArgumentParser()
    add_client_arguments(parser)
    sub = subscriber_from_args(parser.parse_args(["tcp://10.1.2.3:7000"]))
    assert sub.request_endpoint == "tcp://10.1.2.3:7001" and sub.curve is None
    with pytest.raises(ConfigError, match="both --server-key"):
        subscriber_from_args(parser.parse_args(["tcp://127.0.0.1:1", "--server-key", "s.key"]))
    args = parser.parse_args(["ipc:///run/avard/pub", "--request", "ipc:///run/avard/req",
                              "--server-key", "s.key", "--client-key", "c.key_secret",
                              "--timeout", "7"])
    sub = subscriber_from_args(args)
    assert sub.request_endpoint == "ipc:///run/avard/req" and sub.request_timeout_s == 7
    assert sub.curve is not None and sub.curve.client_secret_key_file.name == "c.key_secret"


def _stream(sizes: list[int], gaps: dict[int, int]) -> list[tuple[str, dict]]:
    """Raw blocks of the given sizes, with a service gap of gaps[k] samples before block k."""
    out, i0, seq_raw, seq_ev = [], 1000, 0, 0
    for k, n in enumerate(sizes):
        if k in gaps:
            out.append(("event", F.gap_record("r", seq_ev, i0, gaps[k], 0.0, 0.0, "overrun")))
            seq_ev += 1
            i0 += gaps[k]
        out.append(("raw", _raw("r", seq_raw, i0, n)))
        seq_raw += 1
        i0 += n
    return out


@settings(max_examples=150, deadline=None)
@given(st.lists(st.integers(1, 40), min_size=2, max_size=40),
       st.dictionaries(st.integers(1, 39), st.integers(1, 100), max_size=5),
       st.sets(st.integers(1, 100), max_size=30))
def test_loss_accounting_adds_up(sizes: list[int], gaps: dict[int, int],
                                 dropped: set[int]) -> None:
    """Whatever the network drops (never the first message), every sample index between the
    first and the last received block is accounted for exactly once: received, lost in
    transport, a service gap, or unexplained; unexplained only when a gap record was lost."""
    msgs = _stream(sizes, gaps)
    t = LossTracker()
    kept = [m for j, m in enumerate(msgs) if j == 0 or j not in dropped]
    last_raw = None
    for topic, rec in kept:
        t.observe(topic, rec)
        if topic == "raw":
            last_raw = rec
    s = t.stats
    raw = s.topics["raw"]
    assert raw.received + raw.lost == raw.last_seq - raw.first_seq + 1
    assert last_raw is not None
    span = s.next_index - s.first_index
    assert (s.samples_received + s.samples_lost + s.samples_service_gap
            + s.samples_unexplained + t.pending_samples) == span
    assert s.samples_repeated == 0
    lost_gap_records = any(topic == "event" and j in dropped
                           for j, (topic, _) in enumerate(msgs) if j)
    if not lost_gap_records:
        assert s.samples_unexplained == 0


def test_block_lost_just_before_a_service_gap_is_still_counted() -> None:
    t = LossTracker()
    t.observe("raw", _raw("a", 0, 0))
    # raw seq 1 ([32, 64)) is lost; the service then announces a gap [64, 164)
    t.observe("event", F.gap_record("a", 0, 64, 100, 0.0, 0.0, "overrun"))
    assert t.pending_samples == 32
    m = t.observe("raw", _raw("a", 2, 164))
    assert (m.lost, m.missing) == (1, [(32, 32)])
    s = t.stats
    assert (s.samples_lost, s.samples_service_gap, s.samples_unexplained) == (32, 100, 0)
    assert t.pending_samples == 0
