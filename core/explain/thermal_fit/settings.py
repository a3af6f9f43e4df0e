"""The thermal model's settings: the coupling test's level, the lag scan's size, the jackknife's
groups and the DS18B20's conversion and read times."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    pass


Z_TEMPERATURE = 5.0
#: The lag and channel trials the coupling search looks at, about (``alarm``'s budget).
SCAN_TRIALS = 50
#: Contiguous parts of the record for the jackknife standard error of the coefficient.
JACKKNIFE_GROUPS = 10
#: Most block means the lag scan runs on.
SCAN_POINTS = 1 << 15
#: DS18B20 conversion time (s): the temperature says nothing faster than this.
DS18B20_CONVERSION_S = 0.75
#: The lag filter's start state (``ThermalFit.signal``) is fitted over the record's first this
#: many lags: e^(−t/τ_L) is below 1e-8 at the end, and a random walk moves the level little.
START_FIT_LAGS = 20.0
#: The standard uncertainty (s) of when a logged temperature was true, which the lag's
#: interval carries beside its jackknife (``lag_interval``): a DS18B20 reading is the
#: temperature at some moment of its conversion, logged at the conversion's end or later,
#: and the record says not which; the lag is known to no better than half that window. It is
#: the same on every part of the record, so the parts' spread never shows it, and where the
#: record fixes the lag to a second or so it is as large as that spread.
READ_TIME_S = DS18B20_CONVERSION_S / 2
#: octave correlation of neighbouring AVAR estimates (fit.py: ≈ 0.5 for white noise)
_RHO = 0.5
