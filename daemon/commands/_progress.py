"""The progress line the analysis commands write to a terminal while they read a record."""

from __future__ import annotations

import sys
from typing import Any

from avard.core.analysis.engine import ProgressFn


def progress_printer(stream: Any = None) -> ProgressFn | None:
    """A progress callback writing to stderr, or None when stderr is not a terminal."""
    stream = stream or sys.stderr
    if not getattr(stream, "isatty", lambda: False)():
        return None
    last = [-1]

    def show(done: int, total: int | None) -> None:
        pct = -1 if not total else int(100 * done / total)
        if pct == last[0] and total:
            return
        last[0] = pct
        msg = f"\ranalyze: {pct:3d} % ({done}/{total} samples read)" if total else \
            f"\ranalyze: {done} samples"
        stream.write(msg)
        if total and done >= total:
            stream.write("\n")
        stream.flush()

    return show
