"""The threads behind the page: the subscriber that fills :class:`RunState`, and the fitter.

:class:`Feed` owns one :class:`~avard.daemon.net.subscriber.Subscriber` (the same one ``avard
watch`` and ``avard record`` use; ZeroMQ sockets stay in this one thread) and hands every
decoded message to the state. A second thread fits the newest Allan snapshot with
:func:`avard.daemon.service.snapshots.fit_snapshot` — seconds of CPU for three axes, so at most
every ``fit_interval_s`` and never on the web server's event loop. Both threads wait on
work (a socket poll, an event), never spin.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import Any

from avard.core.allan.streaming import AllanSnapshot
from avard.core.errors import FormatError, NetworkError
from avard.core.io.source import RecordingSource
from avard.daemon.net.subscriber import Subscriber
from avard.daemon.service.snapshots import fit_intervals
from avard.daemon.web.state import RunState, Snapshot

log = logging.getLogger(__name__)

#: Seconds between asks for the run header while the service has not given one.
HEADER_RETRY_S = 10.0

FitFn = Callable[[AllanSnapshot], dict[str, Any]]


class Feed:
    """Subscriber thread + fitter thread over one :class:`RunState`."""

    def __init__(self, sub: Subscriber, state: RunState, *, fit: FitFn | None,
                 fit_interval_s: float = 60.0,
                 history: RecordingSource | None = None) -> None:
        self.sub = sub
        self.history = history
        self.state = state
        self.fit = fit
        self.fit_interval_s = fit_interval_s
        self._stop = threading.Event()
        self._snapshot_arrived = threading.Event()
        self._threads: list[threading.Thread] = []
        self.error: BaseException | None = None
        self._header_retry_s = HEADER_RETRY_S / 2

    def start(self) -> None:
        self._threads = [threading.Thread(target=self._read, name="avard-web-sub", daemon=True)]
        if self.fit is not None:
            self._threads.append(threading.Thread(target=self._fit_loop, name="avard-web-fit",
                                                  daemon=True))
        for t in self._threads:
            t.start()

    def stop(self, timeout: float = 5.0) -> None:
        self._stop.set()
        self._snapshot_arrived.set()
        for t in self._threads:
            t.join(timeout)

    # ---- subscriber thread --------------------------------------------------------------

    def _read(self) -> None:
        try:
            self.sub.connect()  # subscribes, then asks for snapshot and header (logged if not)
            if self.history is not None:
                # live messages wait in the SUB socket's queue meanwhile (~15 min of them)
                self._replay_history(self.history)
            self.state.join(self.sub.header, self.sub.snapshot)
            if self.sub.snapshot:
                self._snapshot_arrived.set()
            next_header: float | None = None if self.sub.header else time.monotonic()
            while not self._stop.is_set():
                msg = self.sub.recv(0.2)
                if msg is not None:
                    self.state.update(msg, self.sub.stats)
                    if msg.record.get("kind") == "avar":
                        self._snapshot_arrived.set()
                    if msg.new_run and self.state.runs and len(self.state.runs) > 1:
                        next_header = 0.0  # a restarted service has a new header
                if next_header is not None and time.monotonic() >= next_header:
                    next_header = self._ask_header()
        except Exception as exc:  # any failure: the server reports it and exits 1
            log.exception("the subscriber thread stopped")
            self.error = exc
        finally:
            self.sub.close()

    def _replay_history(self, source: RecordingSource) -> None:
        """Temperatures, gaps and events of the service's recording, oldest first, as the one
        record source walks it (each run's header once, duplicates dropped)."""
        path = source.path
        t0, n = time.monotonic(), 0
        try:
            for rec in source.records():
                if self._stop.is_set():
                    return
                self.state.replay(rec)
                n += 1
        except (FormatError, OSError) as exc:
            log.warning("cannot read the history in %s: %s", path, exc)
        finally:
            self.state.history_done(n)
        log.info("read %d records of history from %s in %.1f s", n, path,
                 time.monotonic() - t0)

    def _ask_header(self) -> float | None:
        """Ask for the run header; None when done, else the time to ask again."""
        if self.state.header and self.state.header.get("run") == self.sub.stats.run:
            return None
        try:
            header = self.sub.request("header")
        except NetworkError as exc:
            # each try blocks this thread up to --timeout: back off to at most every 5 min
            self._header_retry_s = min(2 * self._header_retry_s, 300.0)
            log.info("no run header yet (next try in %.0f s): %s", self._header_retry_s, exc)
            return time.monotonic() + self._header_retry_s
        self._header_retry_s = HEADER_RETRY_S / 2
        self.state.join(header, None)
        return None

    # ---- fitter thread ------------------------------------------------------------------

    def _fit_loop(self) -> None:
        assert self.fit is not None
        last = -float("inf")
        while not self._stop.is_set():
            self._snapshot_arrived.wait()
            if self._stop.is_set():
                break
            wait = last + self.fit_interval_s - time.monotonic()
            if wait > 0 and self._stop.wait(wait):
                break
            self._snapshot_arrived.clear()
            snap: Snapshot | None = self.state.fit_due()
            if snap is None:
                continue
            last = time.monotonic()
            try:
                fits = self.fit(snap.data)
            except (ArithmeticError, ValueError) as exc:  # a failed fit must not end the page
                log.warning("fitting the snapshot of %d samples failed: %s", snap.n_samples,
                            exc)
                continue
            log.debug("fitted %d samples in %.2f s", snap.n_samples, time.monotonic() - last)
            # the one snapshot fit's ChannelFit: its terms, and the ADEV intervals it supports
            channel_fits = {k: v for k, v in fits.items() if hasattr(v, "allan")}
            self.state.set_fits({k: getattr(v, "fit", v) for k, v in fits.items()}, snap,
                                fit_intervals(snap.data, channel_fits) if channel_fits
                                else None)
