"""A temperature log's units: °C or °F judged from its readings (or said by ``--temperature-
units``), a log that never converted, °F columns converted before any rule."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from avard.core.io.screen.log_step import COARSE_PRINT, PRINT_TOL, _grid_share
from avard.core.io.screen.notes import Block, LogNote
from avard.core.io.screen.temperature import (
    DS18B20_ERROR_C,
    DS18B20_MAX_C,
    DS18B20_MIN_C,
    DS18B20_STEP_C,
    NOT_DS18B20,
    OFF_GRID_SHARE,
    POWER_ON_C,
)
from numpy.typing import NDArray

#: Readings on the DS18B20's °C grid whose median lies here (°F of a 10–40 °C room): a note
#: that °C is assumed.
FAHRENHEIT_ROOM = (50.0, 104.0)
#: A log in °F: at least this share of its distinct values on a DS18B20's grid in °F
#: (32 + 0.1125·k), of at least this many distinct values (and off the °C grid).
FAHRENHEIT_SHARE, FAHRENHEIT_MIN_VALUES = 0.8, 5
#: ... at a °F room's values, fewer suffice: a value lands on the °F grid within the printing
#: by chance about one time in nine, so three together about once in 800 (a stable room
#: dwells on few values)
FAHRENHEIT_MIN_VALUES_ROOM = 3
#: ``--temperature-units``: judged from the readings (auto), or said by the user: °C (never
#: refused as °F) or °F (converted to °C before any rule, the 85 °C and −127 °C values
#: included: 185 °F and −196.6 °F)
TEMPERATURE_UNITS = ("auto", "C", "F")


def temperature_units(text: str | None) -> str:
    """``--temperature-units``'s value: "auto", "C" or "F" (any case, a leading ° allowed);
    a ConfigError (one line) otherwise."""
    from avard.core.errors import ConfigError

    word = "auto" if text is None else str(text).strip().lstrip("°")
    for u in TEMPERATURE_UNITS:
        if word.lower() == u.lower():
            return u
    raise ConfigError(f"--temperature-units {text}: give auto (judged from the readings), "
                      "C or F (the logs' units, said for every temperature log)")


def units_note(values: NDArray[np.float64]) -> tuple[LogNote | None, str | None]:
    """(note, refusal) on a channel's readings as a whole, judged on its distinct values (a
    stable room's one value, which may sit on any grid by chance, counts once).

    A refusal needs positive evidence: most values (``FAHRENHEIT_SHARE``) on a DS18B20's grid
    *in °F* (32 + 1.8·0.0625·k = 32 + 0.1125·k °F, within ``PRINT_TOL``: a logger printing
    2 decimals) and under ``OFF_GRID_SHARE`` on its °C grid (multiples of 0.0625, within the
    same printing), with at least ``FAHRENHEIT_MIN_VALUES`` values (``…_ROOM`` at a °F room's
    values): a DS18B20 read in °F,
    refused for the thermal model (a coupling per K from °F is 1.8× too small, silently).
    Another logger's °C (a thermistor's 0.01 K, a 0.001 K logger) is on neither grid: off the
    °C grid it is taken as °C with a note (which says to convert it if it is °F: off both
    grids, °F cannot be told from a heated plate's °C); on the °C grid at a °F room's values
    (``FAHRENHEIT_ROOM``), a note that °C is assumed. A log printed to 0.1 (``COARSE_PRINT``)
    holds neither grid: at a °F room's values the note says that °C and °F cannot be told
    apart and °C is assumed (no refusal without evidence; a heated plate's °C is kept)."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v) & (v != DS18B20_ERROR_C) & (v != POWER_ON_C)
          & (v >= DS18B20_MIN_C) & (v <= DS18B20_MAX_C)]
    if len(v) < 8:
        return None, None
    u = np.unique(v)
    on = _grid_share(u, 0.0, DS18B20_STEP_C, PRINT_TOL)
    on_f = _grid_share(u, 32.0, 1.8 * DS18B20_STEP_C, PRINT_TOL)
    med = float(np.median(v))
    lo, hi = FAHRENHEIT_ROOM
    room_f = lo <= med <= hi
    least = FAHRENHEIT_MIN_VALUES_ROOM if room_f else FAHRENHEIT_MIN_VALUES
    coarse = bool(np.all(np.abs(u / COARSE_PRINT - np.rint(u / COARSE_PRINT)) < 1e-6))
    if coarse and room_f:
        return LogNote("units_unknown", (
            f"printed to {COARSE_PRINT:g}, which holds neither the DS18B20's 0.0625 K grid nor "
            f"its 0.1125 °F grid: median {med:.4g} is a {(med - 32) / 1.8:.3g} °C room in °F "
            f"or {med:.4g} °C, and this log cannot tell which; taken as °C (if it is °F, "
            "convert it: a coupling per K from °F is 1.8× too small)")), None
    if on < OFF_GRID_SHARE and on_f >= FAHRENHEIT_SHARE and len(u) >= least:
        why = (f"taken for °F: {100 * on_f:.0f} % of its {len(u)} distinct readings are on a "
               f"DS18B20's grid in °F (32 + 0.1125·k) and {100 * (1 - on):.0f} % off its "
               f"0.0625 K grid in °C (median {med:.4g}); a coupling per K from °F would be "
               "1.8× too small; not used (write the log in °C)")
        return LogNote("fahrenheit", (
            f"{100 * on_f:.0f} % of its distinct readings on a DS18B20's grid in °F "
            f"(32 + 0.1125·k), median {med:.4g}: a log in °F, not used by the thermal "
            "model")), why
    if on < OFF_GRID_SHARE:
        return LogNote("off_grid", (
            f"{100 * (1 - on):.0f} % of its distinct readings off the DS18B20's 0.0625 K grid "
            f"(another logger's?), median {med:.4g}: taken as °C; if it is °F, convert "
            "it")), None
    if room_f:
        return LogNote("celsius_assumed", (
            f"readings on the DS18B20's 0.0625 K grid with median {med:.4g}: taken as °C "
            f"(a DS18B20 logged in °F would read {lo:g}–{hi:g} too, but on its 0.1125 °F "
            "grid)")), None
    return None, None


def _never_converted(values: NDArray[np.float64]) -> LogNote | None:
    """The note on a log whose every reading is 85.0 °C (at least three): a DS18B20 that
    never converted a temperature, its power-on register read forever. The per-reading rule
    masks an 85 °C reading by its good neighbours, and such a log has none, so it passed
    as a room at 85 °C."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if len(v) < 3 or not np.all(v == POWER_ON_C):
        return None
    return LogNote("power_on_85", (
        f"85.0 °C throughout ({len(v)} readings): a DS18B20's power-on value, the sensor never "
        "converted a temperature; not used by the thermal model"))


def _celsius_evidence(values: NDArray[np.float64]) -> str:
    """For a log converted from °F as the user asked: what speaks against it, "" where
    nothing does. The evidence mirrors ``units_note``'s for °F: most distinct readings as
    given (before the conversion) on the DS18B20's 0.0625 K grid in °C and under half on
    its grid in °F, of at least ``FAHRENHEIT_MIN_VALUES`` values (a stable room's one value
    may sit on any grid by chance)."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)] * 1.8 + 32.0   # the readings as the log gave them
    v = v[(v != DS18B20_ERROR_C) & (v != POWER_ON_C)]
    u = np.unique(np.round(v, 9))
    if len(u) < FAHRENHEIT_MIN_VALUES:
        return ""
    on = _grid_share(u, 0.0, DS18B20_STEP_C, PRINT_TOL)
    on_f = _grid_share(u, 32.0, 1.8 * DS18B20_STEP_C, PRINT_TOL)
    if on < FAHRENHEIT_SHARE or on_f >= OFF_GRID_SHARE:
        return ""
    return (f"; its readings look like °C ({100 * on:.0f} % of its {len(u)} distinct readings "
            f"on the 0.0625 K grid, {100 * on_f:.0f} % on a DS18B20's grid in °F): if they are, "
            "a coupling per K from them is 1.8× too large")


def fahrenheit_columns(temperature_names: Sequence[str], units: str,
                       check_units: bool = True) -> list[int]:
    """The temperature columns ``--temperature-units F`` converts: every log the units rule
    judges (avard's own die temperature and a recording's logs are °C whatever is said: the
    daemon writes them); none unless ``units`` is "F"."""
    if units != "F" or not check_units:
        return []
    return [j for j, nm in enumerate(temperature_names) if nm not in NOT_DS18B20]


def to_celsius(blk: Block, columns: Sequence[int]) -> Block:
    """The block with its temperature ``columns`` converted from °F to °C (a copy)."""
    if not columns or blk[1] is None:
        return blk
    t0 = np.array(blk[1], dtype=float)
    tv = t0.reshape(len(blk[0]), -1)
    # to 1e-9 K: a DS18B20's °F reading converts back onto its 0.0625 K grid exactly (the
    # float residue of the division put every reading 1e-15 off it, and the thermal model
    # reads a DS18B20's rounding from that grid)
    tv[:, list(columns)] = np.round((tv[:, list(columns)] - 32.0) / 1.8, 9)
    return blk[0], t0, blk[2]
