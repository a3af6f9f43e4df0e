"""Publisher and request server over real loopback TCP sockets (ephemeral ports)."""

from __future__ import annotations

import logging
import os
import re

import msgpack
import numpy as np
import pytest
import zmq
from avard.core.errors import ConfigError, DataError, FormatError
from avard.core.io import frames as F
from avard.daemon.net.publisher import (
    DEFAULT_PUB_ENDPOINT,
    DEFAULT_REQUEST_ENDPOINT,
    Publisher,
    RequestServer,
    is_loopback,
)
from avard.daemon.net.subscriber import LossTracker
from hypothesis import given, settings
from hypothesis import strategies as st

LOCAL = "tcp://127.0.0.1:*"


def _raw(i0: int, n: int = 32) -> dict:
    counts = np.arange(i0 * 3, (i0 + n) * 3, dtype=np.int32).reshape(n, 3)
    return F.raw_record("", 0, i0, counts, i0 / 125.0, 1.7e9 + i0 / 125.0)


def _status() -> dict:
    return F.status_record("", 0, {"ping": True}, 0.0, 0.0)


@pytest.fixture
def ctx():
    c = zmq.Context()
    yield c
    c.destroy(linger=0)


def _sub(ctx: zmq.Context, endpoint: str, hwm: int = 100000) -> zmq.Socket:
    s = ctx.socket(zmq.SUB)
    s.setsockopt(zmq.RCVHWM, hwm)
    s.setsockopt(zmq.SUBSCRIBE, b"")
    s.connect(endpoint)
    return s


def _until_connected(pub: Publisher, sub: zmq.Socket) -> None:
    """PUB drops until the subscription arrives: ping on 'status' until one gets through."""
    for _ in range(500):
        pub.publish("status", _status())
        if sub.poll(10):
            while sub.poll(50):
                sub.recv_multipart()
            return
    raise AssertionError("subscriber never connected")


def test_defaults_are_loopback() -> None:
    assert is_loopback(DEFAULT_PUB_ENDPOINT) and is_loopback(DEFAULT_REQUEST_ENDPOINT)
    assert not is_loopback("tcp://0.0.0.0:5556") and not is_loopback("tcp://192.168.1.5:1")
    assert is_loopback("ipc:///run/avard/pub")


def test_publish_stamps_run_and_per_topic_sequence(ctx: zmq.Context) -> None:
    with Publisher(LOCAL, "run-1") as pub:
        assert pub.endpoint.startswith("tcp://127.0.0.1:")
        sub = _sub(ctx, pub.endpoint)
        _until_connected(pub, sub)
        first_status = pub.next_seq("status")
        seqs = [pub.publish("raw", _raw(32 * i)) for i in range(10)]
        gap_seq = pub.publish(None, F.gap_record("", 0, 320, 5, 0.0, 0.0, "overrun"))
        status_seq = pub.publish(None, _status())
        assert seqs == list(range(10)) and gap_seq == 0 and status_seq == first_status
        got = [sub.recv_multipart() for _ in range(12)]
        topics = [t for t, _ in got]
        assert topics == [b"raw"] * 10 + [b"event", b"status"]
        recs = [F.decode(d) for _, d in got]
        assert all(r["run"] == "run-1" for r in recs)
        assert [r["seq"] for r in recs[:10]] == list(range(10))
        np.testing.assert_array_equal(recs[3]["counts"], _raw(96)["counts"])
        stats = pub.stats()
        assert stats["sent"] >= 12 and stats["dropped"] == 0 and stats["peers"] == 1


def test_slow_subscriber_never_blocks_and_sees_its_loss(ctx: zmq.Context) -> None:
    """A subscriber that does not read: publish completes, memory bounded by HWM, and the
    subscriber afterwards counts every message it missed from the sequence numbers."""
    with Publisher(LOCAL, "run-2", hwm=20) as pub:
        sub = _sub(ctx, pub.endpoint, hwm=20)
        _until_connected(pub, sub)
        total = 5000
        for i in range(total):
            pub.publish("raw", _raw(32 * i))
        tracker = LossTracker()
        while sub.poll(200):
            topic, data = sub.recv_multipart()
            tracker.observe(topic.decode(), F.decode(data))
        raw = tracker.stats.topics["raw"]
        assert raw.received < total  # HWM dropped the rest instead of queueing 5000
        assert raw.received + raw.lost == raw.last_seq - raw.first_seq + 1
        assert tracker.stats.samples_unexplained == 0
        assert tracker.stats.samples_lost == 32 * (raw.last_seq - raw.first_seq + 1 - raw.received)


def test_bind_conflict_is_a_config_error() -> None:
    with Publisher(LOCAL, "a") as pub, pytest.raises(ConfigError, match="cannot bind"):
        Publisher(pub.endpoint, "b")


def test_non_loopback_bind_is_explicit_and_warns_without_curve(
        caplog: pytest.LogCaptureFixture) -> None:
    with pytest.raises(ConfigError, match="allow_remote"):
        Publisher("tcp://0.0.0.0:*", "a")
    with pytest.raises(ConfigError, match="allow_remote"):
        RequestServer("tcp://0.0.0.0:*", {}).start()
    with caplog.at_level(logging.WARNING), \
            Publisher("tcp://0.0.0.0:*", "a", allow_remote=True) as pub:
        assert pub.endpoint.startswith("tcp://0.0.0.0:")
    assert "without CURVE" in caplog.text


def test_from_config_uses_publish_and_curve_sections() -> None:
    from avard.daemon.config import default_config

    cfg = default_config()
    cfg["publish"]["endpoint"] = LOCAL
    cfg["publish"]["request_endpoint"] = LOCAL
    with Publisher.from_config(cfg, "run-x") as pub:
        assert pub.run_id == "run-x" and is_loopback(pub.endpoint)
    with RequestServer.from_config(cfg, {"status": lambda a: {}}) as srv:
        assert srv.endpoint.startswith("tcp://127.0.0.1:")


def test_invalid_records_are_refused_before_sending() -> None:
    with Publisher(LOCAL, "a") as pub:
        bad = _raw(0)
        del bad["t_mono"]
        with pytest.raises(FormatError, match="t_mono"):
            pub.publish("raw", bad)
        assert pub.next_seq("raw") == 0  # no number used up: subscribers see no false loss


# ---- request server -------------------------------------------------------------------------


def _handlers() -> dict:
    def recent(args: dict) -> dict:
        seconds = args.get("seconds", 1)
        if not isinstance(seconds, int | float) or not 0 < seconds <= 60:
            raise DataError(f"recent: seconds={seconds!r} must be in (0, 60]")
        n = int(seconds * 125)
        return {"i0": 1000 - n, "counts": np.zeros((n, 3), dtype=np.int32)}

    def broken(args: dict) -> dict:
        raise RuntimeError("bug")

    return {"status": lambda a: {"rate_hz": 125.0, "echo": a},
            "recent": recent, "broken": broken,
            "unencodable": lambda a: {"x": object()}}


@pytest.fixture
def server():
    srv = RequestServer(LOCAL, _handlers(), max_request_bytes=4096, hard_cap_bytes=1 << 16)
    srv.start()
    yield srv
    srv.stop()


def _ask(ctx: zmq.Context, endpoint: str, payload: bytes, kind: int = zmq.REQ) -> dict:
    s = ctx.socket(kind)
    s.setsockopt(zmq.LINGER, 0)
    s.connect(endpoint)
    if kind == zmq.REQ:
        s.send(payload)
    else:
        s.send_multipart([b"", payload])
    assert s.poll(3000), "no reply"
    reply = F.decode_reply(s.recv_multipart()[-1])
    s.close()
    return reply


def test_request_server_answers(ctx: zmq.Context, server: RequestServer) -> None:
    rep = _ask(ctx, server.endpoint, F.encode_request("status", {"k": 1}, id=5))
    assert rep["ok"] and rep["id"] == 5 and rep["result"] == {"rate_hz": 125.0, "echo": {"k": 1}}
    rep = _ask(ctx, server.endpoint, F.encode_request("recent", {"seconds": 2}), zmq.DEALER)
    counts = F.unpack_arrays(rep["result"])["counts"]
    assert rep["ok"] and counts.shape == (250, 3) and counts.dtype == np.int32


@pytest.mark.parametrize(
    ("payload", "match"),
    [
        (b"not msgpack", "not a valid msgpack"),
        (msgpack.packb([1, 2]), "expected a map"),
        (F.encode_request("pickle"), "unknown op 'pickle'"),
        (F.encode_request("recent", {"seconds": 1e9}), "must be in"),
        (F.encode_request("broken"), "internal error"),
        (F.encode_request("unencodable"), "cannot encode|internal error"),
        (b"\x00" * 5000, "exceeds the 4096-byte limit"),
    ],
)
def test_bad_requests_get_error_replies(ctx: zmq.Context, server: RequestServer,
                                        payload: bytes, match: str) -> None:
    rep = _ask(ctx, server.endpoint, payload)
    assert not rep["ok"]
    assert re.search(match, rep["error"]), rep["error"]
    # and the server still answers
    assert _ask(ctx, server.endpoint, F.encode_request("status"))["ok"]


def test_multi_frame_and_over_hard_cap(ctx: zmq.Context, server: RequestServer) -> None:
    s = ctx.socket(zmq.DEALER)
    s.setsockopt(zmq.LINGER, 0)
    s.connect(server.endpoint)
    s.send_multipart([b"", b"a", b"b"])
    assert s.poll(3000)
    assert "one request frame" in F.decode_reply(s.recv_multipart()[-1])["error"]
    # beyond the hard cap libzmq drops the peer before buffering; the server lives on
    s.send_multipart([b"", os.urandom(1 << 17)])
    assert not s.poll(300)
    s.close()
    assert _ask(ctx, server.endpoint, F.encode_request("status"))["ok"]


def test_random_requests_over_the_socket(ctx: zmq.Context, server: RequestServer) -> None:
    """300 hostile payloads through a real socket: every one answered, none accepted."""
    rng = np.random.default_rng(7)
    s = ctx.socket(zmq.DEALER)
    s.setsockopt(zmq.LINGER, 0)
    s.connect(server.endpoint)
    valid = F.encode_request("status")
    for i in range(300):
        if i % 3 == 0:
            payload = rng.bytes(int(rng.integers(0, 200)))
        else:
            buf = bytearray(valid)
            for _ in range(int(rng.integers(1, 4))):
                buf[int(rng.integers(0, len(buf)))] = int(rng.integers(0, 256))
            payload = bytes(buf[: int(rng.integers(1, len(buf) + 1))])
        s.send_multipart([b"", payload])
        assert s.poll(3000), f"no reply to payload {i}"
        rep = F.decode_reply(s.recv_multipart()[-1])
        assert rep["ok"] == (rep["op"] == "status")
    s.close()
    assert server.errors > 0


def test_ipv6_loopback() -> None:
    from avard.daemon.net.subscriber import Subscriber

    try:
        pub = Publisher("tcp://[::1]:*", "v6")
    except ConfigError as exc:
        pytest.skip(f"no IPv6 loopback here: {exc}")
    with pub:
        assert is_loopback(pub.endpoint)
        sub = Subscriber(pub.endpoint).connect(join=False)
        try:
            for _ in range(500):
                pub.publish("status", _status())
                if (m := sub.recv(0.01)) is not None:
                    break
            assert m is not None and m.record["run"] == "v6"
        finally:
            sub.close()


def test_concurrent_publishers_share_one_sequence(ctx: zmq.Context) -> None:
    """The service loop and temperature threads may publish at once: every sequence number
    is used exactly once and every message arrives whole."""
    import threading

    with Publisher(LOCAL, "run-t") as pub:
        sub = _sub(ctx, pub.endpoint)
        _until_connected(pub, sub)
        seqs: list[int] = []

        def worker(k: int) -> None:
            got = [pub.publish("raw", _raw(10_000 * k + 32 * i)) for i in range(300)]
            seqs.extend(got)

        threads = [threading.Thread(target=worker, args=(k,)) for k in range(4)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        assert sorted(seqs) == list(range(1200))
        received = [F.decode(sub.recv_multipart()[1])["seq"] for _ in range(1200)]
        assert received == list(range(1200))  # sent in sequence order, none interleaved


_leaf = st.one_of(st.none(), st.booleans(), st.integers(-(1 << 63), (1 << 64) - 1),
                  st.floats(), st.text(max_size=10), st.binary(max_size=20))
_obj = st.recursive(_leaf, lambda c: st.one_of(
    st.lists(c, max_size=4), st.dictionaries(st.text(max_size=6), c, max_size=4)), max_leaves=30)
_requestish = st.fixed_dictionaries(
    {"op": st.one_of(st.sampled_from(["status", "recent", "broken", "unencodable"]), _obj)},
    optional={"args": _obj, "id": _obj})


@settings(max_examples=200, deadline=None)
@given(st.one_of(st.binary(max_size=300), _obj.map(msgpack.packb),
                 _requestish.map(lambda r: msgpack.packb(r, use_bin_type=True))))
def test_request_handler_answers_everything(payload: bytes) -> None:
    """The server's request path without the socket (200 inputs per CI run): every payload
    gets a decodable reply; only well-formed requests for a working op succeed."""
    srv = RequestServer(LOCAL, _handlers(), max_request_bytes=4096)
    reply = F.decode_reply(srv.handle(payload))
    if reply["ok"]:
        req = F.decode_request(payload)
        assert req["op"] in ("status", "recent")
