"""A temperature coupling that misses its test by less than half its threshold is said in
explain's text, not only in ``--json`` (issue 23, found by an adversary: a 20-minute record's
coupling at z 17.9 against its threshold 30.1 read "findings: none" and nothing more)."""

from __future__ import annotations

import math
from dataclasses import replace

from avard.core.explain.causes import Finding
from avard.core.explain.engine import explain_file
from avard.core.explain.options import ExplainOptions
from avard.core.explain.report import near_miss_lines, summary
from avard.core.io.source import open_record

from tests.support.hidden import Truth, make_record, save


def _finding(z: float, thr: float, claimed: bool = False, cause: str = "temperature"
             ) -> Finding:
    return Finding(cause, claimed, {"coefficient": 1.18e-3, "lag_s": 95.0},
                   {}, z, thr, "", channel="plate")


def test_the_rule_half_the_threshold_and_a_z_of_four():
    (line,) = near_miss_lines([_finding(17.9, 30.1)])
    assert line == ("  temperature: a coupling of 0.00118 m/s²/K (lag 95 s) to plate at z 17.9, "
                    "below this record's threshold 30.1: not claimed")
    assert near_miss_lines([_finding(14.9, 30.1)]) == []  # below half its threshold
    assert near_miss_lines([_finding(3.9, 5.0)]) == []  # half of 5 is a null axis's z
    assert len(near_miss_lines([_finding(4.2, 5.0)])) == 1
    assert near_miss_lines([_finding(31.0, 30.1)]) == []  # passed: not a near miss
    assert near_miss_lines([_finding(20.0, 30.1, claimed=True)]) == []
    assert near_miss_lines([_finding(20.0, 30.1, cause="gauss_markov")]) == []
    assert near_miss_lines([_finding(math.nan, 30.1)]) == []


def test_the_text_says_a_near_miss_below_findings_none(tmp_path):
    """On a real explanation whose temperature finding is set at the adversary's z and
    threshold, the channel's text carries the line (main printed "findings: none" alone)."""
    rec, _ = make_record(11, hours=1.0, logged=("ambient",),
                         truth=Truth(coefficient=(4e-4, 0, 0), lag_s=60.0))
    ex = explain_file(open_record(save(rec, tmp_path / "r.npz")),
                      ExplainOptions(channels=("x",), heldout=False))
    ch = ex.channels["x"]
    ch.findings = [replace(f, claimed=False, statistic=17.9, threshold=30.1)
                   if f.cause == "temperature" else f for f in ch.findings
                   if f.cause == "temperature" or not f.claimed]
    assert any(f.cause == "temperature" for f in ch.findings)
    text = summary(ex)
    assert "findings: none" in text
    assert "at z 17.9, below this record's threshold 30.1: not claimed" in text


def test_a_coupling_found_on_a_recording_of_short_runs_carries_the_caveat(tmp_path):
    """Two 10-minute runs in one recording fold the second run's warm-up into the coupling
    (issue 23: 1.7e-3 against a truth of ≈ 1.18e-3): not resolved per run, but said under the
    coupling found, naming the runs; an .npz (no runs) and one long run say nothing."""
    from avard.core.explain.report import runs_caveat
    from avard.core.io.source import RecordFormat, RecordingSummary, RunSummary

    rec, _ = make_record(12, hours=1.0, logged=("ambient",),
                         truth=Truth(coefficient=(3e-3, 0, 0), lag_s=60.0))
    ex = explain_file(open_record(save(rec, tmp_path / "r.npz")),
                      ExplainOptions(channels=("x",), heldout=False))
    assert [f.cause for f in ex.channels["x"].claimed] == ["temperature"]
    assert runs_caveat(ex) is None and "caveat: this recording" not in summary(ex)
    info = ex.analysis.info
    assert info is not None

    def runs(*minutes: float) -> RecordingSummary:
        return RecordingSummary(
            runs=tuple(RunSummary(f"run{i}", 10.0, 0.0, 0, int(m * 600), 0, 0)
                       for i, m in enumerate(minutes)),
            losses=(), duplicates=(), gaps=(), n_segments=len(minutes), files=(),
            problems=(), dropped_bytes=0)

    ex.analysis.info = replace(info, format=RecordFormat.RECORDING, recording=runs(10, 10))
    text = summary(ex)
    assert ("caveat: this recording is 2 runs (run0 10 min, run1 10 min); the thermal fit's "
            "start state settles the first run's warm-up only") in text
    ex.analysis.info = replace(info, recording=runs(600))
    assert runs_caveat(ex) is None
