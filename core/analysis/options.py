"""The options of one analysis, spelled once: ``analyze``, ``explain`` (whose options extend
these), the service's fits and the commands all take a frozen :class:`AnalyzeOptions`."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from avard.core.errors import DataError
from avard.core.io.source import BLOCK

__all__ = ["DEFAULT_OPTIONS", "AnalyzeOptions", "FilterCorner"]

#: A low-pass corner in Hz, "auto" (the record's own: the ADXL355's ODR/4 when the record
#: says it is one) or None (not modelled: the bent shortest τ are left out instead).
FilterCorner = float | Literal["auto"] | None


@dataclass(frozen=True)
class AnalyzeOptions:
    """How to analyse a record.

    ``channels``: names or numbers of the accel channels to fit (None: all).
    ``filter_corner_hz``: see :data:`FilterCorner`.
    ``find_sinusoids``: look for lines in the Welch spectrum and fit them as fixed terms.
    ``estimator``: "oadev" (fully overlapping, default) or "cascade" (the service's).
    ``psd``: also each channel's one-sided PSD and the white density read from it.
    ``quantiles``, ``noise_id``: "stable32" reproduces Stable32's χ² quantiles and B1 rule.
    ``ci``: the confidence level of the fit's intervals (0.683: 68 %).
    ``block``: samples per block read (memory is a few blocks).
    ``screen``: read the record through the input screen (``core/io/screen/``: start-up
    glitches and shocks cut out as gaps, bad temperature readings masked, all said).
    ``temperature_units``: the temperature logs' units for the screen (``--temperature-units``):
    "auto" (judged from the readings: a DS18B20 log in °F refused), "C" or "F" (converted).
    ``workers``: processes for the OADEV of an .npz file, cut by time and added up exactly
    (``core/analysis/parallel.py``: the result is one worker's), or ``"auto"`` (1 on a
    machine under 2 GB or for records under 2**22 samples, else the cores, at most 4).
    """

    channels: tuple[str, ...] | None = None
    filter_corner_hz: FilterCorner = "auto"
    find_sinusoids: bool = True
    estimator: str = "oadev"
    psd: bool = False
    quantiles: str = "exact"
    noise_id: str = "avard"
    ci: float = 0.683
    block: int = BLOCK
    screen: bool = True
    workers: int | Literal["auto"] = 1
    temperature_units: str = "auto"

    def __post_init__(self) -> None:
        w = self.workers
        if w != "auto" and (not isinstance(w, int) or isinstance(w, bool) or w < 1):
            raise DataError(f"workers={w!r}: give a whole number of processes >= 1 or 'auto'")


#: analyze's defaults (what `avard analyze FILE` does).
DEFAULT_OPTIONS = AnalyzeOptions()
