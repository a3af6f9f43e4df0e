"""Stable32's published results for PHASE.DAT, read from the tables beside this module.

PHASE.DAT (shipped with Stable32) is the NBS14 1000-point frequency set integrated to 1001
phase points, so avard's rate input is ``tests.core.test_allan.nbs14_1000()``. The tables are
Stable32's own output as kept in allantools' test suite (the path is in each file's first
line); they are reference data, copied row for row, with no code.

Two kinds of run are kept, and they must not be mixed up:

* ``phase_dat_{adev,oadev,hdev,ohdev}_all.txt`` (Stable32 1.53, every AF to N/4 or so): the
  noise type *identified* by Stable32 at each AF (Alpha column), no bounds (printed as 0).
* ``phase_dat_octave_fixed_white_fm.txt`` (Stable32 1.60, octaves): bounds at 68.3 %, Alpha
  0 (white FM) at every AF. Whether the run fixed the noise type or identified it, the table
  cannot tell: identified as Stable32 does (lag-1 ACF to AF 32, B1 at 64, and at 128, 7
  averages, the α of 64 kept: ``noise_id.HOLD_BELOW_AVERAGES``) it is 0 at every AF too, and
  avard's own α gives these bounds. For "fixed": allantools names its file of the 1.60 MTOT
  run ``..._alpha0`` and computes every bound of these tables with alpha = 0, and Stable32's
  automatic MTOT and HTOT octave runs (allantools tests/phasedat/phase_dat_mtotdev_octave.txt,
  phase_dat_htotdev_octave.txt) give 1 at AF 128 (total estimators, whose identification
  avard does not have). The name of the file keeps the first reading.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

HERE = Path(__file__).parent

# avard's kind for each Stable32 sigma type; "hvar" is avard's "phvar" with stride m
ALL_TAU = {"avar": "phase_dat_adev_all.txt", "oavar": "phase_dat_oadev_all.txt",
           "hvar": "phase_dat_hdev_all.txt", "ohvar": "phase_dat_ohdev_all.txt"}
OCTAVE_FIXED_WHITE_FM = "phase_dat_octave_fixed_white_fm.txt"
N_FREQ = 1000  # frequency points of PHASE.DAT (1001 phase points)

# Stable32's automatic Alpha at AF 128 in its MTOT and HTOT octave runs of PHASE.DAT (the
# files named in the module docstring; avard has neither estimator, only this column is used)
AUTO_ALPHA_AT_128 = {"mtot": 1, "htot": 1}


@dataclass(frozen=True)
class Row:
    """One line of a Stable32 table: averaging factor, number of differences ('#'), Alpha,
    and the deviation with its bounds (lo = hi = 0 where the run computed none)."""

    af: int
    n: int
    alpha: int
    lo: float
    dev: float
    hi: float


def _row(fields: list[str]) -> Row:
    af, _tau, n, alpha, lo, dev, hi = fields
    return Row(int(af), int(n), int(alpha), float(lo), float(dev), float(hi))


def read_rows(path: Path) -> list[Row]:
    """The rows of a table file in Stable32's column order (AF, τ, #, Alpha, Min σ, σ,
    Max σ), comment lines left out: these files and allantools' own alike."""
    lines = path.read_text().splitlines()
    return [_row(s.split()) for s in lines if s.strip() and not s.lstrip().startswith("#")]


def all_tau(kind: str) -> list[Row]:
    """The automatic-identification run of one sigma type, every AF in Stable32's order."""
    return read_rows(HERE / ALL_TAU[kind])


def octave_fixed_white_fm() -> dict[str, list[Row]]:
    """The octave runs with bounds (noise type fixed at white FM), per avard kind."""
    out: dict[str, list[Row]] = {}
    for s in (HERE / OCTAVE_FIXED_WHITE_FM).read_text().splitlines():
        if s.strip() and not s.startswith("#"):
            kind, *fields = s.split()
            out.setdefault(kind, []).append(_row(fields))
    return out


def averages(af: int) -> int:
    """Non-overlapping averages of AF samples in PHASE.DAT: the count Stable32's choice of
    method goes by (lag-1 ACF with >= 30, B1 and R(n) below)."""
    return N_FREQ // af
