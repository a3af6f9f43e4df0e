"""Knowing that a subscriber in this process gets everything from a publisher from now on.

A PUB socket drops what it sends before a SUB's subscription has reached it (ZeroMQ's "slow
joiner"); sleeping a moment and hoping is what a loaded machine breaks. Instead the publisher
sends ``hello`` events until the subscriber receives one: ZeroMQ keeps one peer's messages in
order, so from that event on the subscriber gets every message the publisher sends. For a
subscriber in the same process as the service (``avard demo``, the tests), before acquisition.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

from avard.core.errors import NetworkError
from avard.core.io import frames
from avard.daemon.net.publisher import Publisher
from avard.daemon.net.subscriber import Subscriber

HELLO = "subscriber-hello"


def is_hello(record: Mapping[str, Any]) -> bool:
    return record.get("kind") == "event" and record.get("name") == HELLO


def wait_until_subscribed(pub: Publisher, sub: Subscriber, *, limit_s: float = 120.0
                          ) -> list[tuple[str, dict[str, Any]]]:
    """Return once ``sub`` receives what ``pub`` sends, with the other messages that arrived
    meanwhile as (topic, record). ``limit_s`` bounds a broken set-up only (NetworkError)."""
    kept: list[tuple[str, dict[str, Any]]] = []
    deadline = time.monotonic() + limit_s
    while True:
        pub.publish("event", frames.event_record("", 0, HELLO, 0.0, 0.0))
        msg = sub.recv(timeout_s=0.05)
        while msg is not None:
            if is_hello(msg.record):
                return kept
            kept.append((msg.topic, dict(msg.record)))
            msg = sub.recv(timeout_s=0.05)
        if time.monotonic() > deadline:
            raise NetworkError(f"the subscriber to {pub.endpoint} received nothing in "
                               f"{limit_s:g} s")
