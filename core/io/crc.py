"""CRC-32 as zlib computes it, for the file readers: the compiled frame loop's
(``core/io/_framescan.c``: folded by carry-less multiplication where the CPU has it, zlib's
loop elsewhere) when it is built and switched on, else ``zlib.crc32``.

The first pass of ``avard analyze`` over a stored .npz checks its member's CRC-32: with
zlib's table loop that was a third of the cost of reading the file. The compiled loop is the
one the recording scan checks its frames with (``rawscan``); its own tests hold it equal to
zlib's on every length, alignment and start (tests/core/test_recording_fastscan.py).
"""

from __future__ import annotations

import zlib
from typing import Any

__all__ = ["FRAMESCAN_API", "crc32", "load_framescan"]

#: The interface of ``_framescan`` that avard calls: a module built from another
#: ``_framescan.c`` (a stale build left in a source tree) is not used.
FRAMESCAN_API = 3


def load_framescan() -> Any:
    """The compiled frame loop, or None: not built (no compiler at install, setup.py), or
    switched off by ``AVARD_NO_C_KERNELS`` (the one switch for every compiled path,
    core/allan/kernels.py); the general reader then does it all."""
    from avard.core.allan.kernels import switched_off

    if switched_off():
        return None
    try:
        from avard.core.io import _framescan as built  # type: ignore[attr-defined]
    except ImportError:
        return None
    return built


_built = load_framescan()
_compiled = (_built.crc32 if _built is not None
             and getattr(_built, "API", None) == FRAMESCAN_API else None)


def crc32(data: Any, start: int = 0) -> int:
    """``zlib.crc32(data, start)`` (data: any contiguous buffer), by the compiled loop when
    it is in use."""
    if _compiled is not None:
        return int(_compiled(data, start))
    return zlib.crc32(data, start)
