"""Log lines journald can filter by level (``journalctl -p warning -u avard``).

Under systemd, stderr is a stream into the journal and ``$JOURNAL_STREAM`` names it
(``DEVICE:INODE`` of that stream). journald reads a ``<N>`` prefix on each line as the
syslog priority (sd-daemon(3)): the formatter writes one when stderr is that stream, and the
plain ``LEVEL name: message`` form on a terminal. No timestamps: journald adds its own.
"""

from __future__ import annotations

import logging
import os
from typing import TextIO

#: syslog priorities (RFC 5424) of the logging levels.
PRIORITY = {logging.CRITICAL: 2, logging.ERROR: 3, logging.WARNING: 4, logging.INFO: 6,
            logging.DEBUG: 7}


def priority_of(levelno: int) -> int:
    """The syslog priority for a logging level (a level between two named ones takes the
    priority of the named level below it)."""
    for level in sorted(PRIORITY, reverse=True):
        if levelno >= level:
            return PRIORITY[level]
    return 7


def stream_is_journal(stream: TextIO, journal_stream: str | None = None) -> bool:
    """True when ``stream`` is the journal stream ``$JOURNAL_STREAM`` names."""
    value = os.environ.get("JOURNAL_STREAM") if journal_stream is None else journal_stream
    if not value:
        return False
    try:
        dev, ino = (int(x) for x in value.split(":", 1))
        st = os.fstat(stream.fileno())
    except (ValueError, OSError, AttributeError):
        return False
    return (st.st_dev, st.st_ino) == (dev, ino)


class JournalFormatter(logging.Formatter):
    """``<N>name: message`` with N the syslog priority; every line of a multi-line message
    (a traceback) carries the prefix, since journald takes each line as its own entry."""

    def __init__(self) -> None:
        super().__init__("%(name)s: %(message)s")

    def format(self, record: logging.LogRecord) -> str:
        prefix = f"<{priority_of(record.levelno)}>"
        return "\n".join(prefix + line for line in super().format(record).split("\n"))


def formatter_for(stream: TextIO) -> logging.Formatter:
    """The journal's form when ``stream`` goes to the journal, the terminal's otherwise."""
    if stream_is_journal(stream):
        return JournalFormatter()
    return logging.Formatter("%(levelname)s %(name)s: %(message)s")
