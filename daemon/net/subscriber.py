"""A subscriber of the service's stream that counts what it received and what it lost.

Every published record carries the run id, a per-topic sequence number and (for sample data)
the sample index range. From them a subscriber proves it lost nothing, or says exactly what it
lost:

* a hole in a topic's sequence numbers is a message lost between service and subscriber (PUB
  drops at the high-water mark, or the subscriber joined late);
* a hole in the raw sample indices that a ``gap`` record announced is a gap of the service
  itself (overrun, bus error, restart) — the service lost it, not the network;
* a hole in the raw indices together with a hole in the raw sequence is samples lost in
  transport; :class:`Message` ``missing`` names their index range so a recorder can write a
  gap record for them.

A change of run id (the service restarted) starts the counting afresh.

On join the subscriber subscribes first and then asks the request socket for a ``snapshot``
(and the ``header``), so a late joiner has the Allan state at once and misses nothing in
between. Requests go through a DEALER socket with a timeout: a dead server costs a timeout,
never a hung client.
"""

from __future__ import annotations

import itertools
import logging
import math
import time
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import zmq
from avard.core.errors import ConfigError, FormatError, NetworkError
from avard.core.io import frames
from avard.daemon.net.curve import CurveClientConfig, apply_client

log = logging.getLogger(__name__)

#: Messages a subscriber buffers before libzmq drops (~15 min of the service's ≤ 100 blocks/s).
DEFAULT_RCVHWM = 100000


def request_endpoint_for(pub_endpoint: str) -> str:
    """The default request endpoint of a service publishing on ``pub_endpoint``: port + 1.

    (The service's defaults are PUB 5556 and request 5557; see docs/wire-format.md.)
    """
    if not pub_endpoint.startswith("tcp://"):
        raise ConfigError(f"cannot guess the request endpoint of {pub_endpoint!r}; "
                          "give it with --request tcp://HOST:PORT")
    host, sep, port = pub_endpoint[len("tcp://"):].rpartition(":")
    if not sep or not port.isdigit():
        raise ConfigError(f"endpoint {pub_endpoint!r} must look like tcp://HOST:PORT")
    return f"tcp://{host}:{int(port) + 1}"


def _ipv6_if_needed(sock: zmq.Socket, endpoint: str) -> None:
    """libzmq only speaks IPv6 when told: needed for tcp://[::1]:PORT and v6 host names."""
    if endpoint.startswith("tcp://["):
        sock.setsockopt(zmq.IPV6, 1)


@dataclass
class TopicStats:
    """Per-topic counts: messages received and messages missing from the sequence."""

    received: int = 0
    lost: int = 0
    first_seq: int | None = None
    last_seq: int | None = None


@dataclass
class Message:
    """One decoded message and what the subscriber learnt from it.

    lost: messages missing on this topic right before this one (sequence hole).
    missing: (i0, n) sample index ranges lost in transport before this raw block (several
        when a gap record arrived between them), in index order; empty when none.
    new_run: this message starts a run the subscriber had not seen (first, or a restart).
    """

    topic: str
    record: dict[str, Any]
    lost: int = 0
    missing: list[tuple[int, int]] = field(default_factory=list)
    new_run: bool = False


@dataclass
class StreamStats:
    """What the subscriber has seen, in sample and message counts (summed over runs)."""

    run: str | None = None
    runs: int = 0
    topics: dict[str, TopicStats] = field(default_factory=dict)
    samples_received: int = 0
    samples_lost: int = 0           # index holes that coincide with lost raw messages
    samples_service_gap: int = 0    # index holes announced by gap records
    samples_unexplained: int = 0    # index holes with neither (should stay 0)
    samples_repeated: int = 0       # raw blocks that went back in index within a run
    first_index: int | None = None
    next_index: int | None = None   # index the next raw block should start at
    bad_messages: int = 0
    first_bad: str | None = None    # what was wrong with the first undecodable message

    def not_avard(self) -> str:
        """'' when every message decoded; else a clause naming how many did not and why the
        first did not, for a client that received nothing usable: "nothing received" was
        wrong then, and sent the user looking for a service that was not running."""
        if not self.bad_messages:
            return ""
        return (f"{self.bad_messages} message{'s' if self.bad_messages != 1 else ''} arrived "
                f"that this avard cannot read (the first {self.first_bad}): is that address "
                "an avard service of this version?")

    @property
    def messages_lost(self) -> int:
        return sum(t.lost for t in self.topics.values())

    @property
    def messages_received(self) -> int:
        return sum(t.received for t in self.topics.values())

    def to_dict(self) -> dict[str, Any]:
        return {
            "run": self.run, "runs": self.runs,
            "messages_received": self.messages_received, "messages_lost": self.messages_lost,
            "samples_received": self.samples_received, "samples_lost": self.samples_lost,
            "samples_service_gap": self.samples_service_gap,
            "samples_unexplained": self.samples_unexplained,
            "samples_repeated": self.samples_repeated, "bad_messages": self.bad_messages,
            "topics": {k: vars(v).copy() for k, v in self.topics.items()},
        }


class LossTracker:
    """Sequence and index continuity bookkeeping, separate from the sockets (testable alone)."""

    def __init__(self) -> None:
        self.stats = StreamStats()
        self._holes: list[tuple[int, int]] = []

    def observe(self, topic: str, record: dict[str, Any]) -> Message:
        st = self.stats
        msg = Message(topic, record)
        run = record["run"]
        if run != st.run:
            # first message, or the service restarted: sequences and indices start afresh
            if st.run is not None:
                log.info("run changed from %s to %s", st.run, run)
            st.run, st.runs = run, st.runs + 1
            for ts in st.topics.values():  # counts stay cumulative over runs
                ts.last_seq = None
            st.next_index = None
            self._holes = []
            msg.new_run = True
        ts = st.topics.setdefault(topic, TopicStats())
        seq = record["seq"]
        if ts.last_seq is None:
            ts.first_seq = seq
        elif seq > ts.last_seq + 1:
            msg.lost = seq - ts.last_seq - 1
            ts.lost += msg.lost
        ts.last_seq = seq
        ts.received += 1
        kind = record["kind"]
        if kind == "raw":
            self._raw(record, msg)
        elif kind == "gap":
            self._gap(record)
        return msg

    def _raw(self, record: dict[str, Any], msg: Message) -> None:
        st = self.stats
        i0, n = record["i0"], record["n"]
        if st.first_index is None:
            st.first_index = i0
        # holes seen at gap records, and the one right before this block
        holes, self._holes = self._holes, []
        if st.next_index is not None:
            if i0 > st.next_index:
                holes.append((st.next_index, i0 - st.next_index))
            elif i0 < st.next_index:
                st.samples_repeated += min(n, st.next_index - i0)
        for start, count in holes:
            # raw blocks travel in index order on one pipe: a hole with a lost raw message is
            # transport loss; a hole without one, the service never announced
            if msg.lost:
                st.samples_lost += count
                msg.missing.append((start, count))
            else:
                st.samples_unexplained += count
                log.warning("samples [%d, %d) missing without a gap record or a lost "
                            "message", start, start + count)
        st.samples_received += n
        st.next_index = max(i0 + n, st.next_index or 0)

    def _gap(self, record: dict[str, Any]) -> None:
        st = self.stats
        i0, n = record["i0"], record["n"]
        if st.next_index is None:
            st.samples_service_gap += n
            st.next_index = i0 + n
            return
        if i0 > st.next_index:
            # samples between the last block and this gap: their raw messages were lost (or
            # never sent); the next raw block's sequence number tells which
            self._holes.append((st.next_index, i0 - st.next_index))
        end = i0 + n
        if end > st.next_index:
            st.samples_service_gap += end - max(i0, st.next_index)  # never count twice
            st.next_index = end

    @property
    def pending_samples(self) -> int:
        """Samples missing before a gap record, not yet attributed (awaiting the next raw)."""
        return sum(c for _, c in self._holes)


class Subscriber:
    """SUB socket (plus a DEALER for requests) that decodes and counts.

    Use as a context manager or call :meth:`connect` / :meth:`close`.
    """

    def __init__(self, endpoint: str, topics: Iterable[str] = frames.TOPICS, *,
                 request_endpoint: str | None = None, curve: CurveClientConfig | None = None,
                 rcvhwm: int = DEFAULT_RCVHWM, max_bytes: int = frames.DEFAULT_MAX_BYTES,
                 request_timeout_s: float = 2.0, sensor: str | None = None) -> None:
        self.endpoint = endpoint
        #: one sensor of a rig's stream (topics ``raw.NAME``...; a one-sensor service's plain
        #: topics pass); None: a rig's first sensor once :meth:`join` asked for the sensors,
        #: or the first sensor whose topic arrives (:meth:`recv`): never a mix of sensors
        self.sensor = sensor
        self.topics = list(topics)
        unknown = set(self.topics) - set(frames.TOPICS)
        if unknown:
            raise ConfigError(f"unknown topic(s) {sorted(unknown)}; topics are "
                              f"{', '.join(frames.TOPICS)}")
        self.request_endpoint = request_endpoint
        self.curve = curve
        self.rcvhwm = rcvhwm
        self.max_bytes = max_bytes
        self.request_timeout_s = request_timeout_s
        self.tracker = LossTracker()
        self.snapshot: dict[str, Any] | None = None
        self.header: dict[str, Any] | None = None
        self._ctx: zmq.Context | None = None
        self._sub: zmq.Socket | None = None
        self._req: zmq.Socket | None = None
        self._ids = itertools.count(1)

    @property
    def stats(self) -> StreamStats:
        return self.tracker.stats

    # ---- sockets --------------------------------------------------------------------------

    def connect(self, *, join: bool = True) -> Subscriber:
        """Subscribe, connect, and (``join``) ask the request socket for snapshot and header."""
        self._ctx = zmq.Context()
        sub = self._ctx.socket(zmq.SUB)
        self._sub = sub
        sub.setsockopt(zmq.LINGER, 0)
        sub.setsockopt(zmq.RCVHWM, self.rcvhwm)
        # a hostile or broken server cannot make us buffer an oversized message
        sub.setsockopt(zmq.MAXMSGSIZE, self.max_bytes + 1024)
        if self.curve is not None:
            apply_client(sub, self.curve)
        for t in self.topics:
            sub.setsockopt(zmq.SUBSCRIBE, t.encode("ascii"))
        try:
            _ipv6_if_needed(sub, self.endpoint)
            sub.connect(self.endpoint)
        except zmq.ZMQError as exc:
            self.close()
            raise ConfigError(f"cannot connect to {self.endpoint}: {exc.strerror}") from None
        if join and self.request_endpoint:
            self.join()
        return self

    def sensors(self) -> list[str]:
        """The sensors the service publishes (the ``sensors`` op; a service that does not know
        the op has one, named in its header)."""
        try:
            return [str(n) for n in self.request("sensors", {})["sensors"]]
        except NetworkError as exc:
            if "unknown op" not in str(exc):
                raise
        name = (self.request("header", {}).get("sensor") or {}).get("name")
        return [str(name)] if name else []

    def pick_sensor(self) -> None:
        """Check ``sensor`` against the service's sensors (ConfigError, one line naming them);
        without one, a rig's first sensor (said in the log): a rig's sensors each have their
        own sample index, so one stream is one sensor's."""
        names = self.sensors()
        if self.sensor is None:
            if len(names) > 1:
                self.sensor = names[0]
                log.warning("the service has %d sensors (%s): following %s; pick one with "
                            "--sensor NAME", len(names), ", ".join(names), names[0])
            return
        if self.sensor not in names:
            raise ConfigError(f"--sensor {self.sensor}: the service at {self.endpoint} has no "
                              f"such sensor; its sensors are {', '.join(names) or 'unnamed'}")

    def join(self) -> None:
        """Fetch the latest Allan snapshot and the run header; a failure is logged, not fatal.
        A sensor named that the service does not have is refused (ConfigError)."""
        try:
            self.pick_sensor()
        except NetworkError as exc:
            log.warning("no sensors on join: %s", exc)
        for op in ("snapshot", "header"):
            try:
                result = self.request(op)
            except NetworkError as exc:
                log.warning("no %s on join: %s", op, exc)
                if self._req is None:
                    break  # timed out: the next op would only wait as long again
                continue
            if op == "snapshot":
                self.snapshot = result
            else:
                self.header = result

    def _request_socket(self) -> zmq.Socket:
        if self._req is None:
            if self._ctx is None:
                self._ctx = zmq.Context()
            if not self.request_endpoint:
                raise ConfigError("no request endpoint configured for this subscriber")
            req = self._ctx.socket(zmq.DEALER)
            req.setsockopt(zmq.LINGER, 0)
            req.setsockopt(zmq.MAXMSGSIZE, self.max_bytes + 1024)
            if self.curve is not None:
                apply_client(req, self.curve)
            _ipv6_if_needed(req, self.request_endpoint)
            req.connect(self.request_endpoint)
            self._req = req
        return self._req

    def request(self, op: str, args: dict[str, Any] | None = None, *,
                timeout_s: float | None = None) -> dict[str, Any]:
        """Ask the request socket; return the result map or raise NetworkError.

        The DEALER socket talks like REQ (empty delimiter frame) but a lost reply only costs
        the timeout: the socket is rebuilt afterwards so a late reply cannot be mistaken for
        the next one (ids are checked as well).
        """
        timeout = self.request_timeout_s if timeout_s is None else timeout_s
        if self.sensor is not None and op != "sensors":
            args = {"sensor": self.sensor, **(args or {})}   # a rig routes ops by sensor
        sock = self._request_socket()
        rid = next(self._ids)
        sock.send_multipart([b"", frames.encode_request(op, args, id=rid)])
        deadline = time.monotonic() + timeout
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0 or not sock.poll(int(remaining * 1000) + 1):
                self._req = None
                sock.close(linger=0)
                raise NetworkError(f"no reply to {op!r} from {self.request_endpoint} within "
                                   f"{timeout:g} s; is `avard run` up (and the CURVE key "
                                   "authorised)?")
            parts = sock.recv_multipart()
            try:
                reply = frames.decode_reply(parts[-1], max_bytes=self.max_bytes)
            except FormatError as exc:
                raise NetworkError(f"bad reply to {op!r}: {exc}") from None
            if reply.get("id") != rid:
                continue  # a late answer to an earlier, timed-out request
            if not reply["ok"]:
                raise NetworkError(f"{op!r} refused by {self.request_endpoint}: "
                                   f"{reply['error']}")
            return frames.unpack_arrays(reply["result"], max_bytes=self.max_bytes)

    def recv(self, timeout_s: float | None = None) -> Message | None:
        """The next decoded message, or None after ``timeout_s`` (None: wait forever).

        Undecodable messages are counted in ``stats.bad_messages`` and skipped.
        """
        if self._sub is None:
            raise ConfigError("subscriber not connected; call connect() first")
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while True:
            if deadline is not None:
                remaining = deadline - time.monotonic()
                if remaining <= 0 or not self._sub.poll(int(remaining * 1000) + 1):
                    return None
            parts = self._sub.recv_multipart()
            if len(parts) != 2:
                self._bad(f"{parts[0][:40]!r}", f"a message of {len(parts)} parts, not 2")
                continue
            topic = parts[0].decode("ascii", "replace")
            _base, dot, name = topic.partition(".")
            if dot and self.sensor is None:
                # a rig's stream before any sensor was chosen (its request socket was not up):
                # one stream is one sensor's index, so follow the first one seen, never a mix
                self.sensor = name
                log.warning("the stream is a rig's (topic %s) and no sensor was picked: "
                            "following %s; pick one with --sensor NAME", topic, name)
            if dot and name != self.sensor:
                continue          # another sensor of the rig: its own stream, not counted
            try:
                record = frames.decode(parts[1], max_bytes=self.max_bytes)
            except FormatError as exc:
                self._bad(repr(topic), str(exc))
                continue
            return self.tracker.observe(topic, record)

    def _bad(self, topic: str, why: str) -> None:
        """Count an undecodable message; log the first, then only at 10, 100, 1000, … of
        them (a stream of junk logged a line per message, thousands a second)."""
        st = self.stats
        st.bad_messages += 1
        if st.first_bad is None:
            st.first_bad = f"on {topic}: {why}"
            log.warning("undecodable message on %s: %s (further ones are counted)", topic, why)
        elif math.log10(st.bad_messages).is_integer():
            log.warning("%d undecodable messages so far (the last on %s: %s)",
                        st.bad_messages, topic, why)

    def close(self) -> None:
        for sock in (self._sub, self._req):
            if sock is not None:
                sock.close(linger=0)
        self._sub = self._req = None
        if self._ctx is not None:
            self._ctx.term()
            self._ctx = None

    def __enter__(self) -> Subscriber:
        if self._sub is None:
            self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


# ---- command-line plumbing shared by `avard watch` and `avard record` ------------------------


def add_client_arguments(parser: Any) -> None:
    """ENDPOINT, --request, --server-key, --client-key, --timeout (argparse)."""
    parser.add_argument("endpoint", metavar="ENDPOINT",
                        help="the service's PUB endpoint, e.g. tcp://raspberrypi.local:5555")
    parser.add_argument("--request", metavar="ENDPOINT", default=None,
                        help="the service's request endpoint (default: PUB port + 1)")
    parser.add_argument("--server-key", metavar="FILE", default=None,
                        help="the service's public CURVE key (SERVER.key) when CURVE is on")
    parser.add_argument("--client-key", metavar="FILE", default=None,
                        help="this client's secret CURVE key file (NAME.key_secret)")
    parser.add_argument("--timeout", type=float, default=2.0, metavar="S",
                        help="seconds to wait for a request reply (default 2)")
    parser.add_argument("--sensor", metavar="NAME", default=None,
                        help="one sensor of a rig (several [[sensor]] entries; default its "
                             "first); refused, naming the sensors, when it has no such one")


def check_client_endpoint(endpoint: str, what: str = "ENDPOINT") -> None:
    """ConfigError (one line) for an endpoint a client cannot reach whatever runs there: a
    port outside 1–65535, or a host name that does not resolve (said as such, not as a
    service that is not running)."""
    import socket

    if not endpoint.startswith("tcp://"):
        return
    host, sep, port = endpoint[len("tcp://"):].rpartition(":")
    if not sep or not host:
        raise ConfigError(f"{what} {endpoint!r}: write tcp://HOST:PORT, e.g. "
                          "tcp://raspberrypi.local:5555")
    if not port.isdigit() or not 1 <= int(port) <= 65535:
        raise ConfigError(f"{what} {endpoint!r}: port {port} is not a TCP port (1–65535)")
    name = host[1:-1] if host.startswith("[") and host.endswith("]") else host
    try:
        socket.getaddrinfo(name, int(port), type=socket.SOCK_STREAM)
    except (socket.gaierror, UnicodeError) as exc:
        raise ConfigError(f"{what} {endpoint!r}: the host name {name!r} does not resolve "
                          f"({getattr(exc, 'strerror', None) or exc}); check its spelling, "
                          "or give the Pi's IP address") from None


def subscriber_from_args(args: Any, topics: Iterable[str] = frames.TOPICS) -> Subscriber:
    """A (not yet connected) Subscriber from the arguments of :func:`add_client_arguments`."""
    from pathlib import Path

    check_client_endpoint(args.endpoint)
    timeout = getattr(args, "timeout", None)
    if timeout is not None and not (math.isfinite(timeout) and timeout > 0):
        raise ConfigError(f"--timeout {timeout:g}: give a number of seconds above 0")
    if args.request is not None:
        check_client_endpoint(args.request, "--request")
    if (args.server_key is None) != (args.client_key is None):
        raise ConfigError("CURVE needs both --server-key (the service's NAME.key) and "
                          "--client-key (your NAME.key_secret), or neither")
    curve = None
    if args.server_key is not None:
        curve = CurveClientConfig(Path(args.server_key), Path(args.client_key))
    request = args.request
    if request is None and args.endpoint.startswith("tcp://"):
        request = request_endpoint_for(args.endpoint)
    return Subscriber(args.endpoint, topics, request_endpoint=request, curve=curve,
                      request_timeout_s=args.timeout, sensor=getattr(args, "sensor", None))


def check_stream_sensor(sub: Subscriber) -> None:
    """Before a command starts: ``sub.sensor`` checked against the service's sensors (a rig's
    first when none is named), ConfigError for an unknown one; a service not answering now is
    only logged (the command's own wait then says what is wrong)."""
    if not sub.request_endpoint:
        return
    try:
        sub.pick_sensor()
    except NetworkError as exc:
        log.warning("could not ask for the service's sensors: %s", exc)
