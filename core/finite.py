"""Where a block of samples stops being finite, in one pass when it does not.

Shared by the record readers (``io.readers``) and the Allan accumulators' input check
(``allan.deviations.checked_block``), which each say in their own words what to do.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

__all__ = ["first_nonfinite_row"]


def first_nonfinite_row(a: NDArray) -> int | None:
    """Index of the first row (of a 1-D or 2-D float array) holding a NaN or an infinity, or
    None. A NaN or an infinity makes the sum non-finite, so a finite sum clears the block in
    one reduction; only a non-finite sum (or an overflowing one of huge values) is searched."""
    with np.errstate(over="ignore", invalid="ignore"):
        if math.isfinite(float(np.add.reduce(a, axis=None))):
            return None
    bad = ~np.isfinite(a)
    rows = bad.any(axis=1) if bad.ndim == 2 else bad
    return int(np.flatnonzero(rows)[0]) if rows.any() else None
