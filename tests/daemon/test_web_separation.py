"""``avard web``'s self-noise-against-common-mode card: the live separation travels in the
``avar`` record (daemon/service/separation_stage.py → the wire → the one decoder,
``snapshots.separation_of`` / ``Separation.from_dict``) and is drawn per axis with units,
intervals and upper limits; a broken one is refused without losing the Allan snapshot."""

from __future__ import annotations

import re

import numpy as np
import pytest
from avard.core.analysis.separate import Separation
from avard.core.errors import FormatError
from avard.core.io import frames
from avard.daemon.service.separation_stage import AlignedBlock, SeparationStage
from avard.daemon.service.snapshots import separation_of
from avard.daemon.web import render
from avard.daemon.web.state import RunState

from .test_web import RUN, feed, snapshot_dict

pytest.importorskip("aiohttp", reason="avard web needs the 'web' extra (aiohttp)")

RATE = 125.0


def _live_record(n: int = 1 << 15) -> tuple[dict, Separation]:
    """An ``avar`` record carrying a live separation of three sensors on one bed: "quiet"
    has almost no noise of its own, so its self-noise is an upper limit at most τ."""
    rng = np.random.default_rng(3)
    bed = rng.normal(0, 1e-3, (n, 3))
    own = (5e-4, 3e-4, 1e-7)
    names = ("left", "right", "quiet")
    accel = np.stack([bed + rng.normal(0, s, (n, 3)) for s in own])
    stage = SeparationStage(names, RATE)
    idx = np.tile(np.arange(n, dtype=np.int64), (3, 1))
    for a in range(0, n, 4000):
        stage.feed(AlignedBlock(names, idx[:, a:a + 4000], accel[:, a:a + 4000]))
    sep = stage.separation(RATE)
    assert sep is not None
    rec = frames.avar_record(RUN, 0, n, n, snapshot_dict(), 0.0, 1e9)
    rec.update(stage.record_fields(RATE))
    return rec, sep


def test_the_card_draws_the_decoded_live_separation_per_axis_with_units() -> None:
    rec, sep = _live_record()
    state = RunState()
    state.join({"run": RUN, "nominal_odr_hz": RATE}, None)
    feed(state, [("avar", rec)])                      # encoded and decoded as on the wire
    got = state.separation
    assert got is not None and state.snapshot is not None
    assert got.sensors == sep.sensors and got.method == "three-cornered hat"
    for a, b in zip(got.axes, sep.axes, strict=True):  # the one decoder gives back the numbers
        for p, q in zip((*a.self_noise, a.common), (*b.self_noise, b.common), strict=True):
            np.testing.assert_array_equal(p.upper_limit, q.upper_limit)
            np.testing.assert_allclose(p.hi, q.hi, rtol=1e-12)
            np.testing.assert_allclose(p.var[~p.upper_limit], q.var[~q.upper_limit],
                                       rtol=1e-12)
        assert [v.state for v in a.verdicts] == [v.state for v in b.verdicts]
    html = render.separation_html(state)
    assert "m/s²" in html and "τ [s]" in html and "three-cornered hat" in html
    axes = re.findall(r'<div class="sep-axis" data-axis="(\w)">(.*?)</ul></div>', html, re.S)
    assert [a for a, _ in axes] == ["x", "y", "z"]
    limits_seen = 0
    for (name, body), ax in zip(axes, got.axes, strict=True):
        assert name == ax.axis
        groups = re.findall(r'<g class="sep-part" data-role="(\w+)" data-name="([^"]+)" '
                            r'data-points="(\d+)" data-limits="(\d+)"(.*?)</g>', body, re.S)
        assert [g[1] for g in groups] == ["left", "right", "quiet", "common mode"]
        for (role, _n, pts, lims, inner), part in zip(
                groups, (*ax.self_noise, ax.common), strict=True):
            shown = np.isfinite(part.hi) & (part.hi > 0) & (ax.tau > 0)
            assert int(lims) == int(np.sum(shown & part.upper_limit)) == \
                inner.count('<path class="ul"')
            assert int(pts) == int(np.sum(shown & ~part.upper_limit & (part.var > 0)))
            assert inner.count('class="pt"') == int(pts)
            limits_seen += int(lims) if _n == "quiet" else 0
            assert (role == "common") == (_n == "common mode")
        # where the bed is resolved below a sensor's noise, the card says so
        for sensor, v in zip(got.sensors, ax.verdicts, strict=True):
            (line,) = re.findall(rf"<li>{sensor}: (.*?)</li>", body)
            assert ("bed below own noise at τ" in line) == ("below" in v.state), line
            assert ("bed above own noise at τ" in line) == ("above" in v.state), line
            assert ("not resolved at any τ" in line) == (set(v.state) == {"not resolved"})
    assert limits_seen > 0                    # "quiet"'s self-noise: upper limits, drawn as ▽
    assert "upper limit" in html


def test_a_broken_separation_is_refused_and_the_allan_snapshot_still_shown() -> None:
    rec, _sep = _live_record(1 << 12)
    bad = dict(rec)
    sep = dict(bad["separation"])
    axes = dict(sep["axes"])
    z = dict(axes["z"])
    z["tau"] = z["tau"][:-1]                 # ragged
    axes["z"] = z
    sep["axes"] = axes
    bad["separation"] = sep
    with pytest.raises(FormatError, match=r"z\.\w+ must be a list"):
        separation_of(bad)
    with pytest.raises(FormatError):
        Separation.from_dict({"sensors": ["a"], "axes": {}})
    state = RunState()
    state.set_snapshot(bad)
    assert state.separation is None and state.snapshot is not None
    assert "No live separation" in render.separation_html(state)
    assert separation_of({"snapshot": {}}) is None           # a one-sensor service's record


def test_the_page_has_the_card() -> None:
    from avard.daemon.web.app import Hub, page_html

    rec, _sep = _live_record(1 << 12)
    state = RunState()
    state.set_snapshot(rec)
    html = page_html(state, Hub(state), 0.1, "tcp://127.0.0.1:1")
    assert '<section class="card separation"><h2>Self-noise against common mode</h2>' in html
    assert 'class="plot separation"' in html


def test_a_rig_before_its_first_separation_says_it_is_coming() -> None:
    from avard.daemon.web.render import separation_html
    from avard.daemon.web.state import RunState

    state = RunState()
    assert "needs two or three" in separation_html(state)
    state.header = {"rig": {"sensors": ["left", "right"]}}
    assert "No live separation yet" in separation_html(state)
