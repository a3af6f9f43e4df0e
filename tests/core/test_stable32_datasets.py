"""avard against Stable32 on the public data sets whose runs print Stable32's OWN α with bounds.

PHASE.DAT's automatic runs print no bounds (tests/core/test_stable32_reference.py), so the
check "intervals with avard's own α within 1 % of Stable32's where Stable32's method applies"
is made here, on the raw records and Stable32 tables kept in allantools' source distribution
(fetched and cached by ``tests/support/allantools_sdist.py``, never copied into avard):

* Cs 5071A clock against an H-maser, 556 990 phase points at 1 s (decade runs);
* Keysight 53230A time-interval floor, 55 688 phase points at 1 s (octave runs);
* GPS 1PPS against an H-maser, 241 218 phase points at 1 s (decade ADEV, octave others);
* 10 MHz OCXO, 19 982 frequency points at 1 s (octave runs, Stable32 1.60);
* simulated pink (flicker) FM, 10 000 frequency points (octave OADEV, Stable32 1.60).

Per set and sigma type (ADEV, OADEV, HDEV, OHDEV: avard has no MDEV/TDEV/TOTDEV), at every
printed AF: the deviation and the count to the printed digits; avard's own α equal to
Stable32's wherever Stable32 uses the lag-1 ACF (≥ 30 averages: 185 rows, all equal) and the
bounds with it within 5e-4 of Stable32's there (1.3e-3 for the OCXO, whose printed
deviations carry Stable32's rounding); in the B1/R(n) range (4–29 averages) avard's own α
equal at 36 of 46 rows (all 19 non-overlapping ones), the bounds with it within 6e-4 there,
and the 10 others explained (``B1_AGREEMENT``).
"""

from __future__ import annotations

import functools
import json
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from avard.core.allan.deviations import AllanResult, allan_variance
from avard.core.allan.noise_id import Lag1Ladder
from avard.core.allan.overlapping import OverlappingAllan
from numpy.typing import NDArray

from ..support.allantools_sdist import reference_tests, reference_tests_or_skip
from .stable32 import Row, read_rows

LAG1_MIN_AVERAGES = 30  # Stable32 uses the lag-1 ACF with at least this many averages


@dataclass(frozen=True)
class DataSet:
    """One raw record and Stable32's runs of it (paths inside allantools' ``tests/``)."""

    folder: str
    data: str
    phase: bool  # phase in s (else fractional frequency, or Hz about ``nominal_hz``)
    tables: dict[str, str]  # avard kind ("hvar" = Stable32's non-overlapping HDEV) -> file
    nominal_hz: float = 0.0


SETS = {
    "cs5071a": DataSet("Cs5071A", "5071A_phase.txt.gz", True, {
        "avar": "adev_decade.txt", "oavar": "oadev_decade.txt",
        "hvar": "hdev_decade.txt", "ohvar": "ohdev_decade.txt"}),
    "53230a": DataSet("Keysight53230A_ti_noise_floor", "tic_phase.txt", True, {
        "oavar": "tic_oadev.txt", "hvar": "tic_hdev.txt", "ohvar": "tic_ohdev.txt"}),
    "gps": DataSet("gps", "gps_1pps_phase_data.txt.gz", True, {
        "avar": "stable32_ADEV_decade.txt", "oavar": "stable32_OADEV_octave.txt",
        "hvar": "stable32_HDEV_octave.txt", "ohvar": "stable32_OHDEV_octave.txt"}),
    "ocxo": DataSet("ocxo", "ocxo_frequency.txt", False, {
        "avar": "adev_octave.txt", "oavar": "oadev_octave.txt",
        "hvar": "hdev_octave.txt", "ohvar": "ohdev_octave.txt"}, nominal_hz=1e7),
    "pink": DataSet("pink_frequency", "pink_frequency.txt", False, {
        "oavar": "s32_oadev_octave.txt"}),
}
CASES = [(s, k) for s, d in SETS.items() for k in d.tables]

# Stable32 ran the OCXO octave runs on the frequencies divided by 10 MHz (values near 1.0,
# "Average = 1.000000e+00" in their header), so its sums lose digits: up to 1.8e-3 of the
# deviation (test_ocxo_octave_deviations_carry_stable32s_rounding). Its runs of the same
# record with the offset removed ("ocxo_frequency.003", every AF, no bounds) are the ones
# avard's deviations are checked against.
ROUNDED = {"ocxo"}
OFFSET_FREE = {"avar": "stable32_adev_alltau.txt", "oavar": "stable32_oadev_alltau.txt",
               "hvar": "stable32_hdev_alltau.txt", "ohvar": "stable32_ohdev_alltau.txt"}


@pytest.fixture(scope="session")
def tests_dir() -> Path:
    """allantools' ``tests/`` folder: skipped with the reason where it cannot be fetched,
    failed under CI (``CI=true``), failed always when the archive is not the pinned one."""
    return reference_tests_or_skip()


@functools.cache
def _rates(path: Path, phase: bool, nominal_hz: float) -> NDArray[np.float64]:
    raw = np.loadtxt(path, comments="#", dtype=np.float64)
    if phase:
        return np.diff(raw)  # fractional frequency at τ0 = 1 s
    return (raw - nominal_hz) / nominal_hz if nominal_hz else raw


def rates(tests: Path, name: str) -> NDArray[np.float64]:
    """The set's record as avard's input: fractional frequency samples at 1 Hz."""
    d = SETS[name]
    return _rates(tests / d.folder / d.data, d.phase, d.nominal_hz)


def table(tests: Path, name: str, kind: str) -> list[Row]:
    d = SETS[name]
    return read_rows(tests / d.folder / d.tables[kind])


@dataclass(frozen=True)
class Columns:
    """avard's result at a list of AFs (one channel)."""

    n: NDArray[np.int64]
    dev: NDArray[np.float64]
    lo: NDArray[np.float64]
    hi: NDArray[np.float64]
    alpha: NDArray[np.float64]
    edf: NDArray[np.float64]

    def take(self, ks: list[int]) -> Columns:
        return Columns(*(getattr(self, f)[ks] for f in ("n", "dev", "lo", "hi", "alpha", "edf")))

    @classmethod
    def of(cls, parts: list[AllanResult]) -> Columns:
        return cls(*(np.concatenate([getattr(r, f) for r in parts]) for f in
                     ("n", "dev", "dev_lo", "dev_hi", "alpha", "edf")))


def run(y: NDArray[np.float64], kind: str, ms: list[int], alpha: list[int] | None = None,
        **kw) -> Columns:
    """avard's batch estimator for a Stable32 sigma type at the AFs ``ms`` (own α unless
    ``alpha`` gives one per AF). Stable32's HDEV is avard's "phvar" with stride m (a stride
    longer than every m is clipped to m). The identification is "powerlaw" unless ``kw``
    names another: every power-law type, as the clocks behind these runs hold (the default
    "avard" reads rate data, where PM types exist only as LSB rounding)."""
    kw.setdefault("noise_id", "powerlaw")
    if kind == "hvar":
        kind, kw = "phvar", {**kw, "stride": max(ms)}
    return Columns.of([allan_variance(y, 1.0, ms, kind=kind, alpha=alpha, **kw)])


def printed(v: float) -> float:
    """v as Stable32 prints it (5 significant digits)."""
    return float(f"{v:.4e}")


def worst_bound_error(res: Columns, rows: list[Row]) -> float:
    lo = np.abs(res.lo / np.array([r.lo for r in rows]) - 1)
    hi = np.abs(res.hi / np.array([r.hi for r in rows]) - 1)
    return float(max(lo.max(), hi.max())) if rows else 0.0


@pytest.mark.parametrize(("name", "kind"), CASES)
def test_deviation_and_count_to_the_printed_digits(tests_dir: Path, name: str,
                                                   kind: str) -> None:
    """Every row: the count equal, the deviation within 5e-5 relative (Stable32 prints 5
    digits; measured worst 4.4e-5). For the OCXO, every row of the offset-free runs."""
    rows = table(tests_dir, name, kind)
    y = rates(tests_dir, name)
    assert list(run(y, kind, [r.af for r in rows]).n) == [r.n for r in rows]
    if name in ROUNDED:
        rows = read_rows(tests_dir / SETS[name].folder / OFFSET_FREE[kind])
    res = run(y, kind, [r.af for r in rows])
    assert list(res.n) == [r.n for r in rows]
    np.testing.assert_allclose(res.dev, [r.dev for r in rows], rtol=5e-5)


@pytest.mark.parametrize("kind", SETS["ocxo"].tables)
def test_ocxo_octave_deviations_carry_stable32s_rounding(tests_dir: Path, kind: str) -> None:
    """Why the OCXO octave deviations are up to 0.18 % off avard's: they are the plain
    double-precision arithmetic on the frequencies divided by 10 MHz (values near 1.0),
    reproduced here to 2.5e-5 at every AF: ADEV and HDEV from sequential sums of m
    frequencies, OADEV and OHDEV from the phase summed over the whole record."""
    f = np.loadtxt(tests_dir / "ocxo" / "ocxo_frequency.txt", comments="#") / 1e7
    x = np.concatenate([[0.0], np.cumsum(f)])  # the phase Stable32 sums from the ~1.0 data
    d = 2 if kind in ("avar", "oavar") else 3
    rows = table(tests_dir, "ocxo", kind)
    plain = []
    for r in rows:
        m = r.af
        if kind in ("avar", "hvar"):  # non-overlapping: sequential sums of m frequencies
            avg = np.array([np.cumsum(f[i * m:(i + 1) * m])[-1] for i in range(f.size // m)])
            diffs = np.diff(avg / m, n=d - 1)
        else:  # overlapping: d-th differences of the summed phase at lag m
            diffs = (x[2 * m:] - 2 * x[m:-m] + x[:-2 * m] if d == 2 else
                     x[3 * m:] - 3 * x[2 * m:-m] + 3 * x[m:-2 * m] - x[:-3 * m]) / m
        plain.append(np.sqrt(np.mean(diffs ** 2) / (2 if d == 2 else 6)))
    ref = np.array([r.dev for r in rows])
    np.testing.assert_allclose(plain, ref, rtol=2.5e-5)
    ours = run(rates(tests_dir, "ocxo"), kind, [r.af for r in rows]).dev
    assert 1e-4 < np.max(np.abs(ours / ref - 1)) < 2e-3  # the rounding is real, and small


@pytest.mark.parametrize(("name", "kind"), CASES)
def test_own_alpha_and_bounds_where_stable32_uses_the_lag1_acf(tests_dir: Path, name: str,
                                                              kind: str) -> None:
    """≥ 30 averages: avard's OWN α is Stable32's at every AF, and its bounds with it are
    Stable32's within 1.3e-3 (measured worst 1.2e-3, OCXO OHDEV, where Stable32's deviation
    itself carries 1e-3 of rounding; 4.8e-4 elsewhere), far inside the 1 % asked."""
    y = rates(tests_dir, name)
    rows = [r for r in table(tests_dir, name, kind) if y.size // r.af >= LAG1_MIN_AVERAGES]
    assert rows
    res = run(y, kind, [r.af for r in rows])
    assert [int(a) for a in res.alpha] == [r.alpha for r in rows]
    limit = 1.3e-3 if name in ROUNDED else 5e-4
    assert worst_bound_error(res, rows) < limit


# Measured agreement in the B1/R(n) range (4 to 29 averages): (rows where avard's own α is
# Stable32's, rows). The 10 others are the overlapping runs' Cs AF 20000, 40000, 100000 (27, 13,
# 5 averages: Stable32 0, avard -1, which Stable32's own ADEV and HDEV runs print from the
# same averages) and OCXO AF 2048, 4096 (9, 4: Stable32 0, avard -1): Stable32 takes B1's
# expected values at N = its count of overlapping differences, which avard does not copy
# (test_stable32s_overlapping_alpha_is_b1_at_its_count_of_differences).
B1_AGREEMENT = {
    ("cs5071a", "avar"): (3, 3), ("cs5071a", "oavar"): (0, 3),
    ("cs5071a", "hvar"): (3, 3), ("cs5071a", "ohvar"): (0, 3),
    ("53230a", "oavar"): (3, 3), ("53230a", "hvar"): (3, 3), ("53230a", "ohvar"): (3, 3),
    ("gps", "avar"): (3, 3), ("gps", "oavar"): (3, 3),
    ("gps", "hvar"): (3, 3), ("gps", "ohvar"): (3, 3),
    ("ocxo", "avar"): (2, 2), ("ocxo", "oavar"): (1, 3),
    ("ocxo", "hvar"): (2, 2), ("ocxo", "ohvar"): (1, 3),
    ("pink", "oavar"): (3, 3),
}


@pytest.mark.parametrize(("name", "kind"), CASES)
def test_alpha_and_bounds_in_the_b1_range(tests_dir: Path, name: str, kind: str) -> None:
    """< 30 averages (Stable32's B1/R(n) method): α agreement at its measured count, and the
    bounds with avard's own α Stable32's within 6e-4 where the α agree (2.4e-3 for the OCXO,
    whose printed deviations carry Stable32's rounding). With Stable32's α the bounds are
    its printed ones within the same at every row: where they differ more with avard's own
    (up to 13 %), α alone differs."""
    y = rates(tests_dir, name)
    every = table(tests_dir, name, kind)
    # on the run's whole grid: below 10 (8) averages the α of the next shorter τ is kept
    full = run(y, kind, [r.af for r in every])
    b1 = [k for k, r in enumerate(every) if y.size // r.af < LAG1_MIN_AVERAGES]
    rows = [every[k] for k in b1]
    agree, total = B1_AGREEMENT[(name, kind)]
    assert len(rows) == total
    ours = [int(full.alpha[k]) for k in b1]
    same = [k for k, a, r in zip(b1, ours, rows, strict=True) if a == r.alpha]
    assert len(same) >= agree, [(r.af, a, r.alpha) for a, r in zip(ours, rows, strict=True)]
    limit = 2.4e-3 if name in ROUNDED else 6e-4
    assert worst_bound_error(full.take(same), [every[k] for k in same]) < limit
    theirs = run(y, kind, [r.af for r in rows], alpha=[r.alpha for r in rows],
                 quantiles="stable32")
    assert worst_bound_error(theirs, rows) < limit


@pytest.mark.parametrize(("name", "kind"), CASES)
def test_alpha_and_bounds_by_stable32s_rule_in_the_b1_range(tests_dir: Path, name: str,
                                                          kind: str) -> None:
    """``noise_id="stable32"`` (``--noise-id stable32``): avard's own α is Stable32's at every
    B1 row of every run, the 10 overlapping rows where the default rule differs included, and
    the bounds with it are Stable32's within the limits above (1 % asked) at every row."""
    y = rates(tests_dir, name)
    every = table(tests_dir, name, kind)
    full = run(y, kind, [r.af for r in every], noise_id="stable32")
    b1 = [k for k, r in enumerate(every) if y.size // r.af < LAG1_MIN_AVERAGES]
    rows = [every[k] for k in b1]
    assert [int(full.alpha[k]) for k in b1] == [r.alpha for r in rows]
    limit = 2.4e-3 if name in ROUNDED else 6e-4
    assert worst_bound_error(full.take(b1), rows) < limit


@pytest.mark.parametrize(("name", "kind", "af"), [
    ("cs5071a", "oavar", 20000), ("cs5071a", "oavar", 40000), ("cs5071a", "ohvar", 20000),
    ("cs5071a", "ohvar", 40000), ("ocxo", "oavar", 2048), ("ocxo", "ohvar", 2048)])
def test_stable32s_overlapping_alpha_is_b1_at_its_count_of_differences(
        tests_dir: Path, name: str, kind: str, af: int) -> None:
    """Why avard's α differs from Stable32's at these overlapping rows (8 to 29 averages; the
    others of B1_AGREEMENT keep these): the same B1 of the same averages, compared with the
    expected values at N = Stable32's count of overlapping differences ('#') instead of the
    averages, gives Stable32's α; avard's (at N = averages) is Stable32's ADEV/HDEV α there
    (one noise type redder). avard keeps N = averages: see deviations.alphas_from_ladders."""
    y = rates(tests_dir, name)
    (row,) = [r for r in table(tests_dir, name, kind) if r.af == af]
    n = y.size // af
    assert 8 <= n < LAG1_MIN_AVERAGES
    d = 2 if kind == "oavar" else 3
    ladder = Lag1Ladder(1, dmax=d, cross=False)
    ladder.push(y[:n * af].reshape(n, af).sum(axis=1))
    assert int(ladder.alpha(2 - 2 * d, n_terms=row.n)[0]) == row.alpha
    ours = int(ladder.alpha(2 - 2 * d)[0])
    assert ours == int(run(y, kind, [af]).alpha[0]) == row.alpha - 1


@pytest.mark.parametrize("name", [s for s, d in SETS.items() if "oavar" in d.tables])
def test_the_analyze_stream_is_the_batch_oadev(tests_dir: Path, name: str) -> None:
    """``OverlappingAllan`` told the record length (what ``avard analyze`` runs on a file):
    the batch estimator's α, EDF and bounds at every AF of Stable32's OADEV run."""
    rows = table(tests_dir, name, "oavar")
    ms = [r.af for r in rows]
    y = rates(tests_dir, name)
    acc = OverlappingAllan(1, 1.0, ms, n_total=y.size)
    for i in range(0, y.size, 65536):
        acc.update(y[i:i + 65536])
    got = acc.result(noise_id="powerlaw")
    batch = run(y, "oavar", ms)
    np.testing.assert_array_equal(got.alpha, batch.alpha)
    np.testing.assert_allclose(got.edf, batch.edf, rtol=1e-12)
    np.testing.assert_allclose(got.dev, batch.dev, rtol=1e-12)
    np.testing.assert_allclose([got.dev_lo, got.dev_hi], [batch.lo, batch.hi], rtol=1e-12)


def test_analyze_cli_on_pink_noise(tests_dir: Path, tmp_path: Path) -> None:
    """`avard analyze pink.csv --rate 1 --json --noise-id powerlaw` on the pink FM record:
    its octave grid is Stable32's (AF 1 to 2048), the OADEV to the printed digits, α
    Stable32's at every AF (lag-1 ACF to 256, B1 at 512 and 1024, kept from 1024 at 2048
    with 4 averages), the bounds within 5e-4 at every AF, and α, EDF and bounds the Python API's."""
    y = rates(tests_dir, "pink")
    rows = table(tests_dir, "pink", "oavar")
    p = tmp_path / "pink.csv"
    p.write_text("y\n" + "".join(f"{float(v)!r}\n" for v in y))
    out = subprocess.run([sys.executable, "-m", "avard.daemon.cli", "analyze", str(p),
                          "--rate", "1", "--json", "--noise-id", "powerlaw"],
                         capture_output=True, text=True, check=True)
    ch = json.loads(out.stdout)["channels"]["y"]
    assert ch["estimator"] == "oadev"
    assert [int(t) for t in ch["tau_s"]] == [r.af for r in rows]
    np.testing.assert_allclose(ch["adev"], [r.dev for r in rows], rtol=5e-5)
    assert ch["alpha"] == [r.alpha for r in rows]
    np.testing.assert_allclose([ch["adev_lo"], ch["adev_hi"]],
                               [[r.lo for r in rows], [r.hi for r in rows]], rtol=5e-4)
    api = run(y, "oavar", [r.af for r in rows])
    assert ch["alpha"] == [int(a) for a in api.alpha]
    np.testing.assert_allclose(ch["edf"], api.edf, rtol=1e-12)
    np.testing.assert_allclose([ch["adev_lo"], ch["adev_hi"]], [api.lo, api.hi], rtol=1e-12)


def print_table() -> None:
    """The table of docs/analysis.md ("Checked against Stable32"), measured:
    ``.venv/bin/python -m tests.core.test_stable32_datasets``."""
    names = {"avar": "ADEV", "oavar": "OADEV", "hvar": "HDEV", "ohvar": "OHDEV"}

    def worst(res: Columns, rows: list[Row], ks: list[int]) -> str:
        return f"{worst_bound_error(res.take(ks), [rows[k] for k in ks]):.1e}" if ks else "–"

    tests = reference_tests()
    for name, kind in CASES:
        y = rates(tests, name)
        rows = table(tests, name, kind)
        full = run(y, kind, [r.af for r in rows])
        ref = read_rows(tests / SETS[name].folder / OFFSET_FREE[kind]) if name in ROUNDED \
            else rows
        dev = run(y, kind, [r.af for r in ref]).dev / np.array([r.dev for r in ref]) - 1
        lag = [k for k, r in enumerate(rows) if y.size // r.af >= LAG1_MIN_AVERAGES]
        b1 = [k for k in range(len(rows)) if k not in lag]
        same = [k for k in b1 if int(full.alpha[k]) == rows[k].alpha]
        extra = f" (+{len(ref)})" if name in ROUNDED else ""
        print(f"| {name} | {names[kind]} | {len(rows)}{extra} | {np.abs(dev).max():.1e} | "
              f"{sum(int(full.alpha[k]) == rows[k].alpha for k in lag)}/{len(lag)} | "
              f"{len(same)}/{len(b1)} | {worst(full, rows, lag)} | {worst(full, rows, same)} | "
              f"{worst(full, rows, list(range(len(rows))))} |")


if __name__ == "__main__":
    print_table()


def test_analyze_cli_noise_id_stable32(tests_dir: Path, tmp_path: Path) -> None:
    """`avard analyze ocxo.csv --rate 1 --json --noise-id stable32`: the JSON names the rule,
    and its α, EDF and bounds are the Python API's under it at every τ of analyze's grid;
    the "powerlaw" run takes at m = 2048 and 4096 (9 and 4 averages) the noise type one
    redder, as Stable32's ADEV run does
    (test_stable32s_overlapping_alpha_is_b1_at_its_count_of_differences)."""
    y = rates(tests_dir, "ocxo")
    p = tmp_path / "ocxo.csv"
    p.write_text("y\n" + "".join(f"{float(v)!r}\n" for v in y))

    def cli(*extra: str) -> dict:
        out = subprocess.run([sys.executable, "-m", "avard.daemon.cli", "analyze", str(p),
                              "--rate", "1", "--json", *extra],
                             capture_output=True, text=True, check=True)
        return json.loads(out.stdout)["channels"]["y"]

    theirs, ours = cli("--noise-id", "stable32"), cli("--noise-id", "powerlaw")
    assert theirs["noise_id"] == "stable32" and ours["noise_id"] == "powerlaw"
    assert "noise_id" not in cli()  # the default rule, as the default quantiles, unnamed
    tau = [int(t) for t in theirs["tau_s"]]
    api = allan_variance(y, 1.0, tau, kind="oavar", noise_id="stable32")
    assert theirs["alpha"] == [float(a) for a in api.alpha]
    np.testing.assert_allclose(theirs["edf"], api.edf, rtol=1e-12)
    np.testing.assert_allclose([theirs["adev_lo"], theirs["adev_hi"]],
                               [api.dev_lo, api.dev_hi], rtol=1e-12)
    differ = [t for t, a, b in zip(tau, theirs["alpha"], ours["alpha"], strict=True) if a != b]
    assert differ == [2048, 4096]
    bad = subprocess.run([sys.executable, "-m", "avard.daemon.cli", "analyze", str(p),
                          "--rate", "1", "--noise-id", "bogus"], capture_output=True, text=True)
    assert bad.returncode == 2 and "Traceback" not in bad.stderr
