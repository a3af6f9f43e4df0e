"""The tests' subscribers join as the demo's does (no sleep): see avard.daemon.net.handshake."""

from avard.daemon.net.handshake import is_hello as is_probe
from avard.daemon.net.handshake import wait_until_subscribed

__all__ = ["is_probe", "wait_until_subscribed"]
