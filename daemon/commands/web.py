"""A live, read-only browser view of a running service, with ``/metrics`` for Prometheus.

Subscribes to ENDPOINT like ``avard watch`` (request socket for snapshot and header, CURVE
keys when the service uses them) and serves on ``--listen`` (default 127.0.0.1:8080, this
machine only): the Allan deviation of each axis with its 68 % intervals and the fitted model,
the fitted IEEE terms with intervals, the time until each τ's interval is within a target,
temperatures over the run, gaps and events on a time line, and the service's status. Pages
update by server-sent events; every script and style is served by avard itself. Another
listen address is used only when given, and logged. Needs the ``web`` extra
(``pip install 'avard[web]'``; from a checkout ``.venv/bin/pip install -e '.[web]'``).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import ipaddress
import logging
import signal
from pathlib import Path

from avard.core.errors import ConfigError
from avard.daemon.net.subscriber import (
    add_client_arguments,
    check_stream_sensor,
    subscriber_from_args,
)

NAME = "web"
#: INFO lines by default: a long-running command says what it does as it goes
NARRATES = True
HELP = "serve a live, read-only web page (and /metrics) of a running service"

log = logging.getLogger(__name__)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_client_arguments(parser)
    # joining asks the service for its snapshot, which it fits on demand (seconds on a Pi)
    parser.set_defaults(timeout=15.0)
    for action in parser._actions:  # argparse has no public way to change a shared help
        if action.dest == "timeout":
            action.help = ("seconds to wait for a request reply (default 15: the service "
                           "fits the snapshot it is asked for)")
    parser.add_argument("--listen", default="127.0.0.1:8080", metavar="HOST:PORT",
                        help="address to serve on (default 127.0.0.1:8080: this machine only; "
                             "0.0.0.0:8080 serves the lab network)")
    parser.add_argument("--refresh", type=float, default=1.0, metavar="S",
                        help="push changes to the open pages at most every S s (default 1)")
    parser.add_argument("--fit-interval", type=float, default=60.0, metavar="S",
                        help="fit the newest Allan snapshot at most every S s (default 60; "
                             "a fit of three axes costs seconds of CPU)")
    parser.add_argument("--no-fit", action="store_true",
                        help="do not fit (no IEEE terms, no model curve)")
    parser.add_argument("--history", metavar="DIR", default=None,
                        help="the service's recording directory (recording.data_dir), when "
                             "readable here: temperatures, gaps and events from before this "
                             "server started are read from it first")


def parse_listen(text: str) -> tuple[str, int]:
    """``HOST:PORT`` or ``[V6]:PORT`` → (host, port); ConfigError naming what is wrong."""
    host, sep, port = text.rpartition(":")
    if host.startswith("[") and host.endswith("]"):
        host = host[1:-1]
    if not sep or not host or not port.isdigit() or not 0 <= int(port) <= 65535:
        raise ConfigError(f"--listen {text!r}: give HOST:PORT, e.g. 127.0.0.1:8080 or "
                          "0.0.0.0:8080 (port 0–65535)")
    return host, int(port)


def is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def _check_args(args: argparse.Namespace) -> tuple[str, int]:
    host, port = parse_listen(args.listen)
    if not args.refresh > 0:
        raise ConfigError(f"--refresh {args.refresh}: must be a positive number of seconds")
    if not args.fit_interval >= 0:
        raise ConfigError(f"--fit-interval {args.fit_interval}: must be ≥ 0 seconds")
    if args.history is not None and not Path(args.history).is_dir():
        raise ConfigError(f"--history {args.history}: no such directory; give the service's "
                          "recording.data_dir (e.g. /var/lib/avard)")
    if args.history is not None:
        from avard.core.io.source import sensor_path

        sensor_path(args.history, args.sensor)     # a rig's: the sensor named, and known
    return host, port


def run(args: argparse.Namespace) -> int:
    host, port = _check_args(args)
    try:
        from aiohttp import web  # noqa: F401 - only to say what is missing, early
    except ImportError:
        raise ConfigError("avard web needs the 'web' extra (it adds aiohttp): "
                          "pip install 'avard[web]', or from a checkout "
                          ".venv/bin/pip install -e '.[web]'") from None
    sub = subscriber_from_args(args)
    if args.sensor is not None:
        check_stream_sensor(sub)
    return asyncio.run(_serve(args, sub, host, port))


async def _serve(args: argparse.Namespace, sub: object, host: str, port: int) -> int:
    from aiohttp import web
    from avard.core.io.source import RecordingSource, sensor_path
    from avard.daemon.service.snapshots import snapshot_fits
    from avard.daemon.web.app import Hub, make_app
    from avard.daemon.web.feed import Feed
    from avard.daemon.web.state import RunState

    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGTERM, signal.SIGINT):
        with contextlib.suppress(NotImplementedError, RuntimeError):
            loop.add_signal_handler(sig, stop.set)
    state = RunState(history=args.history)
    feed = Feed(sub, state, fit=None if args.no_fit else snapshot_fits,
                fit_interval_s=args.fit_interval,
                history=None if args.history is None
                else RecordingSource(sensor_path(args.history, args.sensor)))
    hub = Hub(state, refresh_s=args.refresh)
    app = make_app(state, hub, endpoint=args.endpoint)
    runner = web.AppRunner(app, access_log=None)
    await runner.setup()
    site = web.TCPSite(runner, host, port, shutdown_timeout=1.0)
    try:
        await site.start()
    except OSError as exc:
        await runner.cleanup()
        raise ConfigError(f"--listen {args.listen}: cannot serve there ({exc.strerror}); "
                          "is another server on that port?") from None
    bound = runner.addresses[0][1] if runner.addresses else port
    shown = f"[{host}]" if ":" in host else host
    if is_loopback(host):
        log.info("serving http://%s:%d/ (read-only; this machine only)", shown, bound)
    else:
        log.warning("serving http://%s:%d/ on %s as asked: reachable from the network, "
                    "read-only, no authentication", shown, bound, host)
    feed.start()
    try:
        while not stop.is_set():
            if feed.error is not None:
                log.error("stopping: the subscriber failed (%s)", feed.error)
                return 1
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(stop.wait(), 0.5)
    finally:
        await hub.close()
        await runner.cleanup()
        feed.stop()
    return 0
