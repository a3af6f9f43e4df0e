"""Signals noted by an async-signal-safe handler and acted on by the main loop.

A Python signal handler runs in the main thread between two bytecodes, wherever that thread
is: inside ``Event.wait`` holding the event's lock, inside the notifier's lock, or inside the
previous run of the same handler. A handler that takes a lock (``Event.set()`` does) deadlocks
there, and a burst of signals nests handlers until RecursionError. So the handler here does
one thing that takes no lock and cannot fail, noting the signal number in a preallocated flag
table; the C-level handler also writes the number to a socket (``signal.set_wakeup_fd``)
which the main loop's :meth:`SignalLatch.wait` selects on, so a signal wakes the loop at once.
Repeats of one signal before the loop looks coalesce into one flag (a burst of SIGHUPs is one
reload), and SIGTERM is never lost behind them: it has its own flag.
"""

from __future__ import annotations

import select
import signal
import socket
import threading
from collections.abc import Iterable
from types import FrameType


class SignalLatch:
    """A wake-up socket pair and a flag per signal; :meth:`wait` returns the signals seen."""

    def __init__(self) -> None:
        self._rx, self._tx = socket.socketpair()
        for s in (self._rx, self._tx):
            s.setblocking(False)
        self._flags = [False] * signal.NSIG   # preallocated: the handler only stores
        self._installed: dict[int, object] = {}
        self._old_wakeup_fd: int | None = None

    def _note(self, signum: int, _frame: FrameType | None) -> None:
        self._flags[signum] = True

    def install(self, signums: Iterable[int]) -> None:
        """Route ``signums`` here (main thread only, as ``signal.signal`` requires)."""
        if threading.current_thread() is not threading.main_thread():
            raise RuntimeError("signals can only be installed from the main thread")
        self._old_wakeup_fd = signal.set_wakeup_fd(self._tx.fileno(), warn_on_full_buffer=False)
        for s in signums:
            self._installed[s] = signal.signal(s, self._note)

    def wake(self) -> None:
        """Wake :meth:`wait` from another thread (a stop requested in code, not by signal)."""
        try:
            self._tx.send(b"\0")
        except (BlockingIOError, OSError):
            pass    # full: a wake-up is already pending; closed: nobody waits

    def wait(self, timeout_s: float) -> list[int]:
        """Sleep until a signal, a :meth:`wake` or ``timeout_s``; return the signals noted
        since the last call (each once, however often it came)."""
        if not self.pending():
            # poll, not select: select() refuses fds above 1024 (LimitNOFILE is higher)
            p = select.poll()
            p.register(self._rx, select.POLLIN)
            p.poll(max(0.0, timeout_s) * 1e3)
        while True:
            try:
                if not self._rx.recv(4096):
                    break
            except (BlockingIOError, OSError):
                break
        seen = [s for s in range(1, len(self._flags)) if self._flags[s]]
        for s in seen:
            self._flags[s] = False
        return seen

    def pending(self) -> bool:
        return any(self._flags)

    def close(self) -> list[int]:
        """Give the signals back to the handlers they had and close the sockets; returns the
        signals that had been installed."""
        installed = list(self._installed)
        if threading.current_thread() is threading.main_thread():
            for s, old in self._installed.items():
                signal.signal(s, old)  # type: ignore[arg-type]
            if self._old_wakeup_fd is not None:
                signal.set_wakeup_fd(self._old_wakeup_fd)
        self._installed.clear()
        self._old_wakeup_fd = None
        self._rx.close()
        self._tx.close()
        return installed


class WakingEvent(threading.Event):
    """A ``threading.Event`` whose ``set()`` from any thread also wakes a :class:`SignalLatch`
    (``Service.stop_requested``: a test or a thread that asks the loop to stop need not wait
    for its next tick). Never call ``set()`` from a signal handler: it takes a lock."""

    def __init__(self) -> None:
        super().__init__()
        self.latch: SignalLatch | None = None

    def set(self) -> None:
        super().set()
        latch = self.latch
        if latch is not None:
            latch.wake()
