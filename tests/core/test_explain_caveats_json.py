"""The caveats explain's text says under a finding are in ``--json`` too (issue 23 item 1,
"say what was screened"): a coupling found on a recording of several runs, a later one under
an hour, was said in the text and the report only."""

from __future__ import annotations

import json
from dataclasses import replace

from avard.core.explain.engine import explain_file
from avard.core.explain.options import ExplainOptions
from avard.core.explain.report import runs_caveat, summary
from avard.core.io.source import RecordFormat, RecordingSummary, RunSummary, open_record

from tests.support.hidden import Truth, make_record, save


def _runs(*minutes: float) -> RecordingSummary:
    return RecordingSummary(
        runs=tuple(RunSummary(f"run{i}", 10.0, 0.0, 0, int(m * 600), 0, 0)
                   for i, m in enumerate(minutes)),
        losses=(), duplicates=(), gaps=(), n_segments=len(minutes), files=(),
        problems=(), dropped_bytes=0)


def test_the_runs_caveat_is_in_the_json_under_its_channel(tmp_path):
    rec, _ = make_record(12, hours=1.0, logged=("ambient",),
                         truth=Truth(coefficient=(3e-3, 0, 0), lag_s=60.0))
    ex = explain_file(open_record(save(rec, tmp_path / "r.npz")),
                      ExplainOptions(channels=("x",), heldout=False))
    assert [f.cause for f in ex.channels["x"].claimed] == ["temperature"]
    d = json.loads(json.dumps(ex.to_dict(), default=str))
    assert d["channels"]["x"]["caveats"] == []  # an .npz: no runs, nothing to say
    info = ex.analysis.info
    assert info is not None
    ex.analysis.info = replace(info, format=RecordFormat.RECORDING, recording=_runs(10, 10))
    caveat = runs_caveat(ex)
    assert caveat is not None and "--run RUN" in caveat
    d = json.loads(json.dumps(ex.to_dict(), default=str))
    assert d["channels"]["x"]["caveats"] == [caveat]
    assert caveat in summary(ex)  # the very line the text says
    # one long run: no caveat, in the JSON as in the text
    ex.analysis.info = replace(info, format=RecordFormat.RECORDING, recording=_runs(600))
    assert json.loads(json.dumps(ex.to_dict(), default=str))["channels"]["x"]["caveats"] == []
    # no coupling claimed on the channel: no caveat, whatever the runs
    ex.analysis.info = replace(info, format=RecordFormat.RECORDING, recording=_runs(10, 10))
    ch = ex.channels["x"]
    ch.findings = [replace(f, claimed=False) for f in ch.findings]
    assert json.loads(json.dumps(ex.to_dict(), default=str))["channels"]["x"]["caveats"] == []
