"""Publish throughput and sample-to-subscriber latency over loopback TCP.

``python -m benchmarks publish [--messages N] [--latency N] [--rate HZ]
[--service-seconds S] [--odr 125,4000]``

Throughput: N raw blocks of 32 samples × 3 axes (int32 counts, the service's block) go from
``Publisher.publish(record)`` to a ``Subscriber`` in another thread that decodes and checks
every one (sequence and index continuity); messages/s and samples/s until the last arrives.
Reference, measured in the same run: plain pyzmq PUB→SUB of the same number of pre-encoded
messages of the same size (no record building, no validation, no decoding).

Latency: messages paced at ``--rate`` (default 1 kHz, far above the service's ~100
blocks/s, so the queue stays empty); the latency of a message is from just before ``publish``
is called to just after the subscriber has decoded it (same clock, CLOCK_MONOTONIC). p50 and
p99 against the same measurement for plain pyzmq bytes.

Sample age: the whole service (``avard run --simulate quiet-lab`` at speed 1, i.e. real
time) at each ODR with a subscriber in a thread; for every raw block, the age of its newest
sample when the subscriber has decoded it, on the service's clock. Reference: the drain poll
period, the floor of this pipeline (a sample waits in the FIFO until the next drain).
"""

from __future__ import annotations

import argparse
import threading
import time
from collections.abc import Iterator

import numpy as np
import zmq
from avard.core.io import frames
from avard.daemon.net.publisher import Publisher
from avard.daemon.net.subscriber import Subscriber

BLOCK = 32
LOCAL = "tcp://127.0.0.1:*"


def _raw(i0: int) -> dict:
    counts = np.arange(i0 * 3, (i0 + BLOCK) * 3, dtype=np.int32).reshape(BLOCK, 3)
    return frames.raw_record("", 0, i0, counts, time.monotonic(), time.time(), rate_hz=125.0)


# ---- avard: Publisher → Subscriber ---------------------------------------------------------


def _connect(pub: Publisher, sub: Subscriber) -> None:
    for _ in range(1000):
        pub.publish("status", frames.status_record("", 0, {}, 0.0, 0.0))
        if sub.recv(0.01) is not None:
            break
    while sub.recv(0.05) is not None:
        pass


def avard_throughput(n: int, check: bool) -> float:
    with Publisher(LOCAL, "bench", hwm=n + 1000, check=check) as pub:
        sub = Subscriber(pub.endpoint, ["raw", "status"], rcvhwm=n + 1000).connect(join=False)
        _connect(pub, sub)
        records = [_raw(BLOCK * i) for i in range(n)]
        done = threading.Event()
        got = {"n": 0}

        def consume() -> None:
            while got["n"] < n:
                m = sub.recv(5.0)
                if m is None:
                    break
                got["n"] += m.topic == "raw"
            done.set()

        t = threading.Thread(target=consume)
        t0 = time.perf_counter()
        t.start()
        for rec in records:
            pub.publish("raw", rec)
        done.wait(60)
        dt = time.perf_counter() - t0
        t.join()
        lost = sub.stats.samples_lost
        sub.close()
    if got["n"] != n or lost:
        raise RuntimeError(f"avard throughput run lost messages: {got['n']} of {n}, {lost} lost")
    return n / dt


def _paced(n: int, rate: float) -> Iterator[int]:
    """0 … n−1, each yielded no earlier than its slot of a fixed ``rate`` (busy wait: a
    sleep's wake-up jitter would be measured as latency)."""
    period = 1.0 / rate
    next_t = time.monotonic()
    for i in range(n):
        while time.monotonic() < next_t:
            pass
        yield i
        next_t += period


def avard_latency(n: int, rate: float) -> np.ndarray:
    with Publisher(LOCAL, "bench") as pub:
        sub = Subscriber(pub.endpoint, ["raw", "status"]).connect(join=False)
        _connect(pub, sub)
        lat = np.empty(n)
        for i in _paced(n, rate):
            rec = _raw(BLOCK * i)
            t_send = time.monotonic()
            pub.publish("raw", rec)
            m = sub.recv(5.0)
            lat[i] = time.monotonic() - t_send
            assert m is not None and m.record["i0"] == BLOCK * i
        sub.close()
    return lat


# ---- reference: plain pyzmq bytes ----------------------------------------------------------


def _zmq_pair(hwm: int) -> tuple[zmq.Context, zmq.Socket, zmq.Socket]:
    ctx = zmq.Context()
    pub = ctx.socket(zmq.PUB)
    pub.setsockopt(zmq.SNDHWM, hwm)
    pub.setsockopt(zmq.LINGER, 0)
    pub.bind(LOCAL)
    sub = ctx.socket(zmq.SUB)
    sub.setsockopt(zmq.RCVHWM, hwm)
    sub.setsockopt(zmq.SUBSCRIBE, b"")
    sub.connect(pub.getsockopt_string(zmq.LAST_ENDPOINT))
    for _ in range(1000):
        pub.send_multipart([b"status", b"x"])
        if sub.poll(10):
            break
    while sub.poll(50):
        sub.recv_multipart()
    return ctx, pub, sub


def zmq_throughput(n: int, payload: bytes) -> float:
    ctx, pub, sub = _zmq_pair(n + 1000)
    done = threading.Event()
    got = {"n": 0}

    def consume() -> None:
        while got["n"] < n and sub.poll(5000):
            sub.recv_multipart()
            got["n"] += 1
        done.set()

    t = threading.Thread(target=consume)
    t0 = time.perf_counter()
    t.start()
    for _ in range(n):
        pub.send_multipart([b"raw", payload], flags=zmq.NOBLOCK)
    done.wait(60)
    dt = time.perf_counter() - t0
    t.join()
    pub.close()
    sub.close()
    ctx.term()
    if got["n"] != n:
        raise RuntimeError(f"reference run lost messages: {got['n']} of {n}")
    return n / dt


def zmq_latency(n: int, rate: float, payload: bytes) -> np.ndarray:
    ctx, pub, sub = _zmq_pair(1000)
    lat = np.empty(n)
    for i in _paced(n, rate):
        t_send = time.monotonic()
        pub.send_multipart([b"raw", payload])
        sub.recv_multipart()
        lat[i] = time.monotonic() - t_send
    pub.close()
    sub.close()
    ctx.term()
    return lat


# ---- the whole service: sample age when it reaches a subscriber ----------------------------


def service_latency(odr_hz: float, seconds: float) -> tuple[np.ndarray, dict]:
    """Run the service on the emulated sensor in real time (speed 1) with a subscriber in a
    thread; for every raw block, the age of its newest sample when decoded at the subscriber,
    on the service's own clock (newest sample time = t_mono + (n − 1)/rate)."""
    import tempfile

    from avard.daemon.compose import simulated_service
    from avard.daemon.config import load_config

    with tempfile.TemporaryDirectory() as tmp:
        cfg = load_config(None, **{"recording.data_dir": tmp, "sensor.odr_hz": odr_hz,
                                   "publish.endpoint": "tcp://127.0.0.1:0",
                                   "publish.request_endpoint": "tcp://127.0.0.1:0"})
        svc, _sims, _emu = simulated_service(cfg, "quiet-lab", seed=1, speed=1.0)
        clock = svc.clock
        ages: list[float] = []
        box: dict = {"stop": threading.Event()}

        def listen() -> None:
            sub = Subscriber(svc.publisher.endpoint, ["raw", "status"]).connect(join=False)
            box["sub"] = sub
            while sub.recv(0.05) is None:  # probe until the subscription is through
                svc.publisher.publish("status", frames.status_record("", 0, {}, 0.0, 0.0))

            def loop() -> None:
                while not box["stop"].is_set():
                    m = sub.recv(0.1)
                    if m is not None and m.topic == "raw" and m.record["n"]:
                        r = m.record
                        rate = r.get("rate_hz") or odr_hz
                        ages.append(clock.monotonic() - (r["t_mono"] + (r["n"] - 1) / rate))
                sub.close()

            box["thread"] = threading.Thread(target=loop, daemon=True)
            box["thread"].start()

        try:
            svc.run(seconds, before_acquisition=listen)
        finally:
            box["stop"].set()
            if "thread" in box:
                box["thread"].join(10)
        stats = box["sub"].stats.to_dict()
    return np.asarray(ages), stats


# ---- main ----------------------------------------------------------------------------------


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks publish", description=__doc__)
    ap.add_argument("--messages", type=int, default=20000, help="throughput messages")
    ap.add_argument("--latency", type=int, default=2000, help="latency messages")
    ap.add_argument("--rate", type=float, default=1000.0, help="latency pacing, messages/s")
    ap.add_argument("--service-seconds", type=float, default=15.0,
                    help="real-time seconds of the whole service per ODR (0: skip)")
    ap.add_argument("--odr", default="125,4000", help="ODRs (Hz) for the service latency")
    args = ap.parse_args(argv)

    payload = frames.encode(dict(_raw(0), run="bench", seq=0))
    print(f"raw block: {BLOCK} samples × 3 axes int32 = {len(payload)} bytes per message; "
          f"loopback TCP, subscriber in a second thread of the same process")
    ref = zmq_throughput(args.messages, payload)
    ours = avard_throughput(args.messages, check=True)
    ours_nc = avard_throughput(args.messages, check=False)
    print(f"\nthroughput, {args.messages} messages")
    print(f"{'case':<46}{'msgs/s':>12}{'samples/s':>14}{'ratio':>8}")
    for name, r in [("pyzmq bytes PUB→SUB (reference)", ref),
                    ("Publisher.publish → Subscriber.recv", ours),
                    ("  same, publish without validation", ours_nc)]:
        print(f"{name:<46}{r:>12,.0f}{r * BLOCK:>14,.0f}{r / ref:>8.2f}")

    zl = zmq_latency(args.latency, args.rate, payload) * 1e6
    al = avard_latency(args.latency, args.rate) * 1e6
    print(f"\nlatency publish → decoded at subscriber, {args.latency} messages at "
          f"{args.rate:g}/s (µs)")
    print(f"{'case':<46}{'p50':>10}{'p99':>10}{'p50 ratio':>11}{'p99 ratio':>11}")
    zp50, zp99 = np.percentile(zl, [50, 99])
    ap50, ap99 = np.percentile(al, [50, 99])
    print(f"{'pyzmq bytes PUB→SUB (reference)':<46}{zp50:>10.0f}{zp99:>10.0f}{1:>11.2f}{1:>11.2f}")
    print(f"{'Publisher.publish → Subscriber.recv':<46}{ap50:>10.0f}{ap99:>10.0f}"
          f"{ap50 / zp50:>11.2f}{ap99 / zp99:>11.2f}")
    busiest = 0.0  # raw blocks/s the service published, at its busiest
    if args.service_seconds > 0:
        print(f"\nsample age at the subscriber: the service on the emulated sensor in real "
              f"time, {args.service_seconds:g} s per ODR (ms; the drain poll period is the "
              "floor of this pipeline)")
        print(f"{'case':<30}{'blocks/s':>9}{'p50':>9}{'p99':>9}{'poll':>9}{'p50/poll':>10}"
              f"{'lost':>6}")
        from avard.daemon.config import effective_poll_hz, load_config

        for odr in (float(x) for x in args.odr.split(",")):
            ages, st = service_latency(odr, args.service_seconds)
            poll_ms = 1e3 / effective_poll_hz(load_config(None, **{"sensor.odr_hz": odr}))
            p50, p99 = np.percentile(ages * 1e3, [50, 99]) if ages.size else (np.nan, np.nan)
            rate = ages.size / args.service_seconds
            busiest = max(busiest, rate)
            print(f"{f'service at {odr:g} Hz ODR':<30}{rate:>9.0f}{p50:>9.1f}{p99:>9.1f}"
                  f"{poll_ms:>9.1f}{p50 / poll_ms:>10.2f}{st['samples_lost']:>6}")
        if busiest > 0:
            print(f"\nheadroom: the service published at most {busiest:.0f} raw blocks/s; "
                  f"Publisher→Subscriber carried {ours:,.0f}/s = {ours / busiest:,.0f}× that")
    return 0
