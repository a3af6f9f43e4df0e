"""The sample ring: independent consumers, no blocking writer, loss reported exactly."""

from __future__ import annotations

import threading

import numpy as np
import pytest
from avard.daemon.service.ring import Consumer, Ring


def _block(i0: int, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    idx = np.arange(i0, i0 + n, dtype=np.int64)
    counts = np.stack([idx, -idx, 2 * idx], axis=1).astype(np.int32)
    return counts, idx, idx / 125.0


def test_two_consumers_see_every_sample_once_in_order() -> None:
    ring = Ring(64)
    a, b = ring.consumer("a"), ring.consumer("b")
    seen_a: list[np.ndarray] = []
    for i0 in range(0, 200, 10):
        ring.push(*_block(i0, 10))
        seen_a.append(a.read().index)
        if i0 % 30 == 0:
            chunk = b.read()
            assert chunk.lost_samples == 0
    np.testing.assert_array_equal(np.concatenate(seen_a), np.arange(200))
    assert a.lost_total == 0


def test_slow_consumer_loses_oldest_and_is_told_which() -> None:
    ring = Ring(50)
    c = ring.consumer("slow")
    first = c.read()
    assert first.n == 0
    ring.push(*_block(0, 30))
    got = c.read()
    np.testing.assert_array_equal(got.index, np.arange(30))
    for i0 in range(30, 130, 20):
        ring.push(*_block(i0, 20))
    chunk = c.read()
    # 100 pushed since the last read, only 50 held: 50 lost, and the run of indices is named.
    assert chunk.lost_samples == 50
    assert chunk.lost_index == (30, 80)
    np.testing.assert_array_equal(chunk.index, np.arange(80, 130))
    np.testing.assert_array_equal(chunk.counts[:, 1], -np.arange(80, 130))


def test_wraparound_preserves_data_and_times() -> None:
    ring = Ring(7)
    c = ring.consumer("c")
    out = []
    for i0 in range(0, 40, 5):
        ring.push(*_block(i0, 5))
        out.append(c.read())
    idx = np.concatenate([o.index for o in out])
    np.testing.assert_array_equal(idx, np.arange(40))
    np.testing.assert_allclose(np.concatenate([o.t_mono for o in out]), np.arange(40) / 125.0)


def test_marks_arrive_between_the_right_samples() -> None:
    ring = Ring(100)
    c = ring.consumer("c")
    ring.push(*_block(0, 10))
    ring.mark({"type": "temp", "v": 1})
    ring.push(*_block(10, 5))
    ring.mark({"type": "temp", "v": 2})
    chunk = c.read(max_samples=12)
    assert [(p, m["v"]) for p, m in chunk.marks] == [(10, 1)]
    chunk2 = c.read()
    assert chunk2.pos0 == 12
    assert [(p, m["v"]) for p, m in chunk2.marks] == [(15, 2)]


def test_block_larger_than_ring_keeps_newest() -> None:
    ring = Ring(8)
    c = ring.consumer("c")
    ring.push(*_block(0, 20))
    chunk = c.read()
    np.testing.assert_array_equal(chunk.index, np.arange(12, 20))
    assert chunk.lost_samples == 12


def test_recent_returns_newest_without_cursor() -> None:
    ring = Ring(10)
    ring.push(*_block(0, 25))
    np.testing.assert_array_equal(ring.recent(4).index, np.arange(21, 25))
    assert ring.recent(100).n == 10


def test_concurrent_writer_and_reader_lose_nothing_when_reader_keeps_up() -> None:
    ring = Ring(100_000)
    c = ring.consumer("c")
    total = 50_000
    done = threading.Event()

    def writer() -> None:
        for i0 in range(0, total, 37):
            ring.push(*_block(i0, min(37, total - i0)))
        done.set()

    t = threading.Thread(target=writer)
    t.start()
    parts = []
    while not done.is_set() or c.backlog:
        parts.append(c.read().index)
    t.join()
    np.testing.assert_array_equal(np.concatenate(parts), np.arange(total))


def test_capacity_must_be_positive() -> None:
    with pytest.raises(ValueError):
        Ring(0)


class _CountingCondition(threading.Condition):
    def __init__(self, lock: threading.Lock) -> None:
        super().__init__(lock)
        self.notified = 0

    def notify(self, n: int = 1) -> None:
        self.notified += 1
        super().notify(n)


def _wait_in_thread(c: Consumer, min_samples: int) -> tuple[threading.Thread, list[bool]]:
    woke: list[bool] = []
    t = threading.Thread(target=lambda: woke.append(c.wait(60.0, min_samples)), daemon=True)
    t.start()
    for _ in range(10_000):              # until the thread is blocked in the wait
        if c._wake_at is not None:
            break
        t.join(0.001)
    assert c._wake_at is not None
    return t, woke


def test_a_batching_consumer_is_woken_once_per_batch_not_per_push_or_mark() -> None:
    """#26 item 9: every push and mark woke every stage thread (notify_all), three wake-ups
    per drain at 125 Hz for stages that then went back to sleep. A consumer waiting for a
    batch is now notified once, when its batch is in the ring; marks wait for the batch."""
    ring = Ring(1000)
    c = ring.consumer("batching")
    other = ring.consumer("single")
    c._cond = cond = _CountingCondition(ring._lock)
    t, woke = _wait_in_thread(c, 32)
    ring.push(*_block(0, 16))                     # a drain: half the batch
    ring.mark({"kind": "temp"})                   # a temperature reading
    assert cond.notified == 0 and t.is_alive()
    ring.push(*_block(16, 16))                    # the batch is there: one notify
    t.join(10)
    assert cond.notified == 1 and woke == [True]
    chunk = c.read()
    assert chunk.n == 32 and len(chunk.marks) == 1 and chunk.marks[0][0] == 16
    # a consumer of single samples is woken by a mark (the publisher's events go out at once)
    other.read()
    other._cond = cond1 = _CountingCondition(ring._lock)
    t, woke = _wait_in_thread(other, 1)
    ring.mark({"kind": "event"})
    t.join(10)
    assert cond1.notified == 1 and woke == [True] and other.read().marks


def test_a_stop_between_the_stop_check_and_the_wait_is_not_missed() -> None:
    ring = Ring(100)
    c = ring.consumer("c")
    since = ring.wakes
    ring.wake()                                   # stop() ran after the stage looked
    assert c.wait(60.0, 32, since=since) is True  # returns at once instead of idling


def test_split_chunk_breaks_runs_where_the_index_jumps_and_at_marks() -> None:
    from avard.daemon.service.stage import split_chunk

    ring = Ring(100)
    c = ring.consumer("c")
    ring.push(*_block(0, 10))
    ring.mark({"kind": "temp"})
    ring.push(*_block(10, 5))
    ring.push(*_block(20, 5))                 # an overrun gap: 15..19 missing
    items = split_chunk(c.read())
    assert [(k, v) if k == "samples" else (k, v["kind"]) for k, v in items] == [
        ("samples", (0, 10)), ("mark", "temp"), ("samples", (10, 15)), ("samples", (15, 20))]
