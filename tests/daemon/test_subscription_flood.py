"""Subscriptions a subscriber sends cost the service memory (adv27).

A PUB socket keeps every subscription its peers send in libzmq's subscription trie, one
node per byte, some 25 bytes a node here: one local client's single 4 MB subscription took
the service's RSS from 17 to 473 MB, 2 000 random 1 kB ones by 50 MB. Nothing the service
publishes needs more than a topic name (core/io/frames.TOPICS, a rig's ``TOPIC.NAME``), so
the publisher now refuses inbound messages above ``MAX_SUBSCRIPTION_BYTES`` (ZMQ_MAXMSGSIZE:
libzmq drops such a peer's connection, its trie entries go with it).

Under that cap the count of distinct subscriptions was unbounded (ten connections of 400
random 250-byte ones: some 40 MB). The publisher's subscription guard (daemon/net/front.py)
now passes on to the PUB socket only subscriptions that can match a topic the service
publishes, whatever their shape: many distinct ones on one connection, subscribe/unsubscribe
churn, many connections of a few each. The counts say so exactly (every junk subscription
dropped, the ``status`` one of each connection applied) and the RSS says what it cost.

The flooder and the publisher are processes of their own, so the RSS measured is the
publisher's alone; the test waits on events (the flooder's own "status" subscription coming
back through each connection, or not: the connection dropped), never on wall time.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

FLOODER = r"""
import os, sys, zmq
ep, waves, n, size, mode = (sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]),
                            sys.argv[5])
ctx = zmq.Context()
keep = []
for w in range(waves):
    # each wave from a new connection, the earlier ones kept open (their subscriptions stay
    # in the publisher's trie for as long as they are connected)
    s = ctx.socket(zmq.SUB)
    s.setsockopt(zmq.LINGER, 0)
    s.setsockopt(zmq.SNDHWM, 0)                 # every subscription goes out
    s.connect(ep)
    for k in range(n):
        junk = os.urandom(size)
        s.setsockopt(zmq.SUBSCRIBE, junk)
        if mode == "churn":                      # and taken back at once
            s.setsockopt(zmq.UNSUBSCRIBE, junk)
    s.setsockopt(zmq.SUBSCRIBE, b"status")      # after the junk, in the same pipe
    keep.append(s)
    # the wave has reached the publisher when the status message comes back through it (or
    # the publisher dropped this connection and it never comes): pacing, nothing measured
    got = s.poll(60_000)
    print("wave", w, "received" if got else "not received", flush=True)
print("done", flush=True)
sys.stdin.read()
"""


PUBLISHER = r"""
import json, os, subprocess, sys, time
from avard.daemon.net.publisher import Publisher


def rss_bytes():
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
    raise AssertionError("no VmRSS in /proc/self/status")


flooder, waves, n, size, mode, guard = sys.argv[1:7]
pub = Publisher("tcp://127.0.0.1:0", "run", check=False, guard=guard == "guard")
before = rss_bytes()
proc = subprocess.Popen([sys.executable, flooder, pub.endpoint, waves, n, size, mode],
                        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
seen = []
os.set_blocking(proc.stdout.fileno(), False)
while proc.poll() is None:
    pub.publish("status", {"kind": "status", "v": 1})
    line = proc.stdout.readline().strip()
    if line == "done":
        break
    if line:
        seen.append(line)
    time.sleep(0.002)      # pacing only: nothing is measured against time
grown = rss_bytes() - before
stats = pub.stats()
proc.kill()
proc.wait()
pub.close()
print(json.dumps({"grown": grown, "seen": seen, "stats": stats}))
"""


def _flood(tmp_path: Path, waves: int, n: int, size: int, mode: str = "distinct",
           guard: bool = True) -> tuple[int, list[str], dict[str, Any]]:
    """RSS growth of the publisher's process once every wave of ``n`` subscriptions of
    ``size`` random bytes has reached it, what each wave saw, and the publisher's counters.
    The publisher runs in a process of its own: freed heap that the test process keeps from
    earlier tests would hide the growth."""
    (tmp_path / "flooder.py").write_text(FLOODER)
    (tmp_path / "publisher.py").write_text(PUBLISHER)
    out = subprocess.run([sys.executable, str(tmp_path / "publisher.py"),
                          str(tmp_path / "flooder.py"), str(waves), str(n), str(size), mode,
                          "guard" if guard else "direct"],
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert len(got["seen"]) == waves, got
    return int(got["grown"]), list(got["seen"]), dict(got["stats"])


def test_one_oversized_subscription_does_not_take_the_services_memory(tmp_path: Path) -> None:
    grown, seen, _stats = _flood(tmp_path, 1, 1, 1 << 20)   # one 1 MiB subscription
    assert grown < 16 << 20, f"publisher RSS grew by {grown / 1e6:.0f} MB ({seen})"
    assert seen == ["wave 0 not received"]              # the peer was dropped


# (waves, subscriptions per wave, mode): adv27's ten connections of 400; one connection of
# 4 000; 4 000 subscribe/unsubscribe pairs; fifty connections of 80
SHAPES = [(10, 400, "distinct"), (1, 4000, "distinct"), (1, 4000, "churn"),
          (50, 80, "distinct")]


@pytest.mark.parametrize(("waves", "n", "mode"), SHAPES,
                         ids=["10x400", "1x4000", "churn-4000", "50x80"])
def test_a_subscription_flood_does_not_take_the_services_memory(
        tmp_path: Path, waves: int, n: int, mode: str) -> None:
    """Random 250-byte subscriptions (under the size cap) match nothing the service
    publishes: the guard drops every one (counted), the ``status`` subscription sent after
    them on each connection is applied, and the publisher's RSS stays where it was. Without
    the guard the first two shapes took some 40-50 MB (the control test below)."""
    grown, seen, stats = _flood(tmp_path, waves, n, 250, mode)
    # every wave reached the publisher before its RSS and counters were read: a wave the
    # flooder stopped waiting for (a starved machine) would measure less than was sent
    assert seen == [f"wave {w} received" for w in range(waves)], seen
    assert stats["subscriptions_guarded"] is True
    assert stats["subscriptions_dropped"] == waves * n, stats
    assert stats["subscriptions_applied"] == waves, stats          # one "status" each
    assert stats["cancels_ignored"] == (waves * n if mode == "churn" else 0), stats
    assert grown < 16 << 20, f"publisher RSS grew by {grown / 1e6:.0f} MB ({stats})"


def test_without_the_guard_the_same_flood_takes_the_memory(tmp_path: Path) -> None:
    """The control: the PUB socket bound directly (``guard=False``, as before daemon28)
    keeps one connection's 4 000 junk subscriptions, and this measurement sees it, so the
    bound above is not the measurement's blindness."""
    grown, seen, stats = _flood(tmp_path, 1, 4000, 250, guard=False)
    assert seen == ["wave 0 received"], seen
    assert stats["subscriptions_guarded"] is False
    assert grown > 24 << 20, f"publisher RSS grew by only {grown / 1e6:.0f} MB unguarded"
