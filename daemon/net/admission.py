"""A cap on the TCP connections one ZeroMQ socket holds, so peers cannot fill the fd table.

libzmq accepts every connection a listening socket is offered, and each one costs a file
descriptor and buffers: 1 010 idle local connections filled the default table of 1 024, and
the recorder could no longer open a segment nor write a checkpoint. libzmq has no per-socket
connection limit (and ``unbind`` drops every connection the endpoint accepted), so
:class:`ConnectionGate` keeps one from the socket's monitor events, which carry each
connection's fd: ACCEPTED adds it, DISCONNECTED removes it, and past ``cap`` one connection is
shut down (``shutdown(2)`` on libzmq's fd, never ``close``: libzmq sees the peer leave and
closes it itself, so no fd number is ever freed under it). Which one (fair admission):

* a request socket evicts the connection that never sent a valid request and came first
  (junk and idle peers), else the one whose last valid request is oldest: a flood of junk
  connections cannot keep a client that asks out, it only pushes out other junk;
* the PUB socket refuses the newcomer (subscribers that are already there keep their data).

A connection that never completes the ZMTP greeting (a raw TCP peer, a port scanner) is also
closed by libzmq after ``HANDSHAKE_IVL_MS``.

The fd budget: the caps of the request and PUB sockets together, plus :data:`RESERVED_FDS`
for the recording, the checkpoints, sd_notify and libzmq's own pipes, must fit under the soft
RLIMIT_NOFILE (the unit sets LimitNOFILE); :func:`fd_budget` scales the caps down, with a
warning, where the limit is lower.
"""

from __future__ import annotations

import fcntl
import itertools
import logging
import resource
import socket
import struct
import termios
import time

import zmq
from zmq.utils.monitor import parse_monitor_message

log = logging.getLogger(__name__)

#: Descriptors kept for everything that is not a network peer: segments, the checkpoint and
#: its temporary file, the state directory, sd_notify, DS18B20 sysfs files, libzmq's
#: internal pipes (two contexts), Python's own. Generous: running out here loses data.
RESERVED_FDS = 256
#: Connections a request socket holds at most (each peer's queues are bounded too).
MAX_REQUEST_CONNECTIONS = 64
#: Connections the PUB socket holds at most (each subscriber's queue is bounded by the HWM).
MAX_SUBSCRIBERS = 256
#: Behind the publisher's subscription guard (daemon/net/front.py) a subscriber costs three
#: descriptors (its TCP connection, both ends of the relay): the cap keeps the PUB side's
#: descriptors where they were with MAX_SUBSCRIBERS direct connections.
MAX_GUARDED_SUBSCRIBERS = MAX_SUBSCRIBERS // 3
#: A TCP connection that has not completed the ZMTP greeting (and CURVE) in this time is
#: closed by libzmq (its default is 30 s).
HANDSHAKE_IVL_MS = 5000


def fd_budget(wanted: int, *, what: str, others: int = 0,
              soft_limit: int | None = None, fds_each: int = 1) -> int:
    """The connection cap to use for ``wanted``: at most what fits beside ``others`` peers and
    RESERVED_FDS under the soft RLIMIT_NOFILE (at least 1), each connection costing
    ``fds_each`` descriptors (3 for a subscriber relayed by the publisher's guard)."""
    if soft_limit is None:
        soft_limit = resource.getrlimit(resource.RLIMIT_NOFILE)[0]
    if soft_limit == resource.RLIM_INFINITY:
        return wanted
    room = soft_limit - RESERVED_FDS - others
    if room >= wanted * fds_each:
        return wanted
    cap = max(1, room // fds_each)
    log.warning("%s: at most %d connections (not %d): the open-file limit is %d and %d fds "
                "are kept for the recording; raise LimitNOFILE (ulimit -n)", what, cap, wanted,
                soft_limit, RESERVED_FDS)
    return cap


class ConnectionGate:
    """Counts one bound socket's connections from its monitor and keeps them ≤ ``cap``.

    Call :meth:`poll` from the thread that owns the socket (ZeroMQ sockets are not
    thread-safe) whenever the monitor socket is readable, or periodically; a request server
    calls :meth:`note_request` with a valid request's source fd (``zmq.SRCFD``)."""

    def __init__(self, sock: zmq.Socket, cap: int, what: str, *, evict_newest: bool,
                 extra_events: int = 0) -> None:
        self.sock = sock
        self.cap = max(1, int(cap))
        self.what = what
        self.evict_newest = evict_newest
        self.port: int | None = None
        self.path: str | None = None   # an ipc endpoint's socket file
        self._order = itertools.count()
        # fd → (accept order, monotonic time of its last valid request or None)
        self._fds: dict[int, tuple[int, float | None]] = {}
        self.accepted = 0
        self.evicted = 0
        self.stalled_evicted = 0
        # fd → monotonic time since which its kernel send queue has stayed full
        self._full_since: dict[int, float] = {}
        self.max_outq = 0          # the most bytes seen waiting in one peer's send queue
        sock.setsockopt(zmq.HANDSHAKE_IVL, HANDSHAKE_IVL_MS)
        self.monitor = sock.get_monitor_socket(
            zmq.EVENT_ACCEPTED | zmq.EVENT_DISCONNECTED | extra_events)

    @property
    def connections(self) -> int:
        return len(self._fds)

    def bound(self, endpoint: str) -> None:
        """The concrete endpoint the socket listens on (its port identifies our fds)."""
        if endpoint.startswith("ipc://"):
            self.path = endpoint[len("ipc://"):]
            return
        _host, _sep, port = endpoint.rpartition(":")
        self.port = int(port) if port.isdigit() else None

    def note_request(self, fd: int | None) -> None:
        if fd is not None and fd in self._fds:
            self._fds[fd] = (self._fds[fd][0], time.monotonic())

    def poll(self) -> list[int]:
        """Read every pending monitor event; returns the events other than ACCEPTED and
        DISCONNECTED (for the caller's own counters)."""
        other: list[int] = []
        while self.monitor.poll(0):
            try:
                event = parse_monitor_message(self.monitor.recv_multipart(zmq.NOBLOCK))
            except (zmq.Again, ValueError):
                break
            ev, fd = event["event"], int(event["value"])
            if ev == zmq.EVENT_ACCEPTED:
                self.accepted += 1
                self._fds[fd] = (next(self._order), None)
                if len(self._fds) > self.cap:
                    self._evict(fd)
            elif ev == zmq.EVENT_DISCONNECTED:
                self._fds.pop(fd, None)
                self._full_since.pop(fd, None)
            else:
                other.append(ev)
        return other

    def _victim(self, newest: int) -> int:
        if self.evict_newest:
            return newest
        return min(self._fds, key=lambda f: (self._fds[f][1] is not None,
                                             self._fds[f][1] or 0.0, self._fds[f][0]))

    def shed_stalled(self, now: float, full_bytes: int, stall_s: float) -> int:
        """Shut down every connection whose kernel send queue (SIOCOUTQ: bytes not yet
        acknowledged by the peer) has held at least ``full_bytes`` for ``stall_s`` seconds:
        a peer that stopped reading. Its libzmq queue, which grows behind the full kernel
        buffer up to the high-water mark, is freed with it; a subscriber reconnects by itself
        and sees what it missed in the sequence numbers. Returns how many were shut down."""
        shed = 0
        for fd in list(self._fds):
            buf = bytearray(4)
            try:
                fcntl.ioctl(fd, termios.TIOCOUTQ, buf)   # SIOCOUTQ on a TCP socket
            except OSError:
                self._full_since.pop(fd, None)
                continue
            outq = struct.unpack("i", buf)[0]
            self.max_outq = max(self.max_outq, outq)
            if outq < full_bytes:
                self._full_since.pop(fd, None)
                continue
            since = self._full_since.setdefault(fd, now)
            if now - since >= stall_s:
                del self._fds[fd]
                self._full_since.pop(fd, None)
                self.stalled_evicted += 1
                shed += 1
                self._shutdown(fd)
                (log.warning if self.stalled_evicted <= 10 or self.stalled_evicted % 1000 == 0
                 else log.debug)(
                    "%s: a peer read nothing for %.0f s (%d bytes waiting in its send queue): "
                    "shut down (#%d), its queue freed", self.what, stall_s, outq,
                    self.stalled_evicted)
        return shed

    def _shutdown(self, fd: int) -> None:
        try:
            s = socket.socket(fileno=fd)
        except OSError:
            return      # already closed by libzmq
        try:
            # only ever a connection of our own endpoint (the fd could have been reused)
            name = s.getsockname()
            if self.path is not None:
                if isinstance(name, bytes) and name[:1] == b"\0":   # abstract: "@name"
                    name = "@" + name[1:].decode("utf-8", "replace")
                ours = s.family == socket.AF_UNIX and name == self.path
            else:
                ours = self.port is None or name[1] == self.port
            if ours:
                s.shutdown(socket.SHUT_RDWR)
        except (OSError, IndexError, TypeError):
            pass
        finally:
            s.detach()   # libzmq owns the fd: never close it here

    def _evict(self, newest: int) -> None:
        fd = self._victim(newest)
        del self._fds[fd]   # its DISCONNECTED event follows; counted gone from now
        self._full_since.pop(fd, None)
        self.evicted += 1
        self._shutdown(fd)
        (log.warning if self.evicted <= 10 or self.evicted % 1000 == 0 else log.debug)(
            "%s: %d connections (the cap): one %s was shut down (#%d)", self.what,
            self.cap, "newcomer" if fd == newest else "idle peer", self.evicted)

    def close(self) -> None:
        try:
            self.sock.disable_monitor()
        except zmq.ZMQError:
            pass
        self.monitor.close(linger=0)
