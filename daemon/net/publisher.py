"""ZeroMQ publishing of the service's records, and the request socket for late joiners.

``Publisher`` owns one PUB socket. ``publish(topic, record)`` stamps the run id and a per-topic
sequence number into the record and sends ``[topic, msgpack]`` without blocking: PUB drops
messages for a subscriber whose queue is at the high-water mark (HWM), so a slow or stalled
subscriber costs the service a bounded amount of memory and never stalls acquisition; the
subscriber sees what it lost as holes in the sequence numbers. Without CURVE, subscribers reach
the PUB socket through the subscription guard (daemon/net/front.py), which passes on only the
subscriptions that can match a published topic: what peers send cannot grow libzmq's
subscription trie.

``RequestServer`` owns one ROUTER socket in its own thread and answers requests
``{"op", "args", "id"}`` through a table of handlers (``snapshot``, ``status``, ``recent``,
``header``). Malformed, oversized and unknown requests get an error reply; nothing a peer sends
can raise out of the server thread.

Both bind to 127.0.0.1 unless told otherwise, and both take an optional CURVE configuration
(daemon/net/curve.py). The wire format is in docs/wire-format.md.
"""

from __future__ import annotations

import errno
import logging
import os
import secrets
import socket
import threading
import time
from collections.abc import Callable, Iterable, Mapping
from typing import Any

import zmq
from avard.core.errors import AvardError, ConfigError, FormatError
from avard.core.io import frames
from avard.daemon.net.admission import (
    MAX_GUARDED_SUBSCRIBERS,
    MAX_REQUEST_CONNECTIONS,
    MAX_SUBSCRIBERS,
    ConnectionGate,
    fd_budget,
)
from avard.daemon.net.curve import CurveServer, CurveServerConfig
from avard.daemon.net.front import SubscriptionFront, topic_prefixes

log = logging.getLogger(__name__)

# the [publish] defaults of daemon/config.py; the request socket is the PUB port + 1
DEFAULT_PUB_ENDPOINT = "tcp://127.0.0.1:5555"
DEFAULT_REQUEST_ENDPOINT = "tcp://127.0.0.1:5556"
#: PUB queue per subscriber, in messages: ~100 s of the service's ≤ 100 raw blocks/s.
DEFAULT_HWM = 10000
#: Shutdown never waits longer than this for queued messages (ms).
LINGER_MS = 200
#: How long, at most, the guard is given at close to relay what the PUB socket flushed into
#: it: it returns as soon as every connection has ended, so this bound is reached only on a
#: starved machine, where a LINGER-sized window lost the last records (the guard's thread
#: not scheduled in time); well inside systemd's TimeoutStopSec.
GUARD_DRAIN_S = 2.0
#: Kernel send buffer per subscriber (SO_SNDBUF; Linux books twice this), instead of TCP
#: autotuning's up to 4 MB: far above the stream's rate × any sane round trip.
PUB_SNDBUF = 128 << 10
#: A subscriber whose send queue stays at least half full for this long has stopped reading:
#: it is shut down and its queues freed (admission.ConnectionGate.shed_stalled). Memory per
#: stalled subscriber is then at most 2 × PUB_SNDBUF in the kernel plus what the stream sends
#: in STALL_S (and the checks' spacing) in libzmq's queue, whatever the HWM: bytes, not
#: messages; across subscribers at most MAX_SUBSCRIBERS times that.
STALL_S = 10.0
#: Largest message a subscriber may send the PUB socket (ZMQ_MAXMSGSIZE; libzmq drops a peer
#: that sends more). A subscriber only ever sends subscriptions, and libzmq keeps each in
#: its trie at one node per byte (some 25 bytes a node): one 4 MB subscription took the
#: service's RSS from 17 to 473 MB. Topics are short (``raw``, ``status.NAME``); the cap
#: leaves room for the CURVE handshake's commands, which the same limit applies to.
MAX_SUBSCRIPTION_BYTES = 1024
_LOOPBACK_HOSTS = {"127.0.0.1", "localhost", "::1", "[::1]"}

Handler = Callable[[dict[str, Any]], Mapping[str, Any]]
#: Unread replies queued per request peer, and requests queued per peer.
REPLY_HWM = 2
REQUEST_HWM = 2
#: Largest reply (a `recent` is capped at 2 MiB): with REPLY_HWM, ≤ 5 MiB per peer.
MAX_REPLY_BYTES = 5 << 19
#: Peers answered at once: a valid request from one more peer than this, while the others
#: asked within PEER_WINDOW_S, gets a short error instead of a reply, so the replies queued for
#: peers that do not read are bounded in total (MAX_PEERS × REPLY_HWM × MAX_REPLY_BYTES).
#: Only a request for an op this server answers takes a place: junk gets its (small) error
#: reply without one, so junk peers cannot lock clients out.
#: Requests queued are bounded too: ≤ MAX_REQUEST_CONNECTIONS connections (admission.py),
#: each with ≤ REQUEST_HWM + 1 messages of ≤ hard_cap_bytes.
MAX_PEERS = 16
PEER_WINDOW_S = 10.0
#: Requests answered per second, all peers together: a flood costs the service at most this
#: many handler calls (the reader shares the interpreter), the rest waits in libzmq's queues.
MAX_REQUESTS_PER_S = 200.0


def endpoint_host(endpoint: str) -> str | None:
    """Host part of a ``tcp://HOST:PORT`` endpoint; None for ipc/inproc endpoints."""
    if not endpoint.startswith("tcp://"):
        return None
    hostport = endpoint[len("tcp://"):]
    host, sep, _port = hostport.rpartition(":")
    if not sep:
        raise ConfigError(f"endpoint {endpoint!r} lacks a port; write tcp://HOST:PORT")
    return host


def is_loopback(endpoint: str) -> bool:
    """True for tcp endpoints on the loopback interface and for local ipc/inproc endpoints."""
    host = endpoint_host(endpoint)
    return host is None or host in _LOOPBACK_HOSTS


def _check_bind(endpoint: str, what: str, secured: bool, allow_remote: bool) -> str:
    """The endpoint to bind (``:0`` → ``:*``), once it is allowed: anything but loopback needs
    ``allow_remote`` (``[publish] allow_remote = true``)."""
    if endpoint.endswith(":0"):
        endpoint = endpoint[:-2] + ":*"
    if not is_loopback(endpoint):
        if not allow_remote:
            raise ConfigError(f"{what}: {endpoint} binds beyond loopback; set "
                              "[publish] allow_remote = true to do that on purpose (and "
                              "enable [curve])")
        # an explicit choice of the operator; say loudly when it is not authenticated
        if secured:
            log.info("%s binds %s (CURVE on)", what, endpoint)
        else:
            log.warning("%s binds %s without CURVE: anyone who reaches this interface can "
                        "read the stream (enable [curve])", what, endpoint)
    return endpoint


def _bind_conflict(what: str, endpoint: str, strerror: str) -> ConfigError:
    return ConfigError(f"{what} cannot bind {endpoint}: {strerror}; choose another "
                       "endpoint or stop the process that holds it")


def _bind(sock: zmq.Socket, endpoint: str, what: str, secured: bool,
          allow_remote: bool) -> str:
    """Bind and return the actual endpoint (ephemeral ``:*`` or ``:0`` ports resolved)."""
    endpoint = _check_bind(endpoint, what, secured, allow_remote)
    if (endpoint_host(endpoint) or "").startswith("["):
        sock.setsockopt(zmq.IPV6, 1)  # libzmq needs it for tcp://[::1]:PORT
    try:
        sock.bind(endpoint)
    except zmq.ZMQError as exc:
        raise _bind_conflict(what, endpoint, exc.strerror) from None
    return sock.getsockopt_string(zmq.LAST_ENDPOINT)


def _listen_tcp(endpoint: str, what: str, allow_remote: bool) -> tuple[socket.socket, str] | None:
    """A listening TCP socket for ``tcp://HOST:PORT`` as libzmq would bind it, and the
    endpoint with the port resolved; None when Python cannot resolve HOST (libzmq also takes
    interface names: those bind directly, without the subscription guard)."""
    endpoint = _check_bind(endpoint, what, False, allow_remote)
    host = endpoint_host(endpoint)
    if host is None:
        return None
    port_s = endpoint.rpartition(":")[2]
    port = 0 if port_s in ("*", "0") else int(port_s) if port_s.isdigit() else -1
    if port < 0:
        return None
    name = "" if host == "*" else host.strip("[]")
    try:
        infos = socket.getaddrinfo(name or None, port, socket.AF_INET if host == "*"
                                   else socket.AF_UNSPEC, socket.SOCK_STREAM, 0,
                                   socket.AI_PASSIVE)
    except OSError:
        return None
    family, type_, proto, _canon, addr = infos[0]
    sock = socket.socket(family, type_, proto)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)   # as libzmq does
        sock.bind(addr)
        sock.listen(100)                                             # libzmq's backlog
    except OSError as exc:
        sock.close()
        if exc.errno in (errno.EADDRINUSE, errno.EADDRNOTAVAIL, errno.EACCES):
            raise _bind_conflict(what, endpoint, exc.strerror or str(exc)) from None
        raise
    bound_host, bound_port = sock.getsockname()[:2]
    shown = f"[{bound_host}]" if family == socket.AF_INET6 else bound_host
    return sock, f"tcp://{shown}:{bound_port}"


class Publisher:
    """PUB socket with per-topic sequence numbers; never blocks the caller.

    Thread-safe: a lock serialises sends so the service loop and the temperature threads may
    share one publisher.
    """

    def __init__(self, endpoint: str = DEFAULT_PUB_ENDPOINT, run_id: str = "", *,
                 hwm: int = DEFAULT_HWM, curve: CurveServerConfig | None = None,
                 check: bool = True, allow_remote: bool = False,
                 max_subscribers: int | None = None, sndbuf: int = PUB_SNDBUF,
                 stall_s: float = STALL_S, topics: Iterable[str] = frames.TOPICS,
                 guard: bool = True) -> None:
        if hwm < 1:
            raise ConfigError(f"publisher hwm={hwm}: must be at least 1 message")
        self.run_id = str(run_id)
        self.check = check
        self._ctx = zmq.Context()
        self._curve: CurveServer | None = None
        self._front: SubscriptionFront | None = None
        #: the PUB socket's own endpoint behind the guard (None: bound directly)
        self.inner_endpoint: str | None = None
        self._lock = threading.Lock()
        self._seq: dict[str, int] = {}
        # the subscriptions that can match a topic this publisher sends (the guard's filter):
        # replaced whole, never changed in place, as the guard's thread reads it
        self._topics: frozenset[str] = frozenset()
        self._prefixes: frozenset[bytes] = frozenset({b""})
        self.declare_topics(topics)
        self.sent = 0
        self.dropped = 0
        self.peers = 0
        self.auth_failures = 0
        self._since_monitor = 0
        self.sndbuf = int(sndbuf)
        self.stall_s = float(stall_s)
        try:
            if curve is not None:
                self._curve = CurveServer(self._ctx, curve)
            self._sock = self._ctx.socket(zmq.PUB)
            self._sock.setsockopt(zmq.SNDHWM, hwm)
            self._sock.setsockopt(zmq.MAXMSGSIZE, MAX_SUBSCRIPTION_BYTES)
            self._sock.setsockopt(zmq.SNDBUF, self.sndbuf)
            self._sock.setsockopt(zmq.LINGER, LINGER_MS)
            if self._curve is not None:
                self._curve.apply(self._sock)
            # Without CURVE, subscribers reach the PUB socket through the subscription guard
            # (front.py): it passes on only subscriptions that can match a published topic,
            # so what a peer sends cannot grow libzmq's trie. The PUB socket listens on an
            # abstract unix socket (nothing in the file system, nothing left by a SIGKILL)
            # that accepts connections from this process only (SO_PEERCRED: the guard's),
            # so nobody reaches it around the guard.
            listening = None
            if guard and curve is None:
                try:
                    self._sock.setsockopt(zmq.IPC_FILTER_PID, os.getpid())
                except zmq.ZMQError:
                    log.warning("publisher: libzmq cannot restrict an ipc endpoint to this "
                                "process; subscriptions are not guarded")
                else:
                    listening = (_listen_tcp(endpoint, "publisher", allow_remote)
                                 if endpoint.startswith("tcp://") else None)
                    if listening is None:
                        log.warning("publisher: %s is not a tcp://HOST:PORT this process "
                                    "can bind itself; subscriptions are not guarded", endpoint)
            fds_each = 3 if listening is not None else 1
            if max_subscribers is None:
                max_subscribers = (MAX_GUARDED_SUBSCRIBERS if listening is not None
                                   else MAX_SUBSCRIBERS)
            cap = fd_budget(max_subscribers, what="publisher", others=MAX_REQUEST_CONNECTIONS,
                            fds_each=fds_each)
            # connection events: STATUS says how many subscribers are connected, and the
            # gate keeps them ≤ max_subscribers (admission.py: the fd table is bounded)
            self._gate = ConnectionGate(
                self._sock, cap, "publisher", evict_newest=True,
                extra_events=zmq.EVENT_HANDSHAKE_FAILED_AUTH)
            if listening is not None:
                lsock, self.endpoint = listening
                name = f"avard-pub-{os.getpid()}-{secrets.token_hex(8)}"
                self.inner_endpoint = f"ipc://@{name}"
                try:
                    self._sock.bind(self.inner_endpoint)
                except BaseException:
                    lsock.close()
                    raise
                self._gate.bound(self.inner_endpoint)
                self._front = SubscriptionFront(
                    lsock, "\0" + name, self._allowed, max_connections=cap,
                    sndbuf=self.sndbuf, max_frame=MAX_SUBSCRIPTION_BYTES)
            else:
                self.endpoint = _bind(self._sock, endpoint, "publisher", curve is not None,
                                      allow_remote)
                self._gate.bound(self.endpoint)
        except BaseException:
            self._teardown()
            raise
        log.info("publishing on %s (run %s, hwm %d%s)", self.endpoint, self.run_id, hwm,
                 ", subscriptions guarded" if self._front is not None else "")

    def declare_topics(self, topics: Iterable[str]) -> None:
        """Topics this publisher will send (before their first message): subscriptions to
        their prefixes are passed on from then on. A topic sent is declared by sending it."""
        new = set(topics) - self._topics
        if new:
            self._topics = self._topics | new
            self._prefixes = self._prefixes | topic_prefixes(new)

    def _allowed(self, sub: bytes) -> bool:
        return sub in self._prefixes

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any], run_id: str) -> Publisher:
        """From the validated config of daemon/config.py (``[publish]`` and ``[curve]``)."""
        pub = cfg["publish"]
        return cls(pub["endpoint"], run_id, hwm=pub["hwm"],
                   curve=CurveServerConfig.from_config(cfg),
                   allow_remote=pub["allow_remote"])

    def next_seq(self, topic: str) -> int:
        """The sequence number the next message on ``topic`` will carry."""
        return self._seq.get(topic, 0)

    def publish(self, topic: str | None, record: Mapping[str, Any]) -> int:
        """Send ``record`` on ``topic`` (default: its kind's topic); return its sequence number.

        The record is copied with ``run`` and ``seq`` filled in. A full local queue (zmq.Again)
        counts as dropped; the sequence number is used up either way, so subscribers see it.
        """
        if topic is None:
            topic = frames.topic_of(record)
        if topic not in self._topics:
            self.declare_topics([topic])
        rec = dict(record)
        rec["run"] = self.run_id
        with self._lock:
            seq = self._seq.get(topic, 0)
            rec["seq"] = seq
            # encode first: a record that cannot be encoded raises and uses up no number
            data = frames.encode(rec, check=self.check)
            self._seq[topic] = seq + 1
            try:
                self._sock.send_multipart([topic.encode("ascii"), data], flags=zmq.NOBLOCK,
                                          copy=len(data) < 65536)
                self.sent += 1
            except zmq.Again:
                self.dropped += 1
            self._since_monitor += 1
            if self._since_monitor >= 8:  # connection events are rare; skip the syscall
                self._poll_monitor()
        return seq

    def _poll_monitor(self) -> None:
        self._since_monitor = 0
        for ev in self._gate.poll():
            if ev == zmq.EVENT_HANDSHAKE_FAILED_AUTH:
                self.auth_failures += 1
                log.warning("publisher refused a peer that failed CURVE authentication")
        now = time.monotonic()
        self._gate.shed_stalled(now, self.sndbuf // 2, self.stall_s)
        if self._front is not None:
            # behind the guard the stall shows in the guard's queue for the subscriber first
            # (the PUB socket's ipc peer is the guard, which stops reading for it)
            self._front.shed_stalled(now, self.stall_s)
        self.peers = self._gate.connections

    def reload_keys(self) -> None:
        """Re-read the authorised client keys (call on SIGHUP); no-op without CURVE."""
        if self._curve is not None:
            self._curve.reload()

    def stats(self) -> dict[str, Any]:
        """Counters for STATUS: sent, dropped locally, connected peers, refused peers, seqs."""
        with self._lock:
            self._poll_monitor()
            front = self._front
            st = {"endpoint": self.endpoint, "sent": self.sent, "dropped": self.dropped,
                  "peers": self.peers, "auth_failures": self.auth_failures,
                  "refused_connections": self._gate.evicted + (front.refused if front else 0),
                  "stalled_shut_down": self._gate.stalled_evicted
                  + (front.stalled if front else 0),
                  "max_send_queue_bytes": self._gate.max_outq,
                  "subscriptions_guarded": front is not None,
                  "seq": dict(self._seq)}
            if front is not None:
                st.update(front.stats())
            return st

    def close(self) -> None:
        """Close the socket (LINGER bounds the wait) and stop the authenticator."""
        with self._lock:
            self._teardown()

    def _teardown(self) -> None:
        sock = getattr(self, "_sock", None)
        gate = getattr(self, "_gate", None)
        if gate is not None and sock is not None and not sock.closed:
            gate.close()
        if sock is not None:
            sock.close(linger=LINGER_MS)
        if self._curve is not None:
            self._curve.stop()
            self._curve = None
        self._ctx.term()      # waits ≤ LINGER_MS for queued records, the guard relaying them
        front = getattr(self, "_front", None)
        if front is not None:
            # then the guard: what it holds for a subscriber goes out first
            front.stop(drain_s=GUARD_DRAIN_S)
            self._front = None

    def __enter__(self) -> Publisher:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _readable_op_id(payload: bytes, max_bytes: int) -> tuple[str, int]:
    """The ``op`` and ``id`` of a request as far as they are readable ("?" and 0 otherwise),
    so that an error reply to a request that is otherwise invalid still names it."""
    try:
        req = frames.unpack_bounded(payload, max_bytes=max_bytes, what="request")
    except FormatError:
        return "?", 0
    if not isinstance(req, dict):
        return "?", 0
    op, rid = req.get("op"), req.get("id")
    return (op[:64] if isinstance(op, str) else "?",
            rid if type(rid) is int and -(1 << 63) <= rid < (1 << 64) else 0)


class RequestServer:
    """ROUTER socket answering ``snapshot``/``status``/``recent``/``header`` in its own thread.

    ``handlers`` maps an op name to ``fn(args) -> result map``; handlers run in the server
    thread, so they must be thread-safe. A handler raising AvardError sends its message back
    as the error; any other exception is logged with its traceback and answered with
    "internal error". Requests larger than ``max_request_bytes`` get an error reply; messages
    beyond ``hard_cap_bytes`` are dropped by libzmq before they are buffered (the peer is
    disconnected), which bounds the memory a hostile peer can make the service use.
    """

    def __init__(self, endpoint: str = DEFAULT_REQUEST_ENDPOINT,
                 handlers: Mapping[str, Handler] | None = None, *,
                 curve: CurveServerConfig | None = None, max_request_bytes: int = 65536,
                 max_reply_bytes: int = MAX_REPLY_BYTES,
                 max_requests_per_s: float = MAX_REQUESTS_PER_S, max_peers: int = MAX_PEERS,
                 hard_cap_bytes: int | None = None, allow_remote: bool = False,
                 max_connections: int = MAX_REQUEST_CONNECTIONS) -> None:
        self.allow_remote = allow_remote
        self.max_connections = int(max_connections)
        self._gate: ConnectionGate | None = None
        self.handlers: dict[str, Handler] = dict(handlers or {})
        self._requested_endpoint = endpoint
        self._curve_config = curve
        self.max_request_bytes = int(max_request_bytes)
        self.max_reply_bytes = int(max_reply_bytes)
        self.hard_cap_bytes = int(hard_cap_bytes or 2 * self.max_request_bytes)
        self.endpoint = endpoint
        self.max_requests_per_s = float(max_requests_per_s)
        self.max_peers = int(max_peers)
        self._peers: dict[bytes, float] = {}   # identity → last request (monotonic s)
        self._last_admitted = False   # the last handle_frames answered an admitted request
        self.refused_peers = 0
        self.answered = 0
        self.errors = 0
        self.refused_replies = 0     # replies a peer's full queue refused (it does not read)
        self._ctx: zmq.Context | None = None
        self._curve: CurveServer | None = None
        self._sock: zmq.Socket | None = None
        # An inproc pair that wakes the server thread's poll at stop(): it then sleeps in
        # poll() without a timeout instead of waking ten times a second to look at _stop.
        self._wake_rx: zmq.Socket | None = None
        self._wake_tx: zmq.Socket | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any], handlers: Mapping[str, Handler]
                    ) -> RequestServer:
        """From the validated config of daemon/config.py (``[publish]`` and ``[curve]``)."""
        pub = cfg["publish"]
        return cls(pub["request_endpoint"], handlers, curve=CurveServerConfig.from_config(cfg),
                   allow_remote=pub["allow_remote"])

    def start(self) -> RequestServer:
        """Bind (errors raise here, in the caller's thread) and start answering."""
        if self._thread is not None:
            return self
        self._ctx = zmq.Context()
        try:
            if self._curve_config is not None:
                self._curve = CurveServer(self._ctx, self._curve_config)
            sock = self._ctx.socket(zmq.ROUTER)
            self._sock = sock
            sock.setsockopt(zmq.LINGER, LINGER_MS)
            sock.setsockopt(zmq.MAXMSGSIZE, self.hard_cap_bytes)
            # Bounded replies: at most REPLY_HWM unread replies queue per peer (a peer that
            # never reads costs ≤ REPLY_HWM × max_reply_bytes, then its replies are refused),
            # and at most REQUEST_HWM requests wait per peer (then libzmq stops reading it).
            sock.setsockopt(zmq.SNDHWM, REPLY_HWM)
            sock.setsockopt(zmq.RCVHWM, REQUEST_HWM)
            sock.setsockopt(zmq.ROUTER_MANDATORY, 1)   # a full peer raises, it is counted
            if self._curve is not None:
                self._curve.apply(sock)
            self._gate = ConnectionGate(sock, fd_budget(self.max_connections,
                                                        what="request server"),
                                        "request server", evict_newest=False)
            self.endpoint = _bind(sock, self._requested_endpoint, "request server",
                                  self._curve is not None, self.allow_remote)
            self._gate.bound(self.endpoint)
            wake = f"inproc://avard-request-wake-{id(self)}"
            self._wake_rx = self._ctx.socket(zmq.PAIR)
            self._wake_rx.bind(wake)
            self._wake_tx = self._ctx.socket(zmq.PAIR)
            self._wake_tx.setsockopt(zmq.LINGER, 0)
            self._wake_tx.connect(wake)
        except BaseException:
            self._close_all()
            raise
        self._stop.clear()
        self._thread = threading.Thread(target=self._serve, name="avard-request", daemon=True)
        self._thread.start()
        log.info("answering requests on %s (ops: %s)", self.endpoint,
                 ", ".join(sorted(self.handlers)))
        return self

    def reload_keys(self) -> None:
        """Re-read the authorised client keys (call on SIGHUP); no-op without CURVE."""
        if self._curve is not None:
            self._curve.reload()

    def stop(self, timeout: float = 2.0) -> None:
        """Stop the thread and close the socket; returns within about ``timeout`` seconds."""
        self._stop.set()
        if self._wake_tx is not None and self._thread is not None:
            try:
                self._wake_tx.send(b"", zmq.NOBLOCK)
            except zmq.ZMQError:
                pass   # the thread also sees _stop at its next request
        if self._thread is not None:
            self._thread.join(timeout)
            if self._thread.is_alive():
                log.warning("request server thread did not stop within %.1f s", timeout)
            self._thread = None
        self._close_all()

    def _close_all(self) -> None:
        for attr in ("_wake_rx", "_wake_tx"):
            wake: zmq.Socket | None = getattr(self, attr)
            if wake is not None:
                wake.close(linger=0)
                setattr(self, attr, None)
        if self._gate is not None:
            self._gate.close()
            self._gate = None
        if self._sock is not None:
            self._sock.close(linger=LINGER_MS)
            self._sock = None
        if self._curve is not None:
            self._curve.stop()
            self._curve = None
        if self._ctx is not None:
            self._ctx.term()
            self._ctx = None

    def __enter__(self) -> RequestServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # ---- the server thread ----------------------------------------------------------------

    def _serve(self) -> None:
        sock = self._sock
        assert sock is not None
        poller = zmq.Poller()
        poller.register(sock, zmq.POLLIN)
        if self._wake_rx is not None:
            poller.register(self._wake_rx, zmq.POLLIN)
        gate = self._gate
        if gate is not None:
            poller.register(gate.monitor, zmq.POLLIN)
        interval = 1.0 / self.max_requests_per_s
        next_slot = time.monotonic()
        while not self._stop.is_set():
            # Pace: one request per interval at most (bursts of up to a second's worth).
            now = time.monotonic()
            if next_slot > now:
                self._stop.wait(next_slot - now)
            next_slot = max(next_slot, now - 1.0) + interval
            try:
                ready = dict(poller.poll(None if self._wake_rx is not None else 100))
                if gate is not None:
                    gate.poll()     # connections counted and capped before any request
                if sock not in ready:
                    continue
                parts = sock.recv_multipart(zmq.NOBLOCK, copy=False)
                msg = [p.bytes for p in parts]
            except zmq.Again:
                continue
            except zmq.ZMQError as exc:
                if self._stop.is_set():
                    break
                log.error("request socket error: %s", exc)
                continue
            try:
                reply_frames = self.handle_frames(msg)
            except Exception:  # never let anything a peer sends end the thread
                log.exception("request handling failed")
                continue
            if reply_frames is None:
                continue
            if gate is not None and self._last_admitted:
                gate.note_request(parts[-1].get(zmq.SRCFD))
            try:
                sock.send_multipart(reply_frames, flags=zmq.NOBLOCK)
            except zmq.ZMQError as exc:  # peer gone or its queue full: its problem, not ours
                self.refused_replies += 1
                log.debug("reply not sent: %s", exc)

    def handle_frames(self, msg: list[bytes]) -> list[bytes] | None:
        """Route one ROUTER message (REQ or DEALER peer) to a reply; None when unanswerable."""
        if len(msg) < 2:
            return None  # no identity and payload: nothing to answer
        identity = msg[0]
        if msg[1] == b"":  # a REQ peer puts an empty delimiter before the payload
            envelope, payloads = [identity, b""], msg[2:]
        else:
            envelope, payloads = [identity], msg[1:]
        self._last_admitted = False
        if len(payloads) != 1:
            self.errors += 1
            return [*envelope, frames.encode_reply(
                "?", error=f"expected one request frame, got {len(payloads)}")]
        op, _rid = _readable_op_id(payloads[0], self.max_request_bytes)
        if op not in self.handlers or len(payloads[0]) > self.max_request_bytes:
            return [*envelope, self.handle(payloads[0])]   # junk: an error, no place taken
        if not self._admit(identity):
            self.errors += 1
            self.refused_peers += 1
            op, rid = _readable_op_id(payloads[0], self.max_request_bytes)
            return [*envelope, frames.encode_reply(
                op, id=rid, error=f"busy: {self.max_peers} other clients asked within "
                f"{PEER_WINDOW_S:g} s; ask again later")]
        self._last_admitted = True
        return [*envelope, self.handle(payloads[0])]

    def _admit(self, identity: bytes) -> bool:
        """Whether this peer may be answered: it is one of the ``max_peers`` that asked last
        within PEER_WINDOW_S (peers quiet for longer make room)."""
        now = time.monotonic()
        peers = self._peers
        if identity not in peers:
            for old in [p for p, t in peers.items() if now - t > PEER_WINDOW_S]:
                del peers[old]
            if len(peers) >= self.max_peers:
                return False
        peers[identity] = now
        return True

    def handle(self, payload: bytes) -> bytes:
        """Answer one request payload with reply bytes; every failure becomes an error reply
        that echoes the request's ``op`` and ``id`` when they could be read."""
        op, rid = "?", 0
        try:
            if len(payload) > self.max_request_bytes:
                raise FormatError(f"request of {len(payload)} bytes exceeds the "
                                  f"{self.max_request_bytes}-byte limit")
            op, rid = _readable_op_id(payload, self.max_request_bytes)
            req = frames.decode_request(payload, max_bytes=self.max_request_bytes)
            op, rid = req["op"], req["id"]
            handler = self.handlers.get(op)
            if handler is None:
                raise FormatError(f"unknown op {op[:40]!r}; this server answers "
                                  f"{', '.join(sorted(self.handlers)) or 'nothing'}")
            result = handler(req["args"])
            reply = frames.encode_reply(op, result=result, id=rid)
            if len(reply) > self.max_reply_bytes:
                raise FormatError(f"reply of {len(reply)} bytes exceeds the "
                                  f"{self.max_reply_bytes}-byte limit; ask for less")
            self.answered += 1
            return reply
        except AvardError as exc:
            self.errors += 1
            return frames.encode_reply(op, error=str(exc), id=rid)
        except Exception as exc:
            self.errors += 1
            log.exception("handler for %r failed", op)
            return frames.encode_reply(op, error=f"internal error ({type(exc).__name__})",
                                       id=rid)
