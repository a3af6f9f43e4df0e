"""No output of a command replaces its input, and no two outputs name one file: both are
refused in one line before any work. ``avard analyze data.csv --export csv data.csv``
replaced the record with its ADEV table, exit status 0; ``--export csv a.csv --export psd
a.csv`` kept only the last one written."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pytest
from avard.daemon.cli import main


@pytest.fixture
def record(tmp_path: Path) -> Path:
    rng = np.random.default_rng(8)
    p = tmp_path / "lab.csv"
    rows = np.column_stack([np.arange(3000) / 100.0, rng.normal(0, 1e-3, (3000, 3))])
    p.write_text("t,x,y,z\n" + "\n".join(",".join(f"{v:.9g}" for v in r) for r in rows) + "\n")
    return p


def _digest(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


@pytest.mark.parametrize("args, said", [
    (["analyze", "{rec}", "--export", "csv", "{rec}"], "is the record read"),
    (["analyze", "{rec}", "--export", "csv", "{dot}"], "is the record read"),
    (["analyze", "{rec}", "--export", "stats", "{rec}", "--stat", "mdev"], "is the record read"),
    (["analyze", "{rec}", "--export", "csv", "{out}", "--export", "psd", "{out}", "--psd"],
     "name one file"),
    (["fleet", "{rec}", "--csv", "{rec}"], "is the record read"),
])
def test_an_output_onto_the_input_or_onto_another_output_is_refused(record: Path, capsys,
                                                                    args, said) -> None:
    before = _digest(record)
    out = record.parent / "adev.csv"
    dot = record.parent / "." / record.name
    argv = [a.format(rec=record, dot=dot, out=out) for a in args]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and said in err, err
    assert _digest(record) == before                 # the record is untouched
    assert not out.exists()                          # and nothing was written


def test_outputs_of_their_own_are_written(record: Path, capsys) -> None:
    out, psd = record.parent / "adev.csv", record.parent / "psd.csv"
    assert main(["analyze", str(record), "--export", "csv", str(out), "--export", "psd",
                 str(psd), "--psd"]) == 0
    assert out.read_text().startswith("channel,tau_s") and psd.exists()
