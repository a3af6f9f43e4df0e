"""Reusable per-thread work arrays for the Allan kernels.

Why: a fresh numpy array larger than glibc's mmap threshold (128 KiB by default) is mapped
from the kernel and zero-filled page by page on first touch; for the streaming accumulator
that page-fault cost was five times the arithmetic itself (measured: 3.2 ms instead of 0.6 ms
per 65536 × 4 block). Kernels therefore write into buffers that live as long as the thread
and only grow. Buffers above ``MAX_CACHED_BYTES`` are not kept, so a one-off batch run on a
long record does not pin its working memory.
"""

from __future__ import annotations

import math
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np
from numpy.typing import NDArray

__all__ = ["MAX_CACHED_BYTES", "histories_passed_on", "mapped_zeros", "reuse_histories",
           "scratch"]

MAX_CACHED_BYTES = 16 << 20
_local = threading.local()


def scratch(key: str, rows: int, cols: int, dtype: np.dtype | type) -> NDArray:
    """A (rows, cols) array of ``dtype`` with undefined contents, reused per (thread, key).

    The caller must not keep it beyond its next request of the same key (copy what it keeps).
    """
    dt = np.dtype(dtype)
    rows = max(0, rows)
    need = rows * cols * dt.itemsize
    if need > MAX_CACHED_BYTES:
        return np.empty((rows, cols), dtype=dt)
    pool: dict = getattr(_local, "pool", None) or {}
    _local.pool = pool
    buf = pool.get((key, dt.str))
    if buf is None or buf.size < rows * cols:
        buf = np.empty(max(rows * cols, 2 * (buf.size if buf is not None else 0)), dtype=dt)
        pool[(key, dt.str)] = buf
    return buf[: rows * cols].reshape(rows, cols)



def mapped_zeros(shape: tuple[int, ...], dtype: np.dtype | type = np.float64) -> NDArray:
    """Zeros whose pages are all mapped now, in one sequential sweep: for a history that a
    streaming loop fills a piece at a time (the OADEV's ring, R(n)'s), the first touches
    otherwise fall inside that loop one page at a time. Measured on the 60 h, 3-axis analyze:
    the running sum's writes took 0.35 CPU-s with the rings' pages mapped on first touch,
    0.06 s after a sweep that itself took 0.02 s. Every page is written by the loop sooner or
    later, so the memory used is the same. After ``reuse_histories()``, the memory of an
    earlier history nothing refers to any more is handed out again, its pages already
    mapped."""
    dt = np.dtype(dtype)
    count = math.prod(shape)
    kept = _reused if _reused is not None else getattr(_local, "histories", None)
    if kept is None:
        out = np.empty(shape, dtype=dt)
    else:
        # free: nothing but this list (and the loop's and getrefcount's own references)
        # holds it, no view either (a view's base is the buffer itself)
        free = [i for i in range(len(kept)) if sys.getrefcount(kept[i]) <= _FREE_REFS]
        fits = [i for i in free if kept[i].dtype == dt and kept[i].size >= count]
        if fits:
            base = kept[min(fits, key=lambda i: kept[i].size)]
        else:
            for i in reversed(free):  # idle and too small: given back, not kept beside it
                del kept[i]
            base = np.empty(count, dtype=dt)
            kept.append(base)
        out = base[:count].reshape(shape)
    out.fill(0)
    return out


#: The histories this process hands out again (``reuse_histories``), None: it does not.
_reused: list[NDArray] | None = None
#: References to a buffer of ``_reused`` that nothing else holds: the list's and
#: ``sys.getrefcount``'s own (any array made from it holds one more: a view's base is the
#: buffer itself, however it was sliced).
_FREE_REFS = 2


@contextmanager
def histories_passed_on() -> Iterator[None]:
    """Within the block, this thread's ``mapped_zeros`` hands out again the memory of an
    earlier history nothing refers to any more, its pages already mapped: the passes of
    one analyze, read one after another, share the first pass's history instead of each
    mapping a fresh one (a 67 MB OADEV ring's page faults cost 0.01–0.2 CPU-s, the more
    the busier the machine). Thread-local: another thread's histories are its own. When the
    block ends the memory is given back; a process that keeps its histories for good
    (``reuse_histories``) keeps doing so."""
    if _reused is not None or getattr(_local, "histories", None) is not None:
        yield
        return
    _local.histories = []
    try:
        yield
    finally:
        _local.histories = None


def reuse_histories() -> None:
    """From now on this process keeps the memory of the histories ``mapped_zeros`` hands
    out and gives it out again once nothing refers to it: for a worker process of a parallel
    analysis (core/analysis/parallel.py), which analyses chunk after chunk with histories of
    the same size and then exits. Mapping a 67 MB OADEV ring afresh costs 0.03–0.14 CPU-s of
    page faults (more on a busy machine), sweeping a mapped one a few milliseconds. Not for a
    long-lived process: the memory stays with it."""
    global _reused
    if _reused is None:
        _reused = []
