"""One fit, live and offline (issue 24 item 2): the service's snapshot fit (the cascade,
core/analysis/live_fit.py) never claims a term analyze of the same samples does not, its
intervals agree with analyze's, and on minutes of data its long-τ terms are "not yet
resolved" rather than a tight interval."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from avard.core.allan.streaming import AllanSnapshot, StreamingAllan
from avard.core.analysis.engine import analyze
from avard.core.analysis.live_fit import is_not_resolved
from avard.core.analysis.options import AnalyzeOptions
from avard.core.analysis.signal_edf import with_signal_edf
from avard.core.io.source import open_record
from avard.core.model.fit.results import LONG_TAU_TERMS
from avard.core.sim.presets import make_config
from avard.core.sim.sim_io import write_npz
from avard.daemon.commands.watch import WatchView
from avard.daemon.service.snapshots import fit_record, snapshot_fits

AXES = ["x", "y", "z"]


def _claimed(fit) -> set[str]:
    return {k for k, t in fit.terms.items() if t.present and t.note is None}


LSB = make_config("quiet-lab").lsb_mps2


def _live(y: np.ndarray, rate: float, gap_at: int | None = None) -> dict:
    """The service's snapshot: the cascade fed one minute a block, with the feed's scale
    (the rounding LSB analyze reads from the record), as the service publishes it."""
    sa = StreamingAllan(3, rate, names=AXES)
    step = int(60 * rate)
    for i in range(0, y.shape[0], step):
        if gap_at is not None and i <= gap_at < i + step:
            sa.update(y[i:gap_at])
            sa.gap()
            sa.update(y[gap_at:i + step])
        else:
            sa.update(y[i:i + step])
    return {**sa.snapshot().to_dict(), "lsb_mps2": LSB}


def _record(tmp_path: Path, preset: str, minutes: float, seed: int,
            step: tuple[int, float] | None = None) -> tuple[Path, np.ndarray, float]:
    cfg = make_config(preset)
    path = tmp_path / f"{preset}-{seed}-{minutes}.npz"
    write_npz(path, cfg, minutes / 60, seed)
    if step is not None:  # a step in x mid-run (a knock on the plate)
        with np.load(path) as z:
            members = dict(z)
        members["accel"][step[0]:, 0] += step[1]
        np.savez(path, **members)
    with np.load(path) as z:
        return path, np.asarray(z["accel"]), cfg.rate_hz


def _compare(path: Path, y: np.ndarray, rate: float) -> list[tuple[str, str, float, float]]:
    """Asserts the live fit's claims ⊆ analyze's on every axis; returns, per term claimed by
    both, (axis, term, centre difference over analyze's half-width, ratio of the widths
    with each fit's Birge factor divided out)."""
    snap = AllanSnapshot.from_dict(_live(y, rate))
    live = snapshot_fits(snap)
    an = analyze(open_record(path), AnalyzeOptions())
    out = []
    for ax in AXES:
        lf, af = live[ax].fit, an.channels[ax].fit
        assert _claimed(lf) <= _claimed(af), (ax, _claimed(lf), _claimed(af))
        for t in _claimed(lf) & _claimed(af):
            le, ae = lf.terms[t], af.terms[t]
            half = (ae.hi - ae.lo) / 2
            birge = math.sqrt(max(lf.chi2_dof, 1.0)) / math.sqrt(max(af.chi2_dof, 1.0))
            out.append((ax, t, (le.value - ae.value) / half,
                        (le.hi - le.lo) / (ae.hi - ae.lo) / birge))
        # the snapshot's printed EDF is analyze's rule (signal_edf) on the live fit
        np.testing.assert_array_equal(live[ax].allan.edf,
                                      with_signal_edf(snap.channel(AXES.index(ax)), lf).edf)
    return out


@pytest.mark.parametrize(("seed", "axis"), [(0, "z"), (2, "y")])
def test_the_live_fit_claims_no_term_analyze_does_not(tmp_path, seed, axis) -> None:
    """55 min of quiet-lab (no K, no R, no B beyond the datasheet's): before the decimation
    guard the live fit claimed K on seed 0's z and B on seed 2's y where analyze of the same
    samples claimed neither (analyze: K and R 'not yet resolved' on z; K in place of B on
    y). Terms both claim agree: the centre within half of analyze's half-width, the widths
    (each fit's Birge factor √(χ²/dof) divided out) within 10 %. What separates the two is
    the cascade's decimation alone (differences every m/8 samples above m = 8, ≥ 98 % of
    the OADEV's EDF; the fits' options, the rounding LSB included, are analyze's)."""
    path, y, rate = _record(tmp_path, "quiet-lab", 55, seed)
    for _ax, _t, centre, width in _compare(path, y, rate):
        assert abs(centre) <= 0.5 and abs(width - 1) <= 0.1, (_ax, _t, centre, width)
    live = snapshot_fits(AllanSnapshot.from_dict(_live(y, rate)))[axis].fit
    guarded = [t for t, e in live.terms.items() if e.present and is_not_resolved(e.note)]
    assert guarded, "the record's near-threshold claim was expected to be held back"


def test_a_step_mid_run_is_claimed_live_only_where_analyze_claims_it(tmp_path) -> None:
    """A 2e-4 m/s² step in x at 20 of 41 min (a knock: a ramp- or walk-like rise at long
    τ): the live fit claims nothing of it analyze does not."""
    cfg = make_config("quiet-lab")
    path, y, rate = _record(tmp_path, "quiet-lab", 41, 3,
                            step=(int(20 * 60 * cfg.rate_hz), 2e-4))
    _compare(path, y, rate)


def test_minutes_of_quiet_lab_show_no_long_tau_term_with_an_interval(tmp_path) -> None:
    """The issue's case: from 37 to 55 min of quiet-lab y the live view showed R with
    ±1–8 % and 'target reached'. On 20 and 41 min of two seeds no K or R of x or y is
    claimed live, and watch shows any present one as 'not yet resolved', never reached."""
    for seed in (4, 5):
        _, y_full, rate = _record(tmp_path, "quiet-lab", 41, seed)
        for minutes in (20, 41):
            snap = _live(y_full[:int(minutes * 60 * rate)], rate)
            fits = snapshot_fits(AllanSnapshot.from_dict(snap))
            for ax in ("x", "y"):
                assert not (_claimed(fits[ax].fit) & set(LONG_TAU_TERMS)), (seed, minutes, ax)
            view = WatchView(clock=lambda: 0.0)
            record = fit_record({"snapshot": snap})
            view.set_snapshot({"snapshot": snap, "fit": record})
            # watch draws the ADEV bars the service's fit sent (analyze's EDF rule)
            for c, ax in enumerate(AXES):
                assert view.snapshot is not None
                np.testing.assert_array_equal(view.snapshot.hi[:, c], record[ax]["hi"])
                np.testing.assert_array_equal(fits[ax].allan.hi, record[ax]["hi"])
            channel = ""
            for line in view._render_fit()[0]:
                if line.startswith("  ") and line.strip().endswith(":"):
                    channel = line.strip()[:-1]
                # z carries the preset's warm-up, a real drift analyze claims as well
                elif channel in ("x", "y") and any(t in line for t in LONG_TAU_TERMS):
                    assert "reached" not in line and "[" not in line, line


def test_a_gap_mid_run_changes_no_claim_analyze_would_not_make(tmp_path) -> None:
    """A gap (the service lost 10 s of samples) in the snapshot: the live claims stay
    within analyze's of the unbroken record (the gap drops a few differences only)."""
    path, y, rate = _record(tmp_path, "quiet-lab", 41, 6)
    n_gap = int(10 * rate)
    at = int(25 * 60 * rate)
    kept = np.concatenate([y[:at], y[at + n_gap:]])
    snap = AllanSnapshot.from_dict(_live(kept, rate, gap_at=at))
    live = snapshot_fits(snap)
    an = analyze(open_record(path), AnalyzeOptions())
    for ax in AXES:
        assert _claimed(live[ax].fit) <= _claimed(an.channels[ax].fit), ax


@pytest.mark.slow
def test_the_first_hour_of_quiet_lab_claims_nothing_analyze_does_not(tmp_path) -> None:
    """The issue's case over the whole first hour: snapshots of quiet-lab at 10–60 min
    (the issue's 37 and 55 among them), seeds 0–3, every axis: the live claims ⊆ analyze's
    of the same samples (the samples cut from one record, analyze reading each cut as its
    own record). Measured: also every 5 min from 10 to 60, 132 axis fits, none."""
    cfg = make_config("quiet-lab")
    rate = cfg.rate_hz
    bad = []
    for seed in range(4):
        path, y_full, _ = _record(tmp_path, "quiet-lab", 60, seed)
        with np.load(path) as z:
            meta = {k: z[k] for k in z.files if k not in ("accel", "temperature_c")}
        for minutes in (10, 20, 30, 37, 45, 55, 60):
            y = y_full[:int(minutes * 60 * rate)]
            cut = tmp_path / "cut.npz"
            np.savez(cut, accel=y, **meta)
            live = snapshot_fits(AllanSnapshot.from_dict(_live(y, rate)))
            an = analyze(open_record(cut), AnalyzeOptions())
            for ax in AXES:
                extra = _claimed(live[ax].fit) - _claimed(an.channels[ax].fit)
                if extra:
                    bad.append((seed, minutes, ax, sorted(extra)))
    assert not bad, bad


@pytest.mark.parametrize("lsb", [-1.0, 0.0, float("nan"), "3.8e-5", [1], True])
def test_a_snapshot_with_a_bad_lsb_is_refused_in_one_line(lsb: object) -> None:
    """The snapshot's ``lsb_mps2`` enters the fit as its rounding term: one that is not a
    positive number is refused by the one decoder (FormatError naming it), never fitted."""
    from avard.core.errors import FormatError

    rng = np.random.default_rng(0)
    sa = StreamingAllan(3, 125.0, names=AXES)
    sa.update(rng.normal(size=(4096, 3)))
    with pytest.raises(FormatError, match="lsb_mps2"):
        AllanSnapshot.from_dict({**sa.snapshot().to_dict(), "lsb_mps2": lsb})
