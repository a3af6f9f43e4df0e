"""The latest published Allan snapshot for the ``snapshot`` request, fitted off the request path.

The publisher hands every ``avar`` record it sends to :meth:`SnapshotBoard.publish`; the
``snapshot`` request returns exactly that record (never an older one, never one the
subscribers have not been sent yet). Its noise fit (core/model/fit.py: NNLS and normal quantiles,
0.1–2 s on a Pi, and the module that loads scipy) is computed by the board's own thread, not by
the request thread, so ``status`` and ``recent`` are never queued behind a fit. The thread
fits on demand only: a ``snapshot`` request leases it the record current then and the next
:data:`FIT_LEASE_RECORDS` published (a client that asks at least that often finds its fit
ready); with no request since, it fits nothing, so one ``avard watch`` (it asks once, at join,
then fits the streamed records itself) costs a few fits, not one per snapshot for the rest of
the run. A service nobody asks never loads scipy. A reply carries the fit of its own record
when it is ready, else ``fit`` nil and ``fit_pending`` true.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from typing import Any

import numpy as np
from avard.core.allan.streaming import AllanSnapshot
from avard.core.analysis.separate import Separation
from avard.core.errors import AvardError

log = logging.getLogger(__name__)

Fit = Callable[[dict[str, Any]], dict[str, Any]]

#: Records fitted after the one current at a ``snapshot`` request, without another request.
FIT_LEASE_RECORDS = 3


class SnapshotBoard:
    """Holds the newest published ``avar`` record and its fit; one fitting thread."""

    def __init__(self, fit: Fit) -> None:
        self._fit = fit
        self._cond = threading.Condition()
        self._latest: dict[str, Any] | None = None
        self._separation: dict[str, Any] | None = None    # the last live separation seen
        self._fitted: dict[str, Any] | None = None    # the record the fit below belongs to
        self._fit_result: dict[str, Any] | None = None
        self._wanted = False
        self._published = 0     # records published so far: the latest is record _published
        self._lease_end = 0     # the last record a request leased a fit to
        self._stopping = False
        self._thread: threading.Thread | None = None
        self.fits = 0

    def publish(self, record: dict[str, Any]) -> None:
        """A new ``avar`` record went out on the wire. A rig's records carry the live
        ``separation`` only when it was computed anew: the board keeps the last one and
        replies with it beside a later snapshot."""
        with self._cond:
            self._latest = record
            self._published += 1
            if "separation" in record:
                self._separation = record["separation"]
            self._cond.notify_all()

    def reply(self) -> dict[str, Any] | None:
        """The latest published record with its fit if ready (None before the first)."""
        with self._cond:
            if not self._wanted:
                self._wanted = True
                self._start()
            self._lease_end = self._published + FIT_LEASE_RECORDS
            self._cond.notify_all()
            rec = self._latest
            if rec is None:
                return None
            ready = self._fitted is rec
            extra = {} if self._separation is None or "separation" in rec else \
                {"separation": self._separation}
            return dict(rec, fit=self._fit_result if ready else None, fit_pending=not ready,
                        **extra)

    def wait_fitted(self, timeout: float) -> bool:
        """Block until the latest record has its fit (tests, and clients in-process)."""
        with self._cond:
            return self._cond.wait_for(
                lambda: self._latest is not None and self._fitted is self._latest, timeout)

    def stop(self, timeout: float = 5.0) -> None:
        with self._cond:
            self._stopping = True
            self._cond.notify_all()
        if self._thread is not None:
            self._thread.join(timeout)

    def _start(self) -> None:
        if self._thread is None and not self._stopping:
            self._thread = threading.Thread(target=self._run, name="avard-fit", daemon=True)
            self._thread.start()

    def fit_due(self) -> bool:
        """Whether the thread has a record to fit: the latest is unfitted and within the
        lease of the last request."""
        with self._cond:
            return self._fit_due()

    def _fit_due(self) -> bool:
        return (self._latest is not None and self._fitted is not self._latest
                and self._published <= self._lease_end)

    def _run(self) -> None:
        while True:
            with self._cond:
                self._cond.wait_for(lambda: self._stopping or self._fit_due())
                if self._stopping:
                    return
                rec = self._latest
            assert rec is not None
            try:
                result = self._fit(rec)
            except Exception:   # a fit must never end the thread; the reply says no fit
                log.exception("fitting the snapshot failed")
                result = {}
            with self._cond:
                self._fitted, self._fit_result = rec, result
                self.fits += 1
                self._cond.notify_all()


ACCEL_CHANNELS = ("x", "y", "z")


def snapshot_fits(snap: AllanSnapshot, *, filter_corner_hz: float | None = None
                  ) -> dict[str, Any]:
    """The fit of each acceleration channel of a decoded Allan snapshot
    (``AllanSnapshot.from_dict``) with the channel's curve at the EDF the fit supports: a
    ``core.analysis.live_fit.ChannelFit`` per channel (``live_fit.fit_channel``: analyze's
    fit, its claims held to the decimated curve's margin, analyze's ``with_signal_edf``);
    {} without the analysis side.

    The one snapshot fit: the service's ``snapshot`` replies, ``avard watch`` and ``avard web``
    all call it, so they show the same terms. The ADXL355's digital low-pass sits at ODR/4
    (``filter_corner_hz`` defaults to the snapshot's rate / 4)."""
    try:
        from avard.core.analysis.live_fit import fit_channel
    except ImportError:  # the analysis side is optional for a watcher
        return {}
    out = {}
    # the rounding of the published counts, as analyze takes it from the recording's scale
    kw = {} if snap.lsb_mps2 is None else {"rounding_lsb": snap.lsb_mps2}
    for c, name in enumerate(snap.names):
        if name not in ACCEL_CHANNELS:
            continue
        try:
            out[name] = fit_channel(snap.channel(c), ci=snap.ci,
                                    filter_corner_hz=filter_corner_hz or snap.rate_hz / 4,
                                    **kw)
        except (AvardError, IndexError, ValueError, TypeError) as exc:
            log.debug("no fit for %s: %s", name, exc)
    return out


def fit_snapshot(snap: AllanSnapshot, *, filter_corner_hz: float | None = None
                 ) -> dict[str, Any]:
    """The noise fit (``avard.core.model.fit.NoiseFit``) of each acceleration channel of
    :func:`snapshot_fits`."""
    return {name: cf.fit for name, cf in
            snapshot_fits(snap, filter_corner_hz=filter_corner_hz).items()}


def fit_intervals(snap: AllanSnapshot, fits: dict[str, Any]) -> AllanSnapshot:
    """``snap`` with each fitted channel's EDF and bounds those of its fit
    (:func:`snapshot_fits`: analyze's ``with_signal_edf``), the others as published."""
    from dataclasses import replace

    edf, lo, hi = (np.array(a, dtype=float) for a in (snap.edf, snap.lo, snap.hi))
    for c, name in enumerate(snap.names):
        cf = fits.get(name)
        if cf is None or len(cf.allan.edf) != len(snap.tau):
            continue
        edf[:, c], lo[:, c], hi[:, c] = cf.allan.edf, cf.allan.lo, cf.allan.hi
    return replace(snap, edf=edf, lo=lo, hi=hi)


def fit_record(rec: dict[str, Any]) -> dict[str, Any]:
    """The service's fit of an ``avar`` record: :func:`snapshot_fits` as plain dicts, each
    channel's with the EDF and bounds of its curve the fit supports (``"edf"``, ``"lo"``,
    ``"hi"``: per τ of the snapshot, what analyze prints)."""
    snap = AllanSnapshot.from_dict(rec["snapshot"])
    return {name: {**cf.fit.to_dict(), "edf": np.asarray(cf.allan.edf).tolist(),
                   "lo": np.asarray(cf.allan.lo).tolist(),
                   "hi": np.asarray(cf.allan.hi).tolist()}
            for name, cf in snapshot_fits(snap).items()}


def separation_of(rec: dict[str, Any]) -> Separation | None:
    """The live separation of co-located sensors an ``avar`` record carries (its
    ``separation`` field, from daemon/service/separation_stage.py), decoded by the one
    decoder :meth:`Separation.from_dict` (also that of ``avard separate --json``); None when
    the record has none (a one-sensor service). ``FormatError`` when it does not decode."""
    sep = rec.get("separation")
    return None if sep is None else Separation.from_dict(sep)
