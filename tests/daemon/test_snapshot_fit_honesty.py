"""The live fit claims no more than the data hold (issue 24): on 41 min of a quiet-lab run
(no ramp, no rate random walk; a 30-minute air-conditioning cycle coupled through the
plate's temperature), the service's snapshot fit read a rate ramp R ≈ 1.8e-7 m/s³ with a
±2 % interval from the one longest τ of its fit, and drew a model 6× the measured ADEV at
τ = 1049 s. The snapshot fit is the one fit: analyze of the same samples with the service's
estimator gives the same terms, values and notes."""

from __future__ import annotations

import numpy as np
import pytest
from avard.core.allan.streaming import AllanSnapshot, StreamingAllan
from avard.core.analysis.engine import analyze
from avard.core.analysis.formats import format_table
from avard.core.analysis.options import AnalyzeOptions
from avard.core.io.source import open_record
from avard.core.model.fit.results import NOT_RESOLVED
from avard.core.sim.presets import make_config
from avard.core.sim.simulate import SensorSimulator
from avard.daemon.commands.watch import WatchView
from avard.daemon.service.snapshots import fit_record, fit_snapshot


def quiet_lab(minutes: float, seed: int) -> tuple[np.ndarray, float]:
    config = make_config("quiet-lab")
    sim = SensorSimulator(config, seed=seed)
    n = int(minutes * 60 * config.rate_hz)
    chunk = sim.next(n)
    return chunk.counts.astype(np.float64) * config.lsb_mps2, config.rate_hz


def test_a_ramp_seen_only_at_the_longest_tau_is_not_yet_resolved(tmp_path) -> None:
    y, rate = quiet_lab(41, seed=4)
    sa = StreamingAllan(3, rate, names=["x", "y", "z"])
    step = int(60 * rate)
    for i in range(0, y.shape[0], step):  # the service's blocks: one snapshot a minute
        sa.update(y[i:i + step])
    snap = sa.snapshot().to_dict()
    fits = fit_snapshot(AllanSnapshot.from_dict(snap))
    ramp = fits["x"].terms["rate_ramp"]
    # the presence test passes (z > 2.33), but without its longest τ it does not
    assert ramp.present and ramp.z is not None and ramp.z > 2.33
    assert ramp.note == NOT_RESOLVED
    # and its interval is no narrower than the test's evidence (±θ/z on θ = R²), not ±2 %
    assert ramp.lo is not None and ramp.hi is not None and ramp.value is not None
    assert ramp.hi - ramp.lo > ramp.value / ramp.z
    # no long-τ term of any axis is claimed resolved on the strength of one point
    for fit in fits.values():
        for name in ("rate_ramp", "rate_random_walk"):
            est = fit.terms[name]
            if est.present and est.note is None:
                assert est.z is not None and est.z > 2.33
    # one fit: analyze of the same samples with the service's estimator says the same
    path = tmp_path / "ql.npz"
    np.savez(path, accel=y, rate_hz=rate, axes=np.array(["x", "y", "z"]))
    an = analyze(open_record(path), AnalyzeOptions(estimator="cascade", filter_corner_hz=rate / 4,
                                                   find_sinusoids=False, channels=("x",)))
    off = an.channels["x"].fit.terms
    table = format_table(an)  # analyze's table says it under the term's line
    assert table.count(NOT_RESOLVED) == sum(e.note == NOT_RESOLVED for e in off.values()) >= 1
    for name, est in fits["x"].terms.items():
        assert (off[name].present, off[name].note) == (est.present, est.note), name
        if est.present:
            np.testing.assert_allclose([off[name].lo, off[name].hi], [est.lo, est.hi],
                                       rtol=1e-6)
    # watch shows it as not yet resolved, with no interval and no time to target
    view = WatchView(clock=lambda: 0.0)
    view.set_snapshot({"snapshot": snap, "fit": fit_record({"snapshot": snap})})
    full = view._render_fit()[0]
    x_ramp = full[full.index("  x:") + 1:][:5]
    line = next(s for s in x_ramp if "rate_ramp" in s)
    assert "not yet resolved" in line and "[" not in line




def _ramp_claims(seeds: tuple[int, ...], tmp_path) -> tuple[int, int, int, int, int, int]:
    """Over 41 and 55 min of each seed: (x and y axis fits, live ramps claimed resolved on
    x or y, the same on z, axes where analyze of the same samples with the service's
    estimator says the same of R and K as the live fit, axes where analyze's default OADEV
    claims R resolved, those of them where the live fit does not)."""
    claimed, claimed_z, same, total, by_oadev, beyond_live = 0, 0, 0, 0, 0, 0
    for seed in seeds:
        y_full, rate = quiet_lab(55, seed)
        for minutes in (41, 55):
            y = y_full[: int(minutes * 60 * rate)]
            sa = StreamingAllan(3, rate, names=["x", "y", "z"])
            step = int(60 * rate)
            for i in range(0, y.shape[0], step):
                sa.update(y[i:i + step])
            fits = fit_snapshot(AllanSnapshot.from_dict(sa.snapshot().to_dict()))
            path = tmp_path / f"ql{seed}_{minutes}.npz"
            np.savez(path, accel=y, rate_hz=rate, axes=np.array(["x", "y", "z"]))
            an = analyze(open_record(path), AnalyzeOptions(
                estimator="cascade", filter_corner_hz=rate / 4, find_sinusoids=False))
            # analyze's default OADEV stops at N/4; its ramps are tested against the TOTVAR
            # out to T/2 (core/analysis/long_tau_check.py)
            oadev = analyze(open_record(path), AnalyzeOptions(filter_corner_hz=rate / 4,
                                                              find_sinusoids=False))
            for axis, fit in fits.items():
                ramp = fit.terms["rate_ramp"]
                off_r = oadev.channels[axis].fit.terms["rate_ramp"]
                if off_r.present and off_r.note is None:
                    by_oadev += 1
                    beyond_live += not (ramp.present and ramp.note is None)
                if axis == "z":
                    claimed_z += ramp.present and ramp.note is None
                else:
                    total += 1
                    claimed += ramp.present and ramp.note is None
                off = an.channels[axis].fit.terms
                same += all((off[t].present, off[t].note) == (fit.terms[t].present,
                                                              fit.terms[t].note)
                            for t in ("rate_ramp", "rate_random_walk"))
    return total, claimed, claimed_z, same, by_oadev, beyond_live


def test_no_ramp_is_claimed_on_quiet_lab_seeds_4_and_5(tmp_path) -> None:
    """Counts, not one record: quiet-lab has no ramp. On seed 5's x axis the live fit read
    R ≈ 2e-7 m/s³ from τ ≤ 262 s, its test passing even without its longest τ (z 3–6),
    while the snapshot's own τ beyond the fit (524 and 1049 s: too few averages to fit, not
    to test) measured 0.5× and 0.02× the ramp's prediction there (fit._refuted_beyond). On
    41 and 55 min of seeds 4 and 5 no ramp is claimed resolved on any axis, and analyze
    of the same samples with the service's estimator says the same of R and K on each.
    analyze's default OADEV (to N/4) had claimed seed 5's x ramp at 41 and 55 min; the
    TOTVAR out to T/2 now refutes it there too."""
    total, claimed, claimed_z, same, by_oadev, beyond_live = _ramp_claims((4, 5), tmp_path)
    assert (total, claimed, claimed_z, same, by_oadev, beyond_live) == (8, 0, 0, 12, 0, 0)


@pytest.mark.slow
def test_no_ramp_is_claimed_on_quiet_lab_across_seeds(tmp_path) -> None:
    """The same over twelve seeds. x and y (48 fits): no ramp claimed resolved. z carries
    the preset's warm-up (2e-4 m/s² settling with a 600 s time constant), a monotonic drift
    that a ramp describes over these minutes; it is counted, not asserted absent (measured:
    seed 11 at 41 and 55 min, 2 of 24, before the decimation guard; 0 since: near the
    threshold, the live fit holds a decimated curve's claim back, core/analysis/live_fit.py).
    Every one of the 72 axes: analyze with the service's estimator says the same.
    analyze's default OADEV, which stops at N/4, had claimed R on 5 of the 72 (seed 0 z at
    55 min, seed 5 x at 41 and 55, seed 11 z at 41 and 55); with the TOTVAR out to T/2 it
    claims it on 1 (seed 11 z at 41 min, the warm-up, which the live fit holds back as near
    its threshold). The live fit claims no ramp analyze does not (issue 24: one fit, live
    and offline; tests/daemon/test_live_fit.py holds it for every term)."""
    total, claimed, claimed_z, same, by_oadev, beyond_live = _ramp_claims(tuple(range(12)),
                                                                          tmp_path)
    assert (total, claimed, same) == (48, 0, 72)
    assert claimed_z <= 2
    assert by_oadev <= 1 and beyond_live <= by_oadev
    # every ramp the live fit claims, analyze's OADEV claims too
    assert claimed + claimed_z <= by_oadev - beyond_live
