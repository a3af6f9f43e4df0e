"""The publisher's subscription guard speaks ZMTP as libzmq does to a well-behaved subscriber.

daemon/net/front.py relays each subscriber to the PUB socket and passes on only subscriptions
that can match a published topic. These tests hold what a client written from
docs/wire-format.md relies on: libzmq SUB clients (ZMTP 3.1: SUBSCRIBE/CANCEL commands),
a hand-written ZMTP 3.0 client (subscriptions as messages), heartbeats, unsubscribing, a
rig's ``KIND.NAME`` topics subscribed before their first record; and what it refuses: an
oversized frame, a greeting that is not ZMTP 3 with the NULL mechanism. Every wait is on an
event (a message arriving, a counter reaching its value) with a generous deadline that only
ends a hang.
"""

from __future__ import annotations

import select
import socket
import time
from collections.abc import Callable

import msgpack
import zmq
from avard.daemon.net.publisher import Publisher
from avard.daemon.service.rig_service import SensorPublisher

LOCAL = "tcp://127.0.0.1:0"
DEADLINE_S = 20.0


def _first_received(sub: zmq.Socket, send: Callable[[], None]) -> bytes:
    """Call ``send`` until ``sub`` receives something (a subscription the guard passed on
    reaches libzmq a moment later); the topic of the first message (pacing only: the
    deadline ends a hang)."""
    end = time.monotonic() + DEADLINE_S
    while not sub.poll(5):
        assert time.monotonic() < end, "nothing received"
        send()
    return bytes(sub.recv_multipart()[0])


# ---- a ZMTP 3.0 subscriber written by hand (RFC 23) -----------------------------------------

def _greeting(minor: int = 0, mechanism: bytes = b"NULL") -> bytes:
    return (b"\xff" + b"\0" * 8 + b"\x7f" + bytes([3, minor]) + mechanism.ljust(20, b"\0")
            + b"\0" * 32)


def _frame(body: bytes, flags: int = 0) -> bytes:
    if len(body) > 255:
        return bytes([flags | 0x02]) + len(body).to_bytes(8, "big") + body
    return bytes([flags, len(body)]) + body


def _ready() -> bytes:
    prop = bytes([11]) + b"Socket-Type" + (3).to_bytes(4, "big") + b"SUB"
    return _frame(bytes([5]) + b"READY" + prop, 0x04)


def _recv_exact(sock: socket.socket, n: int) -> bytes:
    out = b""
    while len(out) < n:
        chunk = sock.recv(n - len(out))
        if not chunk:
            raise ConnectionError("closed")
        out += chunk
    return out


def _read_frame(sock: socket.socket) -> tuple[int, bytes]:
    flags = _recv_exact(sock, 1)[0]
    size = (int.from_bytes(_recv_exact(sock, 8), "big") if flags & 0x02
            else _recv_exact(sock, 1)[0])
    return flags, _recv_exact(sock, size)


def _handshake(endpoint: str) -> socket.socket:
    host, _, port = endpoint[len("tcp://"):].rpartition(":")
    sock = socket.create_connection((host, int(port)), timeout=DEADLINE_S)
    sock.sendall(_greeting())
    peer = _recv_exact(sock, 64)
    assert peer[0] == 0xFF and peer[10] == 3 and peer[12:16] == b"NULL"
    sock.sendall(_ready())
    flags, body = _read_frame(sock)
    assert flags & 0x04 and body[1:6] == b"READY", body
    return sock


def _closed_by_peer(sock: socket.socket) -> bool:
    """Whether the other end closed (EOF or reset), reading what it still sends."""
    end = time.monotonic() + DEADLINE_S
    while time.monotonic() < end:
        ready, _, _ = select.select([sock], [], [], 1.0)
        if ready:
            try:
                if not sock.recv(65536):
                    return True
            except ConnectionError:
                return True
    return False


def test_a_zmtp30_client_gets_its_topic_and_its_junk_is_dropped() -> None:
    with Publisher(LOCAL, "run-g", check=False) as pub:
        sock = _handshake(pub.endpoint)
        try:
            sock.sendall(_frame(b"\x01" + b"nothing-we-send")
                         + _frame(b"\x00" + b"never-subscribed")     # ignored cancel
                         + _frame(b"\x01stat"))                      # a prefix: applied
            # publish until the subscription has reached libzmq and a record comes back
            end = time.monotonic() + DEADLINE_S
            while not select.select([sock], [], [], 0.005)[0]:
                assert time.monotonic() < end, pub.stats()
                pub.publish("raw", {"kind": "raw", "v": 0})          # not subscribed
                pub.publish("status", {"kind": "status", "v": 1, "n": 2})
            flags, topic = _read_frame(sock)
            assert topic == b"status" and flags & 0x01               # topic, then the record
            _flags, data = _read_frame(sock)
            assert msgpack.unpackb(data)["kind"] == "status"
            st = pub.stats()
            assert st["subscriptions_dropped"] == 1
            assert st["cancels_ignored"] == 1
        finally:
            sock.close()


def test_an_oversized_frame_or_another_protocol_ends_the_connection() -> None:
    with Publisher(LOCAL, "run-g", check=False) as pub:
        big = _handshake(pub.endpoint)
        big.sendall(_frame(b"\x01" + b"x" * 2000))     # > MAX_SUBSCRIPTION_BYTES
        assert _closed_by_peer(big)
        big.close()
        host, _, port = pub.endpoint[len("tcp://"):].rpartition(":")
        for greeting in (_greeting(mechanism=b"CURVE"), b"GET / HTTP/1.0\r\n\r\n" + b"\0" * 64):
            other = socket.create_connection((host, int(port)), timeout=DEADLINE_S)
            other.sendall(greeting)
            assert _closed_by_peer(other), greeting[:20]
            other.close()
        assert pub.stats()["protocol_closed"] == 3


# ---- libzmq subscribers, as a client written from the docs is --------------------------------

def test_libzmq_subscribers_subscribe_unsubscribe_and_heartbeat() -> None:
    ctx = zmq.Context()
    watch = None
    try:
        with Publisher(LOCAL, "run-g", check=False) as pub:
            everything = ctx.socket(zmq.SUB)
            everything.setsockopt(zmq.HEARTBEAT_IVL, 20)     # PING/PONG pass through the guard
            # a PONG within a second however loaded the machine; the wait below is longer
            everything.setsockopt(zmq.HEARTBEAT_TIMEOUT, 1000)
            everything.setsockopt(zmq.SUBSCRIBE, b"")
            watch = everything.get_monitor_socket(zmq.EVENT_DISCONNECTED)
            everything.connect(pub.endpoint)
            one = ctx.socket(zmq.SUB)
            one.setsockopt(zmq.SUBSCRIBE, b"avar")
            one.connect(pub.endpoint)

            def both() -> None:
                pub.publish("raw", {"kind": "raw", "v": 1})
                pub.publish("avar", {"kind": "avar", "v": 1})

            assert _first_received(one, both) == b"avar"       # never raw: not subscribed
            seen = {_first_received(everything, both)}
            while not {b"raw", b"avar"} <= seen and everything.poll(DEADLINE_S * 1000):
                seen.add(everything.recv_multipart()[0])
            assert {b"raw", b"avar"} <= seen
            assert pub.stats()["subscriptions_applied"] == 2
            # some hundred PINGs later (pacing), the connection is still the first one: each PING
            # was answered through the guard (no PONG within the timeout drops it)
            time.sleep(2.5)
            assert not watch.poll(0), "the heartbeating subscriber was disconnected"
            # unsubscribing: the cancel is passed on (the client held it). Its next subscription
            # goes through the same connection after it, so once an `event` record has reached
            # `one`, libzmq has applied the cancel too: from then on no avar record reaches it.
            one.setsockopt(zmq.UNSUBSCRIBE, b"avar")
            one.setsockopt(zmq.SUBSCRIBE, b"event")
            end = time.monotonic() + DEADLINE_S
            while not (one.poll(5) and one.recv_multipart()[0] == b"event"):
                assert time.monotonic() < end, pub.stats()
                pub.publish("avar", {"kind": "avar", "v": 2})
                pub.publish("event", {"kind": "event", "v": 2})
            while one.poll(0):                                  # what was queued before
                one.recv_multipart()
            pub.publish("avar", {"kind": "avar", "v": 3})
            pub.publish("event", {"kind": "event", "v": 3})
            assert one.poll(DEADLINE_S * 1000)
            assert one.recv_multipart()[0] == b"event"          # the avar before it: not sent
            assert pub.stats()["cancels_ignored"] == 0
    finally:
        if watch is not None:
            everything.disable_monitor()
            watch.close(linger=0)
        ctx.destroy(linger=0)   # a failed check leaves no socket to hang a later GC


def test_a_rigs_sensor_topics_can_be_subscribed_before_their_first_record() -> None:
    """A client may subscribe to ``raw.left`` before the service sent anything on it: the
    lane's publisher declares its topics, so the guard passes the subscription on."""
    ctx = zmq.Context()
    with Publisher(LOCAL, "run-g", check=False) as pub:
        lane = SensorPublisher(pub, "left")
        sub = ctx.socket(zmq.SUB)
        sub.setsockopt(zmq.SUBSCRIBE, b"raw.left")
        sub.setsockopt(zmq.SUBSCRIBE, b"raw.right")       # no such sensor: dropped
        sub.connect(pub.endpoint)
        assert _first_received(sub, lambda: lane.publish("raw", {"kind": "raw", "v": 1})) \
            == b"raw.left"
        assert pub.stats()["subscriptions_dropped"] == 1
        sub.close(linger=0)
    ctx.term()


def test_nobody_reaches_the_pub_socket_around_the_guard() -> None:
    """The PUB socket's own endpoint (abstract ``ipc://@…``, listed in /proc/net/unix for
    anyone to see) takes connections from the service's process only: a subscriber in another
    process that connects there is refused before any subscription is read."""
    import subprocess
    import sys

    child = r"""
import sys, zmq
ctx = zmq.Context()
s = ctx.socket(zmq.SUB)
s.setsockopt(zmq.SUBSCRIBE, b"")
mon = s.get_monitor_socket(zmq.EVENT_HANDSHAKE_SUCCEEDED | zmq.EVENT_DISCONNECTED
                           | zmq.EVENT_CLOSED)
s.connect(sys.argv[1])
from zmq.utils.monitor import recv_monitor_message
ev = recv_monitor_message(mon)["event"]     # the first thing that happens to the connection
print("handshake" if ev == zmq.EVENT_HANDSHAKE_SUCCEEDED else "refused", flush=True)
"""
    with Publisher(LOCAL, "run-g", check=False) as pub:
        assert pub.inner_endpoint is not None and pub.inner_endpoint.startswith("ipc://@")
        out = subprocess.run([sys.executable, "-c", child, pub.inner_endpoint],
                             capture_output=True, text=True, timeout=60)
        assert out.stdout.strip() == "refused", (out.stdout, out.stderr[-500:])
        # the control: the public endpoint, from the same kind of child, is served
        out = subprocess.run([sys.executable, "-c", child, pub.endpoint],
                             capture_output=True, text=True, timeout=60)
        assert out.stdout.strip() == "handshake", (out.stdout, out.stderr[-500:])


def test_the_last_records_before_close_still_reach_a_subscriber() -> None:
    """At the service's stop, libzmq's linger flushes what is queued into the guard, and the
    guard relays it before it closes the subscriber's connection (ten closes in a row)."""
    # the records fit the relay's socket buffers (what libzmq flushes within its linger does
    # not wait on the guard's thread), so what is tested is the order of the close, not
    # whether a loaded machine schedules the guard within the linger
    for _ in range(10):
        ctx = zmq.Context()
        pub = Publisher(LOCAL, "run-g", check=False)
        try:
            sub = ctx.socket(zmq.SUB)
            sub.setsockopt(zmq.SUBSCRIBE, b"")
            sub.connect(pub.endpoint)
            _first_received(sub, lambda p=pub: p.publish("status", {"kind": "status", "v": 1}))
            for i in range(200):
                pub.publish("event", {"kind": "event", "v": 1, "i": i, "pad": b"x" * 200})
            pub.close()
            last = -1
            while last != 199 and sub.poll(DEADLINE_S * 1000):
                topic, data = sub.recv_multipart()
                if topic == b"event":
                    last = msgpack.unpackb(data)["i"]
            assert last == 199
        finally:
            pub.close()
            ctx.destroy(linger=0)   # a failed check leaves no socket to hang a later GC
