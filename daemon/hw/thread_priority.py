"""Real-time scheduling for the FIFO reader thread, when the system allows it.

At 4 kHz the ADXL355 FIFO overflows 8 ms after the last drain. A normal (SCHED_OTHER) thread
on a busy host can be woken tens of milliseconds late (``python -m benchmarks driver`` measures
it), so the reader raises itself to SCHED_FIFO when it may. Linux scheduling policies are per
thread, so only the calling thread is raised: the recorder, publisher and Allan threads stay
ordinary and cannot starve the system. It needs CAP_SYS_NICE (or an RLIMIT_RTPRIO) and, under
systemd, ``RestrictRealtime=no``; without them it logs once and carries on.
"""

from __future__ import annotations

import logging
import os

log = logging.getLogger(__name__)


def raise_thread_priority(priority: int = 10) -> bool:
    """Put the calling thread under SCHED_FIFO at ``priority`` (1–99); True on success.

    A real-time thread that never blocks would lock up its CPU: call this only from a thread
    that sleeps between short pieces of work (the FIFO reader polls and sleeps)."""
    if not 1 <= priority <= 99:
        raise ValueError("SCHED_FIFO priority is 1..99")
    if not hasattr(os, "sched_setscheduler"):
        log.info("no sched_setscheduler on this platform; reader thread keeps normal priority")
        return False
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except PermissionError:
        log.warning("cannot raise the reader thread to SCHED_FIFO (needs CAP_SYS_NICE or "
                    "LimitRTPRIO, and RestrictRealtime=no under systemd); at high ODR a busy "
                    "host may then cause FIFO overruns")
        return False
    except OSError as exc:
        log.warning("SCHED_FIFO refused: %s", exc)
        return False
    log.info("reader thread runs SCHED_FIFO priority %d", priority)
    return True


def current_policy() -> str:
    """Name of the calling thread's scheduling policy (for status and logs)."""
    names = {getattr(os, n): n for n in ("SCHED_OTHER", "SCHED_FIFO", "SCHED_RR",
                                         "SCHED_BATCH", "SCHED_IDLE") if hasattr(os, n)}
    return names.get(os.sched_getscheduler(0), "unknown")
