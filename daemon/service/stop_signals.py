"""SIGTERM and SIGHUP ending a command the way Ctrl-C does: through its ``finally`` blocks.

Python's default for SIGTERM and SIGHUP kills the process at once, so temporary files a
command cleans up in ``finally`` (simulate's hidden ``.NAME.npz.*.part``) stay behind when a
job scheduler, ``timeout`` or a closed terminal stops it. Inside :func:`stop_signals_unwind`
both raise :class:`StopSignal`, which unwinds the stack like ``KeyboardInterrupt``; the command
line turns it into the conventional exit status 128 + signal number.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType

STOP_SIGNALS = (signal.SIGTERM, signal.SIGHUP)


class StopSignal(BaseException):
    """Raised in the main thread when SIGTERM or SIGHUP arrives. A BaseException, as
    KeyboardInterrupt is, so that ``except Exception`` blocks do not swallow it."""

    def __init__(self, signum: int) -> None:
        super().__init__(f"stopped by {signal.Signals(signum).name}")
        self.signum = signum


def _raise(signum: int, frame: FrameType | None) -> None:
    raise StopSignal(signum)


@contextmanager
def stop_signals_unwind() -> Iterator[None]:
    """Within this block SIGTERM and SIGHUP raise StopSignal (main thread only: elsewhere
    Python cannot install handlers, and the block runs unchanged)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = {s: signal.signal(s, _raise) for s in STOP_SIGNALS}
    try:
        yield
    finally:
        for s, handler in old.items():
            signal.signal(s, handler)
