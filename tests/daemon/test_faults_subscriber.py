"""A stalled subscriber beside a healthy one, on a service with a small PUB high-water mark.

The service is unaffected (nothing in the ring is lost to the publisher, the recording is
complete, the healthy subscriber gets every message), the stalled subscriber's queue is bounded
by the high-water marks instead of growing with the run, and when it finally reads it sees
exactly what it lost through the sequence numbers, never an unexplained hole.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import zmq
from avard.core.io import frames
from avard.daemon.net.handshake import HELLO, is_hello
from avard.daemon.net.publisher import Publisher
from avard.daemon.net.subscriber import LossTracker

from .test_faults_bus import Listener, run_rig

PUB_HWM = 50
SUB_HWM = 20


class StalledSubscriber:
    """A SUB socket that connects and reads nothing until told to; tiny kernel receive buffer
    (SO_RCVBUF), so the high-water marks, not the kernel, decide how much waits for it."""

    def __init__(self, endpoint: str) -> None:
        self.ctx = zmq.Context()
        self.sock = self.ctx.socket(zmq.SUB)
        self.sock.setsockopt(zmq.RCVHWM, SUB_HWM)
        self.sock.setsockopt(zmq.RCVBUF, 4096)
        self.sock.setsockopt(zmq.LINGER, 0)
        self.sock.setsockopt(zmq.SUBSCRIBE, b"")
        self.sock.connect(endpoint)
        self.tracker = LossTracker()
        self.received: list[Any] = []

    def read_available(self) -> None:
        """Read what waits, until nothing more comes for half a second."""
        while self.sock.poll(500):
            topic, data = self.sock.recv_multipart()
            self.received.append(self.tracker.observe(topic.decode(), frames.decode(data)))

    def read_everything(self) -> None:
        self.read_available()
        self.sock.close()
        self.ctx.term()


class TwoSubscribers(Listener):
    """The usual reading subscriber plus one that connects and does not read until the end."""

    def __init__(self, svc: Any) -> None:
        self.stalled = StalledSubscriber(svc.publisher.endpoint)
        super().__init__(svc)
        deadline = time.monotonic() + 5
        while svc.publisher.stats()["peers"] < 2 and time.monotonic() < deadline:
            time.sleep(0.01)

    def finish(self) -> None:
        super().finish()
        self.stalled.read_everything()


def test_stalled_subscriber_costs_the_service_nothing_and_sees_its_loss(tmp_path):
    # speed 20: a healthy subscriber keeps up (at full simulation speed bursts of messages
    # exceed so small a high-water mark even for a reader that never stalls)
    rig = run_rig(tmp_path, 60.0, listener_factory=TwoSubscribers, speed=20.0,
                  **{"publish.hwm": PUB_HWM})
    svc, lst = rig.svc, rig.listener
    # The service: the publisher kept up with the ring, nothing dropped anywhere upstream.
    assert svc.final_status["consumers_lost"] == {"allan": 0, "recorder": 0, "publisher": 0}
    # The healthy subscriber got everything, in order.
    st = lst.sub.stats
    assert st.messages_lost == 0 and st.samples_unexplained == 0 and st.samples_repeated == 0
    assert st.samples_received == svc.final_status["samples"]
    # The recording is complete too.
    rec_n = sum(r["n"] for r in rig.kinds("raw"))
    assert rec_n == svc.final_status["samples"]
    # The stalled subscriber, once it reads, accounts for every message: received or lost,
    # nothing unexplained (whether it lost any depends on the kernel's socket buffers; the
    # test below fills them).
    sst = lst.stalled.tracker.stats
    # what the publisher sent (its own counter): the healthy subscriber stops listening after
    # a short quiet period and may miss the very last message under load
    published = svc.final_status["published"]
    assert published >= sum(t.received for t in st.topics.values())
    assert 0 < sst.messages_received + sst.messages_lost <= published
    assert sst.samples_unexplained == 0 and sst.samples_repeated == 0


def _rss_bytes() -> int:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
    raise AssertionError("no VmRSS in /proc/self/status")


def test_publisher_memory_is_bounded_by_the_hwm_for_a_stalled_peer():
    # 1000 raw blocks of 1000 samples (12 kB each, 12 MB in all) to a peer that reads nothing:
    # without a high-water mark libzmq would queue all of it in this process.
    block = np.arange(3000, dtype=np.int32).reshape(1000, 3)
    with Publisher("tcp://127.0.0.1:0", "run-x", hwm=PUB_HWM) as pub:
        stalled = StalledSubscriber(pub.endpoint)
        deadline = time.monotonic() + 5
        while pub.stats()["peers"] < 1 and time.monotonic() < deadline:
            time.sleep(0.01)
        time.sleep(0.2)
        for i in range(20):  # warm-up: allocator and socket buffers reach their size
            pub.publish("raw", frames.raw_record("run-x", 0, 1000 * i, block, 0.0, 0.0))
        rss0 = _rss_bytes()
        n = 1000
        for i in range(20, 20 + n):
            pub.publish("raw", frames.raw_record("run-x", 0, 1000 * i, block, 0.0, 0.0))
        growth = _rss_bytes() - rss0
        stalled.read_available()            # what the high-water marks kept for it
        # one block more once it reads again: what was dropped at the marks is then a hole
        # before it, whatever the timing (without it, a peer whose queue took the first
        # blocks and dropped every later one saw its whole loss as a tail)
        pub.publish("raw", frames.raw_record("run-x", 0, 1000 * (20 + n), block, 0.0, 0.0))
        stalled.read_everything()
    assert growth < 6 * 2**20, f"RSS grew by {growth / 2**20:.1f} MB for a stalled peer"
    st = stalled.tracker.stats
    # It lost most of them and knows how many from the sequence numbers: holes between what
    # it received, plus the tail it can count against the publisher's last sequence number.
    raw = st.topics["raw"]
    assert raw.first_seq == 0 and raw.received + raw.lost == raw.last_seq + 1
    tail = pub.next_seq("raw") - 1 - raw.last_seq
    assert raw.received + raw.lost + tail == 20 + n + 1
    assert raw.lost + tail > n / 2 and raw.lost > 0
    # Holes in the sample index coincide with lost messages: none unexplained.
    assert st.samples_unexplained == 0
    # (a hole is seen between two received blocks: whole blocks of 1000, never more than lost)
    assert 0 < st.samples_lost <= st.messages_lost * 1000 and st.samples_lost % 1000 == 0


def test_stalled_subscribers_are_shut_down_by_bytes_waiting_not_by_message_count():
    """#26 (item 8's growth): with a high-water mark in messages, each stalled subscriber held
    up to `hwm` messages (10 000 by default: minutes of the stream, 80 MB for 50 of them at
    4 kHz). A subscriber whose kernel send queue stays at least half full for `stall_s` is
    now shut down, whatever the HWM: three stalled peers beside a reading one, a HWM of
    100 000 messages that would never drop, and the stalled ones are cut while the reader
    gets every message."""
    import threading

    block = np.arange(3000, dtype=np.int32).reshape(1000, 3)     # 12 kB raw blocks
    sndbuf = 32 << 10
    with Publisher("tcp://127.0.0.1:0", "run-s", hwm=100_000, sndbuf=sndbuf,
                   stall_s=0.3) as pub:
        stalled = [StalledSubscriber(pub.endpoint) for _ in range(3)]
        ctx = zmq.Context()
        reader = ctx.socket(zmq.SUB)
        reader.setsockopt(zmq.SUBSCRIBE, b"")
        reader.setsockopt(zmq.RCVHWM, 0)
        reader.connect(pub.endpoint)
        tracker = LossTracker()
        done, joined = threading.Event(), threading.Event()

        def read() -> None:
            while not done.is_set() or reader.poll(500):
                if reader.poll(50):
                    topic, data = reader.recv_multipart()
                    record = frames.decode(data)
                    if is_hello(record):  # subscribed: every message from here on
                        joined.set()
                        continue
                    tracker.observe(topic.decode(), record)

        th = threading.Thread(target=read, daemon=True)
        th.start()
        for _ in range(500):
            if pub.stats()["peers"] >= 4:
                break
            time.sleep(0.01)
        assert pub.stats()["peers"] == 4
        # the reader's subscription reaches the publisher some time after its connection
        # (ZeroMQ's slow joiner): hello events until it has one (daemon/net/handshake.py)
        for _ in range(2400):  # a bound on a broken set-up only
            pub.publish("event", frames.event_record("", 0, HELLO, 0.0, 0.0))
            if joined.wait(0.05):
                break
        assert joined.is_set()
        sent = 0
        for i in range(20_000):     # a bound on the loop only: it ends at the third cut
            pub.publish("raw", frames.raw_record("run-s", 0, 1000 * i, block, 0.0, 0.0))
            sent += 1
            if pub.stats()["stalled_shut_down"] >= 3:
                break
            time.sleep(0.002)
        st = pub.stats()
        done.set()
        th.join(30)
        reader.close(linger=0)
        ctx.term()
        for s in stalled:
            s.sock.close(linger=0)
            s.ctx.term()
    assert st["stalled_shut_down"] >= 3
    # the kernel's share per peer stays at the buffer set (Linux books twice SO_SNDBUF)
    assert st["max_send_queue_bytes"] <= 2 * sndbuf + 4096
    # the reading subscriber was never cut: every message, in order, none lost
    raw = tracker.stats.topics["raw"]
    assert raw.received == sent and raw.lost == 0
