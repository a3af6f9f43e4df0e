"""The subscription guard: what a subscriber may make the PUB socket hold (adv27, daemon28).

libzmq's PUB socket keeps every subscription its peers send in a trie, one node per byte, for
as long as the peer stays connected; nothing in libzmq bounds how many distinct subscriptions
a peer sends (``ZMQ_MAXMSGSIZE`` bounds one). ``XPUB_MANUAL`` does not help: libzmq still keeps
every subscription it reads, per pipe, to unsubscribe them when the pipe ends (xpub.cpp's
``manual_subscriptions``), and it reads a pipe's whole inflow into that trie in one go, before
the application sees any of it. So the filter has to sit before libzmq reads anything.

:class:`SubscriptionFront` listens on the publisher's public endpoint and relays each
subscriber's connection to the PUB socket, which is bound to an abstract ``ipc://@…``
endpoint that accepts connections from the service's own process only (``IPC_FILTER_PID``).
Bytes from the service to the subscriber pass through as they are. Bytes from the subscriber
are parsed as ZMTP 3 frames (greeting, then ``flags, size, body``), and
each subscription or cancel — a message whose first byte is 1 or 0 (ZMTP 3.0) or a
``SUBSCRIBE``/``CANCEL`` command (3.1) — is passed on only when it can matter:

* a subscription is passed on when it is a prefix of a topic the service publishes (the empty
  subscription included) and this connection does not hold it already; otherwise it is
  dropped and counted;
* a cancel is passed on when this connection holds that subscription; otherwise ignored.

The PUB socket's trie therefore holds, per connection, a subset of the prefixes of the
published topics, whatever a peer sends; the guard's own state per connection is that set and
buffers of fixed size. Other commands (READY, PING, PONG) pass through; a frame above
``max_frame`` bytes, a greeting that is not ZMTP 3 with the NULL mechanism, or a malformed
frame ends the connection (as libzmq would). The guard runs in one thread that sleeps in
``select`` until a socket has work (no timeout); the service's send path is the PUB socket's,
unchanged and non-blocking. Only used without CURVE: encrypted frames cannot be read here.
"""

from __future__ import annotations

import errno
import logging
import selectors
import socket
import threading
import time
from collections.abc import Callable, Iterable

log = logging.getLogger(__name__)

GREETING_BYTES = 64
#: Bytes read from a peer at once (either direction).
CHUNK = 16384
#: Bytes queued towards a subscriber before the guard stops reading from the PUB socket for
#: it (libzmq's own queue and its high-water mark take over from there, as without a guard).
S2C_LIMIT = 32768
#: Bytes queued towards the PUB socket before the guard stops reading from the subscriber.
C2S_LIMIT = 16384
#: Log lines about dropped subscriptions: at most one per this many seconds (the count of
#: lines held back is in the next one and the totals are in the service's status).
LOG_EVERY_S = 60.0

_FLAG_MORE, _FLAG_LONG, _FLAG_COMMAND = 0x01, 0x02, 0x04


def topic_prefixes(topics: Iterable[str | bytes]) -> set[bytes]:
    """Every prefix of every topic, the empty one included: the subscriptions that can match."""
    out: set[bytes] = {b""}
    for t in topics:
        b = t.encode("ascii") if isinstance(t, str) else bytes(t)
        out.update(b[:i] for i in range(1, len(b) + 1))
    return out


class _Conn:
    __slots__ = ("applied", "c2s_in", "c2s_out", "client", "closed", "dropped", "full_since",
                 "greeting", "inner", "inner_eof", "mask_c", "mask_i", "more", "peer",
                 "s2c_out", "subs")

    def __init__(self, client: socket.socket, inner: socket.socket, peer: str) -> None:
        self.client = client
        self.inner = inner
        self.peer = peer
        self.c2s_in = bytearray()      # from the subscriber, not yet parsed
        self.c2s_out = bytearray()     # parsed, passed on, not yet written to the PUB socket
        self.s2c_out = bytearray()     # from the PUB socket, not yet written to the subscriber
        self.greeting = GREETING_BYTES  # greeting bytes still to pass through
        self.more = False              # inside a multi-frame message (dropped whole)
        self.subs: set[bytes] = set()  # subscriptions passed on and not cancelled
        self.applied = 0
        self.dropped = 0
        self.mask_c = 0
        self.mask_i = 0
        self.closed = False
        #: the PUB socket closed its end (the service stops): what it sent still goes out
        self.inner_eof = False
        #: monotonic time since which s2c_out has stayed full (the subscriber does not read)
        self.full_since: float | None = None


class SubscriptionFront:
    """Relay from the public endpoint to the PUB socket's private one, filtering subscriptions.

    ``allowed(sub)`` says whether a subscription (bytes) can match a published topic; it is
    called from the guard's thread. ``listen`` is a bound, listening TCP socket; ``inner`` the
    address of the PUB socket's ipc endpoint (a leading NUL: the abstract namespace)."""

    def __init__(self, listen: socket.socket, inner: str, allowed: Callable[[bytes], bool], *,
                 max_connections: int, sndbuf: int, max_frame: int) -> None:
        self.listen = listen
        self.inner_path = inner
        self.allowed = allowed
        self.max_connections = int(max_connections)
        self.sndbuf = int(sndbuf)
        self.max_frame = int(max_frame)
        self.accepted = 0
        self.refused = 0            # connections beyond max_connections, closed at once
        self.protocol_closed = 0    # connections ended for an oversized or malformed frame
        self.applied = 0            # subscriptions passed on to the PUB socket
        self.dropped = 0            # subscriptions that can match nothing published, or extra
        self.cancels_ignored = 0    # cancels of a subscription the connection does not hold
        self.stalled = 0            # subscribers shut down for reading nothing (shed_stalled)
        self._conns: dict[int, _Conn] = {}   # fileno (either side) → connection
        self._sel = selectors.DefaultSelector()
        self._wake_r, self._wake_w = socket.socketpair()
        self._wake_r.setblocking(False)
        self._wake_w.setblocking(False)
        self._stop = False
        self._last_log = -LOG_EVERY_S
        self._held_back = 0
        self._listen_paused = False
        self._idle = threading.Event()        # set while no subscriber is connected
        self._idle.set()
        listen.setblocking(False)
        self._sel.register(listen, selectors.EVENT_READ, "listen")
        self._sel.register(self._wake_r, selectors.EVENT_READ, "wake")
        self._thread = threading.Thread(target=self._run, name="avard-pub-guard", daemon=True)
        self._thread.start()

    @property
    def connections(self) -> int:
        return len(self._conns) // 2

    def stats(self) -> dict[str, int]:
        return {"subscriptions_applied": self.applied, "subscriptions_dropped": self.dropped,
                "cancels_ignored": self.cancels_ignored,
                "protocol_closed": self.protocol_closed}

    def shed_stalled(self, now: float, stall_s: float) -> int:
        """Shut down every subscriber whose queue in the guard has stayed full for
        ``stall_s`` (it reads nothing: its TCP send buffer is full and so is ours); the guard's
        thread then sees the connection end and closes both sides, and libzmq frees its queue
        for it. Called from the publisher's thread (``shutdown(2)`` is safe across threads;
        a connection closed meanwhile raises OSError here, ignored). Returns how many."""
        shed = 0
        for conn in list(self._conns.values()):
            since = conn.full_since
            if conn.closed or since is None or now - since < stall_s:
                continue
            conn.full_since = None
            try:
                conn.client.shutdown(socket.SHUT_RDWR)
            except OSError:
                continue
            self.stalled += 1
            shed += 1
            (log.warning if self.stalled <= 10 or self.stalled % 1000 == 0 else log.debug)(
                "publisher: subscriber %s read nothing for %.0f s: shut down (#%d), its "
                "queues freed", conn.peer, stall_s, self.stalled)
        return shed

    def stop(self, timeout: float = 2.0, drain_s: float = 0.0) -> None:
        """Stop the thread and close every connection; with ``drain_s``, first wait that long
        at most for the connections to end by themselves (the PUB socket closed: each one
        ends once what the service sent is out)."""
        if drain_s > 0:
            self._idle.wait(drain_s)
        self._stop = True
        try:
            self._wake_w.send(b"x")
        except OSError:
            pass
        self._thread.join(timeout)
        if self._thread.is_alive():
            log.warning("publisher guard thread did not stop within %.1f s", timeout)
            return
        for conn in list({id(c): c for c in self._conns.values()}.values()):
            self._close(conn, log_it=False)
        self._sel.close()
        self.listen.close()
        self._wake_r.close()
        self._wake_w.close()

    # ---- the guard's thread ---------------------------------------------------------------

    def _run(self) -> None:
        while not self._stop:
            try:
                events = self._sel.select()       # no timeout: woken by work or by stop()
            except OSError as exc:                # EINTR is retried by selectors itself
                log.error("publisher guard: select failed: %s", exc)
                return
            for key, mask in events:
                try:
                    if key.data == "listen":
                        self._accept()
                    elif key.data == "wake":
                        self._wake_r.recv(64)
                    else:
                        conn = key.data
                        if not conn.closed:
                            self._service(conn, key.fileobj is conn.client, mask)
                except Exception:   # nothing a peer sends may end the thread
                    log.exception("publisher guard: unexpected error")
                    if isinstance(key.data, _Conn):
                        try:
                            self._close(key.data, log_it=False)
                        except Exception:
                            log.exception("publisher guard: closing failed")

    def _accept(self) -> None:
        while True:
            try:
                client, addr = self.listen.accept()
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:
                # EMFILE and friends: say so, leave the peer in the backlog and stop looking
                # at the listener until a connection ends (it would stay readable: a spin)
                if exc.errno in (errno.EMFILE, errno.ENFILE, errno.ENOBUFS, errno.ENOMEM):
                    log.warning("publisher guard: cannot accept: %s; accepting again when a "
                                "subscriber leaves", exc.strerror)
                    if not self._listen_paused:
                        self._sel.unregister(self.listen)
                        self._listen_paused = True
                    return
                continue
            self.accepted += 1
            if self.connections >= self.max_connections:
                self.refused += 1
                (log.warning if self.refused <= 10 or self.refused % 1000 == 0 else log.debug)(
                    "publisher: %d subscribers (the cap): a newcomer was refused (#%d)",
                    self.max_connections, self.refused)
                client.close()
                continue
            inner = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            try:
                inner.settimeout(1.0)
                inner.connect(self.inner_path)
            except OSError as exc:
                log.warning("publisher guard: cannot reach the PUB socket: %s", exc)
                inner.close()
                client.close()
                continue
            inner.setblocking(False)
            client.setblocking(False)
            try:
                client.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, self.sndbuf)
                client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            except OSError:
                pass
            peer = f"{addr[0]}:{addr[1]}" if isinstance(addr, tuple) else str(addr)
            conn = _Conn(client, inner, peer)
            self._idle.clear()
            self._conns[client.fileno()] = conn
            self._conns[inner.fileno()] = conn
            self._update(conn)

    def _update(self, conn: _Conn) -> None:
        """(Re-)register both sides for what they can do now."""
        mc = 0
        if len(conn.c2s_out) < C2S_LIMIT:
            mc |= selectors.EVENT_READ
        if conn.s2c_out:
            mc |= selectors.EVENT_WRITE
        mi = 0
        if conn.inner_eof:
            conn.c2s_out.clear()     # nobody to pass it to
            if conn.full_since is None:
                conn.full_since = time.monotonic()   # it drains, or shed_stalled ends it
        elif len(conn.s2c_out) < S2C_LIMIT:
            mi |= selectors.EVENT_READ
            conn.full_since = None
        elif conn.full_since is None:
            conn.full_since = time.monotonic()
        if conn.c2s_out and not conn.inner_eof:
            mi |= selectors.EVENT_WRITE
        for sock, old, new in ((conn.client, conn.mask_c, mc), (conn.inner, conn.mask_i, mi)):
            if old == new:
                continue
            if old == 0:
                self._sel.register(sock, new, conn)
            elif new == 0:
                self._sel.unregister(sock)
            else:
                self._sel.modify(sock, new, conn)
        conn.mask_c, conn.mask_i = mc, mi

    def _service(self, conn: _Conn, client_side: bool, mask: int) -> None:
        try:
            if mask & selectors.EVENT_READ:
                src = conn.client if client_side else conn.inner
                try:
                    data = src.recv(CHUNK)
                except (BlockingIOError, InterruptedError):
                    data = None
                if data is not None:
                    if not data:
                        if client_side or not conn.s2c_out:
                            self._close(conn)
                            return
                        conn.inner_eof = True   # the service's last records still go out
                    if client_side:
                        conn.c2s_in += data
                        if not self._parse(conn):
                            self.protocol_closed += 1
                            self._close(conn)
                            return
                    else:
                        conn.s2c_out += data
            # write what can be written now, either way (saves a round through select)
            for dst, out in ((conn.client, conn.s2c_out), (conn.inner, conn.c2s_out)):
                if out:
                    try:
                        n = dst.send(out)
                    except (BlockingIOError, InterruptedError):
                        continue
                    del out[:n]
        except OSError:
            self._close(conn)
            return
        if conn.inner_eof and not conn.s2c_out:
            self._close(conn)
            return
        self._update(conn)

    def _parse(self, conn: _Conn) -> bool:
        """Move what the subscriber sent from ``c2s_in`` to ``c2s_out``, frame by frame,
        leaving out the subscriptions that are not passed on. False: end the connection."""
        buf = conn.c2s_in
        if conn.greeting:
            n = min(conn.greeting, len(buf))
            done = GREETING_BYTES - conn.greeting
            head = bytes(buf[:n])
            # signature 0xFF … 0x7F, then the major version (3) and the mechanism (NULL)
            for i, b in enumerate(head, start=done):
                if (i == 0 and b != 0xFF) or (i == 9 and b != 0x7F) or (i == 10 and b < 3):
                    return False
            mech_lo, mech_hi = max(12, done), min(32, done + n)
            if mech_lo < mech_hi:
                want = b"NULL".ljust(20, b"\0")[mech_lo - 12:mech_hi - 12]
                if head[mech_lo - done:mech_hi - done] != want:
                    return False
            conn.c2s_out += head
            del buf[:n]
            conn.greeting -= n
            if conn.greeting:
                return True
        pos = 0
        while True:
            if len(buf) - pos < 2:
                break
            flags = buf[pos]
            if flags & ~(_FLAG_MORE | _FLAG_LONG | _FLAG_COMMAND):
                return False
            if flags & _FLAG_LONG:
                if len(buf) - pos < 9:
                    break
                size = int.from_bytes(buf[pos + 1:pos + 9], "big")
                hdr = 9
            else:
                size = buf[pos + 1]
                hdr = 2
            if size > self.max_frame:
                return False
            end = pos + hdr + size
            if len(buf) < end:
                break
            body = bytes(buf[pos + hdr:end])
            if self._keep(conn, flags, body):
                conn.c2s_out += buf[pos:end]
            pos = end
        del buf[:pos]
        return True

    def _keep(self, conn: _Conn, flags: int, body: bytes) -> bool:
        """Whether one frame goes on to the PUB socket (and the subscription books)."""
        if flags & _FLAG_COMMAND:
            if not body:
                return False
            name = body[1:1 + body[0]]
            if name == b"SUBSCRIBE":
                return self._subscribe(conn, body[1 + body[0]:])
            if name == b"CANCEL":
                return self._cancel(conn, body[1 + body[0]:])
            return True                 # READY, PING, PONG, ERROR: the protocol's own
        more, conn.more = conn.more, bool(flags & _FLAG_MORE)
        if more or flags & _FLAG_MORE or not body or body[0] > 1:
            return False                # a subscriber sends nothing else; PUB ignores it
        if body[0] == 1:
            return self._subscribe(conn, body[1:])
        return self._cancel(conn, body[1:])

    def _subscribe(self, conn: _Conn, topic: bytes) -> bool:
        if topic in conn.subs:
            return False                # held already: the PUB trie's entry is a set member
        if self.allowed(topic):
            conn.subs.add(topic)
            conn.applied += 1
            self.applied += 1
            return True
        conn.dropped += 1
        self.dropped += 1
        if conn.dropped == 1 or conn.dropped % 100000 == 0:
            self._log_drops(conn, topic)
        return False

    def _cancel(self, conn: _Conn, topic: bytes) -> bool:
        if topic in conn.subs:
            conn.subs.discard(topic)
            return True
        self.cancels_ignored += 1
        return False

    def _log_drops(self, conn: _Conn, topic: bytes | None) -> None:
        now = time.monotonic()
        if now - self._last_log < LOG_EVERY_S:
            self._held_back += 1
            return
        held, self._held_back, self._last_log = self._held_back, 0, now
        what = f"e.g. {topic[:32]!r}" if topic is not None else "on closing"
        log.warning("publisher: subscriber %s sent %d subscription(s) that match no topic "
                    "avard publishes (%s): dropped, not held; %d dropped in all%s",
                    conn.peer, conn.dropped, what, self.dropped,
                    f" ({held} such lines held back)" if held else "")

    def _close(self, conn: _Conn, log_it: bool = True) -> None:
        if conn.closed:
            return
        conn.closed = True
        for sock, mask in ((conn.client, conn.mask_c), (conn.inner, conn.mask_i)):
            self._conns.pop(sock.fileno(), None)
            if mask:
                try:
                    self._sel.unregister(sock)
                except (KeyError, ValueError):
                    pass
            sock.close()
        if not self._conns:
            self._idle.set()
        if self._listen_paused and not self._stop:
            self._listen_paused = False
            self._sel.register(self.listen, selectors.EVENT_READ, "listen")
        if log_it and conn.dropped > 1:
            self._log_drops(conn, None)
