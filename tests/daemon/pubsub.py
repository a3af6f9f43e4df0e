"""Joining a publisher without sleeping: the subscription is known to be in place.

A PUB socket drops what it sends before a SUB's subscription has reached it (ZeroMQ's "slow
joiner"). Sleeping a fraction of a second and hoping is what a loaded machine breaks; instead
the test publishes probe events until its subscriber receives one. ZeroMQ keeps one peer's
messages in order, so from that probe on the subscriber gets every message the service sends.
"""

from __future__ import annotations

import time
from typing import Any

from avard.core.io import frames
from avard.daemon.net.publisher import Publisher
from avard.daemon.net.subscriber import Subscriber

PROBE = "avard-test-subscribed"

#: Not a timing assumption: only a bound on how long a broken set-up may hang the test.
HANG_LIMIT_S = 120.0


def is_probe(record: dict[str, Any]) -> bool:
    return record.get("kind") == "event" and record.get("name") == PROBE


def wait_until_subscribed(pub: Publisher, sub: Subscriber) -> list[tuple[str, dict]]:
    """Return once ``sub`` receives what ``pub`` sends; the non-probe messages that arrived
    meanwhile are returned (topic, record) so the caller keeps them."""
    kept: list[tuple[str, dict]] = []
    deadline = time.monotonic() + HANG_LIMIT_S
    while True:
        pub.publish("event", frames.event_record("", 0, PROBE, 0.0, 0.0))
        msg = sub.recv(timeout_s=0.05)
        while msg is not None:
            if is_probe(msg.record):
                return kept
            kept.append((msg.topic, msg.record))
            msg = sub.recv(timeout_s=0.05)
        assert time.monotonic() < deadline, "the subscription never reached the publisher"
