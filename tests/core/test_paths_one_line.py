"""Two paths and the dT/dt term on a drive of one line are named beside each other
(``thermal_paths.oneline``), with the response at the drive and its interval."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from avard.core.explain.thermal_paths import PathScore
from avard.core.explain.thermal_paths.oneline import _rate_on_one_line


def _score(kind: str, beta: list[float]) -> PathScore:
    return PathScore(kind, -100.0, (120.0, 152.0), np.array(beta), np.zeros(2),
                     (100.0, 140.0), (130.0, 170.0), 40.0, False, (), (0.0, 0.0),
                     (0.0, 0.0), True, 1.0, (),
                     (1800.0, 1.9e-3, 1.7e-3, 2.0e-3, 1.1, 1.05, 1.15, 0.97))


def test_only_two_paths_in_the_dt_terms_limit_on_one_line_read_as_it():
    """Two paths of opposite sign that nearly cancel, on a drive of one line: the dT/dt
    term's reading with a parameter more. Two paths of their own response (the two-path
    row's truth, 8e-4 through 0 s and −2.7e-3 through 900 s) or a drive of more than one
    line keep the margin rule."""
    cancel = _score("two_path", [0.0224, -0.0234])
    assert _rate_on_one_line(cancel, 0.97)
    assert not _rate_on_one_line(cancel, 0.72)  # the compressor rows' drive
    assert not _rate_on_one_line(cancel, math.nan)
    assert not _rate_on_one_line(_score("two_path", [8e-4, -2.7e-3]), 0.97)
    assert not _rate_on_one_line(_score("rate", [8e-4, 0.5]), 0.97)


def test_the_note_names_both_readings_with_the_response_at_the_drive_and_its_interval():
    """The note that names the dT/dt term beside two paths on one line says both readings
    and the response at the drive with its 68 % interval, which both readings fit."""
    from avard.core.explain.thermal_paths.oneline import _one_line_note

    two = _score("two_path", [0.0224, -0.0234])
    rate = replace(_score("rate", [7.8e-4, 0.5]), heldout=-90.5)
    note = _one_line_note(two, rate, 1800.0, 0.97)
    assert note.startswith("two paths or one lag plus a dT/dt term: this record cannot tell "
                           "them apart")
    assert "gain 0.0019 m/s²/K [0.0017, 0.002]" in note
    assert "phase +1.1 rad [+1.05, +1.15]" in note
    assert "worse by 9.5" in note


def test_a_dt_term_at_3x_the_fits_minimum_is_named_beside_two_paths_that_beat_it():
    """The weekend benchmark's dT/dt record (8e-4 m/s²/K at lag 0) with r at 3× the minimum
    against one lag as explain's fit sees the line (cand26b: 0.485 m/s² per K/s), seed
    30019: two paths through 120 and 152 s of cancelling coefficients predict the held-out
    halves better than a dT/dt term of the right size by more than the margin (9.5). One
    line cannot tell the two readings apart: both are named, with the response at the drive
    and its interval; before, two paths alone with nothing beside them."""
    import benchmarks.bench_explain_weekend as bw

    base, r, _ = bw.fit_seen_sizes()
    assert r == pytest.approx(0.485, rel=0.01)
    ex, _ = bw.explain_weekend(replace(base, rate_coupling=r), 30019)
    th = [f for f in ex.channels["x"].claimed if f.cause == "temperature"]
    assert th
    named = (th[0].mechanism, *th[0].alternatives)
    assert "rate" in named and "two_path" in named
    # the mechanism's parameters are model-dependent (no interval); the response at the
    # drive, the generator's own within its tolerance, is in the finding's text with its
    # interval
    assert th[0].model_dependent and th[0].intervals == {}
    g = bw._true_response(replace(base, rate_coupling=r), th[0].params["drive_period_s"])
    g += 2j * math.pi / th[0].params["drive_period_s"] * r * (
        1 + 2j * math.pi / th[0].params["drive_period_s"] * base.sensor_tau_s) / (
        1 + 2j * math.pi / th[0].params["drive_period_s"] * base.die_tau_s)
    assert th[0].params["gain_at_drive"] == pytest.approx(abs(g), rel=0.2)
    assert "two paths or one lag plus a dT/dt term: this record cannot tell them apart" in (
        th[0].evidence)
    assert f"gain {th[0].params['gain_at_drive']:.4g} m/s²/K [" in th[0].evidence


def test_a_relays_narrowest_width_is_a_value_and_its_widest_an_edge():
    """The hysteresis grid (lag, width): the narrowest width is an ideal relay's value (its
    switch time is the lag's, which has grid on both sides), not a search's edge; the widest
    width and the longest lag are edges (open)."""
    from avard.core.explain.thermal_paths.columns import trials
    from avard.core.explain.thermal_paths.profile import _at_end
    from avard.core.explain.thermal_paths.settings import WIDTHS_K

    ts = trials("hysteresis", [0.0, 60.0, 120.0, 240.0, 480.0])
    where = {t.theta: k for k, t in enumerate(ts)}
    assert not _at_end(ts, where[(240.0, WIDTHS_K[0])])
    assert not _at_end(ts, where[(120.0, WIDTHS_K[2])])
    assert _at_end(ts, where[(120.0, WIDTHS_K[-1])])
    assert _at_end(ts, where[(480.0, WIDTHS_K[2])])


@pytest.mark.parametrize("seed", [407, 416])
def test_a_relay_against_a_coupling_of_the_other_sign_is_chosen(tmp_path, seed: int):
    """The adversary's hysteresis class at 3× the relay's minimum as the fit sees the lines
    (``hysteresis_minimum="fit"``), c < 0: the relay's fundamental opposite the coupling
    puts the response where no one lag reaches. The relay predicts the held-out halves
    best, its term past the search threshold, at the narrowest width with a lag of
    120–240 s (the ridge along which width and lag trade); with that width read as the
    grid's edge it was never chosen, and two paths were claimed instead."""
    from avard.core.explain.engine import explain_file
    from avard.core.explain.options import ExplainOptions
    from avard.core.io.source import open_record

    from tests.support.adversary_gen import make_record

    path = tmp_path / f"hysteresis{seed}.npz"
    truth = make_record("hysteresis", seed, path, logged=("plate",),
                        hysteresis_minimum="fit")["axes"]["x"]
    assert truth["coefficient_mps2_per_k"] < 0
    ch = explain_file(open_record(str(path)), ExplainOptions(channels=("x",))).channels["x"]
    th = [f for f in ch.claimed if f.cause == "temperature"]
    assert th and th[0].mechanism == "hysteresis", [(f.mechanism, f.params) for f in th]
    assert math.copysign(1.0, th[0].params["coefficient"]) == -1.0
