"""The request side is bounded and fair (issue 26, items 7, 8, 11): junk peers cannot take the
places of clients that ask, and no flood of connections holds more than the cap (the fd table
and the memory they cost are bounded)."""

from __future__ import annotations

import socket
import time
from collections.abc import Iterator

import msgpack
import pytest
import zmq
from avard.core.io import frames
from avard.daemon.net.admission import fd_budget
from avard.daemon.net.publisher import MAX_PEERS, Publisher, RequestServer

LOCAL = "tcp://127.0.0.1:*"


@pytest.fixture
def ctx() -> Iterator[zmq.Context]:
    c = zmq.Context()
    yield c
    c.destroy(linger=0)


def _server(**kw: object) -> RequestServer:
    return RequestServer(LOCAL, {"status": lambda args: {"ok": True}}, **kw).start()  # type: ignore[arg-type]


def _ask(ctx: zmq.Context, endpoint: str, op: str = "status") -> dict:
    s = ctx.socket(zmq.DEALER)
    s.setsockopt(zmq.LINGER, 0)
    s.connect(endpoint)
    s.send(msgpack.packb({"op": op, "args": {}, "id": 7}))
    assert s.poll(10_000), "no reply"
    reply = frames.unpack_bounded(s.recv(), max_bytes=1 << 20, what="reply")
    s.close()
    return reply


def test_junk_peers_do_not_lock_clients_out(ctx: zmq.Context) -> None:
    with _server() as srv:
        junk = []
        for k in range(2 * MAX_PEERS):     # more junk peers than places
            s = ctx.socket(zmq.DEALER)
            s.setsockopt(zmq.LINGER, 0)
            s.connect(srv.endpoint)
            s.send(b"\xc1 not msgpack %d" % k if k % 2 else msgpack.packb({"op": "nope"}))
            junk.append(s)
        for s in junk:                      # each got its error, none a place
            assert s.poll(10_000)
            assert "error" in frames.unpack_bounded(s.recv(), max_bytes=1 << 20,
                                                    what="reply")
        reply = _ask(ctx, srv.endpoint)
        assert reply.get("error") is None, reply
        assert reply["result"] == {"ok": True}


def _wait(cond: object, polls: int = 500) -> bool:
    for _ in range(polls):
        if cond():  # type: ignore[operator]
            return True
        time.sleep(0.02)
    return False


def test_a_connection_flood_holds_at_most_the_cap_and_clients_still_get_in(
        ctx: zmq.Context) -> None:
    cap = 8
    with _server(max_connections=cap) as srv:
        host, port = srv.endpoint[len("tcp://"):].rsplit(":", 1)
        raw = [socket.create_connection((host, int(port))) for _ in range(5 * cap)]
        try:
            gate = srv._gate
            assert gate is not None
            assert _wait(lambda: gate.accepted >= 5 * cap), gate.accepted
            assert _wait(lambda: gate.connections <= cap), gate.connections
            assert gate.evicted >= 4 * cap
            # the flood is still connected (idle, within the handshake interval): a client
            # that asks takes the place of one of them, not the other way round
            for _ in range(3):
                assert _ask(ctx, srv.endpoint)["result"] == {"ok": True}
            assert gate.connections <= cap
            closed = 0
            for r in raw:        # the server shut the evicted ones down: they read EOF
                r.settimeout(0.0)
                try:
                    while r.recv(1024):   # the server's ZMTP greeting, then EOF
                        pass
                    closed += 1
                except BlockingIOError:
                    pass            # still connected: not evicted
                except ConnectionResetError:
                    closed += 1
            assert closed >= 4 * cap - 3
        finally:
            for r in raw:
                r.close()


def test_the_publisher_refuses_subscribers_past_its_cap(ctx: zmq.Context) -> None:
    with Publisher(LOCAL, "r", max_subscribers=4) as pub:
        subs = []
        for _ in range(10):
            s = ctx.socket(zmq.SUB)
            s.setsockopt(zmq.LINGER, 0)
            s.setsockopt(zmq.RECONNECT_IVL, 60_000)   # an evicted one stays out
            s.setsockopt(zmq.SUBSCRIBE, b"")
            s.connect(pub.endpoint)
            subs.append(s)
        assert _wait(lambda: pub.stats()["refused_connections"] >= 6)
        assert pub.stats()["peers"] <= 4
        for s in subs:
            s.close()


def test_the_fd_budget_keeps_room_for_the_recording() -> None:
    assert fd_budget(64, what="t", soft_limit=8192) == 64
    assert fd_budget(64, what="t", others=100, soft_limit=400) == 400 - 256 - 100
    assert fd_budget(300, what="t", soft_limit=400) == 400 - 256
    assert fd_budget(300, what="t", soft_limit=100) == 1
    # a subscriber behind the publisher's guard costs three descriptors (daemon28)
    assert fd_budget(256, what="t", others=64, soft_limit=8192, fds_each=3) == 256
    assert fd_budget(256, what="t", others=64, soft_limit=1024, fds_each=3) == (1024 - 320) // 3
