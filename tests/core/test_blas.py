"""The Python API holds OpenBLAS to one thread while avard computes (core/blas.py): checked in
a child process started with OPENBLAS_NUM_THREADS unset, by the CPU time of the BLAS worker
threads (OpenBLAS starts them when numpy loads, so their number does not change; the CPU they
use does)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading

import pytest
from avard.core import blas
from avard.core.blas import BlasLibrary

_CHILD = r"""
import json, os, threading, time
import numpy as np
from avard.core.allan.deviations import allan_variance
from avard.core.allan.streaming import StreamingAllan
from avard.core.blas import active_backends, single_blas_thread

main_tid = threading.get_native_id()

def worker_ticks():
    ticks = 0
    for tid in os.listdir("/proc/self/task"):
        if int(tid) != main_tid:
            with open(f"/proc/self/task/{tid}/stat") as fh:
                f = fh.read().rsplit(")", 1)[1].split()
            ticks += int(f[11]) + int(f[12])
    return ticks

libs = active_backends()
pool = [b.get_threads() for b in libs]
y = np.random.default_rng(0).normal(size=(1 << 19, 3))

def cascade(update, result):
    s = StreamingAllan(3, 100.0)
    for i in range(0, len(y), 1 << 16):
        update(s, y[i:i + (1 << 16)])
    return result(s)

def run(fn):
    time.sleep(0.3)  # workers of an earlier call stop spinning
    t0 = worker_ticks()
    fn()
    return worker_ticks() - t0

held = run(lambda: (cascade(StreamingAllan.update, StreamingAllan.result),
                    allan_variance(y, 100.0, "octave", kind="oavar")))
after = [b.get_threads() for b in libs]
try:
    with single_blas_thread():
        raise KeyError("inside")
except KeyError:
    pass
after_error = [b.get_threads() for b in libs]
free = run(lambda: (cascade(StreamingAllan.update.__wrapped__,
                            StreamingAllan.result.__wrapped__),
                    allan_variance.__wrapped__(y, 100.0, "octave", kind="oavar")))
print(json.dumps({"libs": [os.path.basename(b.path) for b in libs], "pool": pool,
                  "held": held, "free": free, "after": after, "after_error": after_error}))
"""


@pytest.mark.skipif(not os.path.exists("/proc/self/task"), reason="needs Linux /proc")
@pytest.mark.parametrize("kernels", ["numpy", "compiled"])
def test_api_computations_leave_the_blas_pool_idle(kernels: str) -> None:
    """On numpy's path (no compiled loops: an install without a compiler) the computations
    make long dot products, and the probe sees the workers wake without the hold. The
    compiled loops make few (6–7 ticks against 24–28 here, 4 under a parallel suite), so
    there only the hold itself is checked."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS",
                        "AVARD_NO_C_KERNELS")}
    if kernels == "numpy":
        env["AVARD_NO_C_KERNELS"] = "1"
    out = subprocess.run([sys.executable, "-c", _CHILD], env=env, capture_output=True,
                         text=True, timeout=300, check=True).stdout
    r = json.loads(out.strip().splitlines()[-1])
    if not r["libs"] or max(r["pool"]) <= 1:
        pytest.skip(f"no OpenBLAS pool to hold here (libraries {r['libs']}, pool {r['pool']})")
    if kernels == "numpy":
        # the same computations without the hold wake the workers: the probe can see them
        assert r["free"] >= 5, r
    # with it (as shipped) the workers get no CPU at all (one clock tick of slack)
    assert r["held"] <= 1, r
    # and the program gets its pool back afterwards, also when the computation raised
    assert r["after"] == r["pool"] and r["after_error"] == r["pool"], r


class _FakeOpenBlas:
    """Stands for one loaded OpenBLAS: per-thread setting (``local``, OpenBLAS ≥ 0.3.27) or
    the process-wide one; records every call."""

    def __init__(self, threads: int, local: bool) -> None:
        self.global_n = threads
        self.local_n: dict[int, int] = {}
        self.local = local
        self.calls: list[tuple[str, int]] = []

    def get(self) -> int:
        return self.local_n.get(threading.get_ident(), self.global_n)

    def set(self, n: int) -> int:
        self.calls.append(("set", n))
        if self.local:
            old = self.get()
            self.local_n[threading.get_ident()] = n
            return old
        self.global_n = n
        return 0

    def library(self) -> BlasLibrary:
        return BlasLibrary(f"fake-{self.local}", self.local, self.set, self.get)


def _use(monkeypatch: pytest.MonkeyPatch, *fakes: _FakeOpenBlas) -> None:
    monkeypatch.setattr(blas, "active_backends", lambda: [f.library() for f in fakes])


def test_one_thread_inside_nested_calls_and_the_pool_back_after_an_error(
        monkeypatch: pytest.MonkeyPatch) -> None:
    fake = _FakeOpenBlas(4, local=True)
    _use(monkeypatch, fake)
    seen = []

    @blas.one_blas_thread
    def inner() -> None:
        seen.append(fake.get())

    @blas.one_blas_thread
    def outer() -> None:
        seen.append(fake.get())
        inner()
        raise KeyError("stop")

    with pytest.raises(KeyError):
        outer()
    assert seen == [1, 1] and fake.get() == 4
    assert fake.calls == [("set", 1), ("set", 4)]  # the nested call set nothing


def test_nothing_is_set_when_the_pool_has_one_thread(monkeypatch: pytest.MonkeyPatch) -> None:
    """The CLI and the service start numpy with OPENBLAS_NUM_THREADS=1: no call at all."""
    fake = _FakeOpenBlas(1, local=False)
    _use(monkeypatch, fake)
    with blas.single_blas_thread():
        pass
    assert fake.calls == []


def test_a_process_wide_setting_is_given_back_when_the_last_computation_ends(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Old OpenBLAS (no per-thread setting): two threads computing at once; the pool comes
    back only when both are done, and is set to one only once."""
    fake = _FakeOpenBlas(4, local=False)
    _use(monkeypatch, fake)
    a_in, b_in, a_may_leave = threading.Event(), threading.Event(), threading.Event()
    during: list[int] = []

    def first() -> None:
        with blas.single_blas_thread():
            a_in.set()
            a_may_leave.wait(10)

    def second() -> None:
        a_in.wait(10)
        with blas.single_blas_thread():
            b_in.set()
            during.append(fake.global_n)
        during.append(fake.global_n)  # first still inside
        a_may_leave.set()

    ta, tb = threading.Thread(target=first), threading.Thread(target=second)
    ta.start()
    tb.start()
    ta.join(10)
    tb.join(10)
    assert b_in.is_set() and during == [1, 1]
    assert fake.global_n == 4 and fake.calls == [("set", 1), ("set", 4)]
