"""analyze's inner loops: the compiled module when it was built, numpy otherwise.

``_kernels.c`` holds each loop that a 60 h analyze spends its time in, beside the numpy path
that stays for installs without a compiler (and for counts and covariances):

* ``sumsq(x0, x1, x2)``: Σ_i D_i² with D_i = (x2_i − x1_i) − (x1_i − x0_i), for spans X_i,
  X_{i+m}, X_{i+2m} of a phase record the sum behind the fully overlapping AVAR (NIST SP
  1065 eq. 12). numpy needs three element-wise passes (``second_differences``) and a dot
  product; the loop reads the three spans once (1.3 → 0.37 ns per sample and τ, in the
  cache). ``sumsq_ring(ring, spans, out)`` is the same sums for every channel at many τ in
  one call, read straight from ``OverlappingAllan``'s ring (wrapped spans included, no
  copy). ``sumsq_mod`` adds the modified AVAR's running sums for ``noise_id.RnSums``
  (general path ``RnSums.push``).
* ``running_sum(y, offset, carry, out)``: the running sum of a (strided) column less an
  offset, numpy's subtract-and-cumsum bit for bit (``OverlappingAllan``'s ring).
* ``lag_sums(x, m, ref, out, old)``: the noise identification's sum and lag products of the
  non-overlapping averages, read straight from a running-sum span (``Lag1Ladder``'s
  ``push_spans``; general path: the averages made, then a row sum and dot products).
* ``power_sum(spec, k, out)``: the Welch spectrum's Σ |X|² over segments
  (``report.WelchAccumulator``).
* ``local_residual(y, half, out)``: the input screen's |sample − its neighbours' mean|
  (``core/io/screen/accel.py``; general path ``accel._local_residual``): one pass where numpy
  pads, sums cumulatively and subtracts.
* ``first_order(x, b0, b1, a1, z, out)``: a first-order IIR filter, scipy.signal.lfilter's
  operations in its order (explain's thermal lag, ``thermal_fit.lag_filter``; general path
  lfilter itself): explain then does not import scipy.signal, whose import (scipy.stats with
  it) cost more CPU than the filtering.

The extension is optional (setup.py): without a compiler avard installs and runs on the
numpy path, which gives the same results to rounding (``tests/core/test_kernels.py`` holds
each pair equal, and the OADEV built on each).

``compiled()`` is the module in use, or None. ``use_compiled(False)`` switches to numpy
(tests; ``AVARD_NO_C_KERNELS=1`` does it at import). A build whose ``API`` number is not this
module's is ignored (numpy is used).
"""

from __future__ import annotations

import os
from types import ModuleType

import numpy as np
from numpy.typing import NDArray

__all__ = ["API", "compiled", "second_differences", "switched_off", "use_compiled"]


#: The interface this module calls (``_kernels.API``): a module built from another version of
#: ``_kernels.c`` (a stale build left in a source tree) is not used.
API = 5


def switched_off() -> bool:
    """Whether ``AVARD_NO_C_KERNELS`` (set to anything but 0) switches the compiled code off:
    the one switch for every compiled path (these kernels, the recording scan's frame loop
    in core/io/rawscan.py), so one run shows the whole pure-Python-and-numpy path."""
    return os.environ.get("AVARD_NO_C_KERNELS", "0") not in ("", "0")


def _load() -> ModuleType | None:
    if switched_off():
        return None
    try:
        from avard.core.allan import _kernels  # type: ignore[attr-defined]
    except ImportError:  # not built (no compiler at install): the numpy path
        return None
    if getattr(_kernels, "API", None) != API:
        return None
    return _kernels


_C: ModuleType | None = _load()
_ACTIVE: ModuleType | None = _C


def compiled() -> ModuleType | None:
    """The compiled module when it is built and in use, else None."""
    return _ACTIVE


def use_compiled(on: bool) -> bool:
    """Use the compiled loops (when built) or numpy; returns whether they are now in use."""
    global _ACTIVE
    _ACTIVE = _C if on else None
    return _ACTIVE is not None


def second_differences(x0: NDArray, x1: NDArray, x2: NDArray,
                       out: NDArray | None = None) -> NDArray:
    """D = (x2 − x1) − x1 + x0 element-wise (into ``out`` when given): the numpy path's
    differences, whose Σ D² the compiled ``sumsq`` gives without storing them. Exact for
    int64 counts."""
    d = np.subtract(x2, x1, out=out)
    d -= x1
    d += x0
    return d
