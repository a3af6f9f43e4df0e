"""The weekend benchmark's ``--heldout on|off`` switch (``benchmarks/bench_explain_weekend.py``)
reaches the options every row's records are explained with, and the table says which.

Nothing is explained here: ``explain_file`` and the record's writer are replaced by stand-ins
that record the options they are given (the plumbing, not a benchmark run).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

import benchmarks.bench_explain_weekend as bw


class _Stop(Exception):
    """Raised by the stand-in ``explain_file`` once it has seen its options."""


@pytest.fixture
def seen(monkeypatch: pytest.MonkeyPatch) -> list[Any]:
    import avard.core.explain.engine as engine
    import avard.core.io.source as source

    import tests.support.weekend as weekend

    got: list[Any] = []

    def explain_file(_src: Any, options: Any, *a: Any, **k: Any) -> Any:
        got.append(options)
        raise _Stop

    monkeypatch.setattr(engine, "explain_file", explain_file)
    monkeypatch.setattr(source, "open_record", lambda path: path)
    monkeypatch.setattr(weekend, "save", lambda seed, w, path: path)
    return got


@pytest.mark.parametrize("kind,rows", [("plain", bw.rows), ("path", bw.rows_paths),
                                       ("outside", bw.outside_rows)])
@pytest.mark.parametrize("held", [True, False])
def test_every_kind_of_row_is_explained_with_the_switchs_held_out_test(
        seen: list[Any], kind: str, rows: Any, held: bool) -> None:
    name = rows()[0].name
    with pytest.raises(_Stop):
        bw._job(kind, (name, 1), heldout=held)
    assert [o.heldout for o in seen] == [held]


def test_event_rows_follow_the_switch(seen: list[Any]) -> None:
    r = bw.rows_events()[0]
    for held in (True, False):
        with pytest.raises(_Stop):
            bw.score_events(r, 1, 1, heldout=held)
    assert [o.heldout for o in seen] == [True, False]


def test_the_default_is_explains_own(seen: list[Any]) -> None:
    from avard.core.explain.options import ExplainOptions

    with pytest.raises(_Stop):
        bw._job("plain", (bw.rows()[0].name, 1))
    assert seen[0].heldout is ExplainOptions().heldout is True


@pytest.mark.parametrize("arg,held", [([], True), (["--heldout", "on"], True),
                                      (["--heldout", "off"], False)])
def test_the_command_line_switch_reaches_every_table(
        monkeypatch: pytest.MonkeyPatch, arg: list[str], held: bool) -> None:
    calls: dict[str, bool] = {}
    monkeypatch.setattr(bw, "run", lambda *a, **k: calls.__setitem__("run", a[5]))
    monkeypatch.setattr(bw, "run_events", lambda *a, **k: calls.__setitem__("events", a[3]))
    monkeypatch.setattr(bw, "run_paths", lambda *a, **k: calls.__setitem__("paths", a[5]))
    monkeypatch.setattr(bw, "run_outside", lambda *a, **k: calls.__setitem__("outside", a[5]))
    bw.main(["--rows", "null", *arg])
    bw.main(["--outside", *arg])
    assert calls == {"run": held, "events": held, "paths": held, "outside": held}


def test_the_header_says_how_the_rows_were_scored(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setattr(bw, "_score_all", lambda *a, **k: None)
    for held, word in ((True, "held-out test on"), (False, "held-out test OFF")):
        bw.run(1, 23000, ["null"], heldout=held)
        assert word in capsys.readouterr().out.splitlines()[0]


def test_a_results_file_keeps_the_two_ways_apart(tmp_path: Path) -> None:
    # a stopped run resumed with the other switch must not count the first's records
    f = tmp_path / "r.jsonl"
    lines = [{"row": "a", "seed": 1, "heldout": True}, {"row": "a", "seed": 2,
                                                         "heldout": False},
             {"row": "a", "seed": 3}]  # before the switch: a plain row, scored off
    f.write_text("".join(json.dumps(d) + "\n" for d in lines))
    assert set(bw._load_results(f, lambda d: d, True)) == {("a", 1)}
    assert set(bw._load_results(f, lambda d: d, False)) == {("a", 2), ("a", 3)}
