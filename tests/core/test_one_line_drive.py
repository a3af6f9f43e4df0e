"""A room whose cycle is one line (≥ 90 % of the channel's variance at one period): any
sinusoid of the axis at that period, of any phase, is a coupling through some lag of either
sign. A pump or compressor vibrating at the room's cycle is then read as a temperature
coupling that "fits" (an adversary's 16 records of 16, with no coupling at all); the finding
must say that the coupling rests on that one cycle and what would tell the two apart."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from avard.core.explain.engine import explain_file
from avard.core.explain.options import ExplainOptions
from avard.core.io.source import open_record

from tests.support.hidden import make_record, save

NOTE = "a periodic disturbance of the axis at that period would read the same"


@pytest.fixture(scope="module")
def pump(tmp_path_factory):
    """4 h, nothing coupled; x carries a 4e-4 m/s² sinusoid at the room's 1800 s cycle."""
    rec, _ = make_record(32, logged=("ambient",), hours=4.0)
    n = len(rec.accel)
    t = np.arange(n) / rec.rate_hz
    acc = np.array(rec.accel, dtype=float)
    acc[:, 0] += 4e-4 * np.sin(2 * math.pi * t / 1800.0 + 2.5)
    path = save(replace(rec, accel=acc), tmp_path_factory.mktemp("pump") / "pump.npz")
    return explain_file(open_record(str(path)), ExplainOptions(heldout=False))


def test_a_coupling_read_on_one_drive_line_says_what_it_rests_on(pump):
    temps = [f for f in pump.channels["x"].findings
             if f.cause == "temperature" and f.evidence]
    assert temps, "no thermal finding on x"
    # claimed or not, the finding says the one cycle cannot tell it from a disturbance
    assert all(NOTE in f.evidence for f in temps), temps[0].evidence


def test_an_axis_without_the_sinusoid_says_nothing_of_it(pump):
    for name in ("y", "z"):
        assert not any(f.cause == "temperature" and f.claimed
                       for f in pump.channels[name].findings)
