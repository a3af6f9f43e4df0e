"""``avard web`` without a browser: the run's history, the SVG and tables, ``/metrics`` read
by a parser written from the Prometheus text-format description, the HTTP routes and SSE
stream, and the command line (read-only, loopback by default, bad input → one line, exit 2).
"""

from __future__ import annotations

import asyncio
import json
import math
import re
import signal
import subprocess
import threading
import time

import numpy as np
import pytest
from avard.core.allan.streaming import AllanSnapshot, StreamingAllan
from avard.core.io import frames
from avard.core.io.source import RecordingSource
from avard.daemon.commands.web import is_loopback, parse_listen
from avard.daemon.net.subscriber import LossTracker
from avard.daemon.web import render
from avard.daemon.web.metrics import metrics_text
from avard.daemon.web.state import RunState, Series

from .web_rig import avard, free_ports

aiohttp = pytest.importorskip("aiohttp", reason="avard web needs the 'web' extra (aiohttp)")

RATE = 125.0
RUN = "20260101T000000Z-aaaaaa"


def snapshot_dict(n: int = 20000, seed: int = 1, names=("x", "y", "z", "chip")) -> dict:
    """A real AllanSnapshot of white noise (m/s²) on the axes and a slow drift in °C."""
    rng = np.random.default_rng(seed)
    sa = StreamingAllan(len(names), RATE, names=list(names))
    data = rng.normal(0, 1e-3, (n, len(names)))
    data[:, 3] = 21 + np.linspace(0, 0.5, n)
    sa.update(data)
    return sa.snapshot().to_dict()


def feed(state: RunState, records: list[tuple[str, dict]]) -> LossTracker:
    """Pass records through the subscriber's own bookkeeping into the state."""
    tracker = LossTracker()
    for topic, rec in records:
        state.update(tracker.observe(topic, frames.decode(frames.encode(rec))), tracker.stats)
    return tracker


def a_run(run: str = RUN, i0: int = 0, blocks: int = 10, seq0: int = 0) -> list[tuple[str, dict]]:
    counts = np.zeros((125, 3), dtype=np.int32)
    out = []
    for k in range(blocks):
        i = i0 + 125 * k
        out.append(("raw", frames.raw_record(run, seq0 + k, i, counts, i / RATE, 1e9 + i / RATE,
                                             rate_hz=RATE, chip_temp_c=21.0 + k / 100)))
        out.append(("temp", frames.temp_record(run, seq0 + k, i, ["28-0000plate"], [20.5 + k],
                                               i / RATE, 1e9)))
    return out


# ---- history ---------------------------------------------------------------------------------


def test_a_series_keeps_the_whole_run_in_bounded_memory():
    s = Series(max_points=100)
    for k in range(100_000):
        s.append(float(k), float(k) * 2)
    assert 50 <= len(s) < 100
    assert s.x[0] == 0.0 and s.x[-1] > 99_000 - 2 * 2048  # spans the run to its end
    steps = np.diff(s.x)
    assert steps.min() == steps.max()  # evenly thinned
    assert all(y == 2 * x for x, y in zip(s.x, s.y, strict=True))


def test_state_keeps_temperatures_gaps_and_events_of_the_whole_run():
    state = RunState()
    state.join({"run": RUN, "nominal_odr_hz": RATE, "i0": 0}, None)
    recs = a_run(blocks=6)
    recs.insert(5, ("event", frames.gap_record(RUN, 0, 750, 250, 6.0, 1e9, "overrun")))
    recs.insert(7, ("event", frames.event_record(RUN, 1, "clock_step", 7.0, 1e9, i0=900,
                                                 detail={"step_s": 2.5})))
    feed(state, recs)
    assert state.gaps_by_reason == {"overrun": 1}
    assert state.gap_samples_by_reason == {"overrun": 250}
    assert state.events_by_name == {"clock_step": 1}
    gap = next(i for i in state.timeline if i.kind == "gap")
    assert gap.t_s == pytest.approx(750 / RATE) and gap.samples == 250
    assert state.temperatures["28-0000plate"].y == [20.5 + k for k in range(6)]
    assert len(state.temperatures["chip"]) == 6  # one chip point per second of run time
    assert state.latest_temps["chip"] == pytest.approx(21.05)


def test_a_restart_whose_gap_record_was_missed_becomes_a_restart_gap():
    state = RunState()
    state.join({"run": RUN, "nominal_odr_hz": RATE}, None)
    new = "20260101T010000Z-bbbbbb"
    tracker = feed(state, a_run(blocks=4))  # indices [0, 500)
    # the new run's first block starts 300 samples later; its gap record never arrived
    for topic, rec in a_run(new, i0=800, blocks=2):
        state.update(tracker.observe(topic, rec), tracker.stats)
    assert state.runs == [RUN, new]
    assert state.gaps_by_reason == {"restart": 1}
    assert state.gap_samples_by_reason == {"restart": 300}
    assert state.events_by_name == {"new run": 1}


def test_a_restart_gap_record_that_arrived_is_not_counted_twice():
    state = RunState()
    state.join({"run": RUN, "nominal_odr_hz": RATE}, None)
    new = "20260101T010000Z-bbbbbb"
    tracker = feed(state, a_run(blocks=4))
    recs = [("event", frames.gap_record(new, 0, 500, 300, 0.0, 1e9, "restart")),
            *a_run(new, i0=800, blocks=2)]
    for topic, rec in recs:
        state.update(tracker.observe(topic, rec), tracker.stats)
    assert state.gaps_by_reason == {"restart": 1}
    assert state.gap_samples_by_reason == {"restart": 300}


def test_an_unreadable_snapshot_is_ignored_not_fatal():
    state = RunState()
    state.set_snapshot({"snapshot": {"tau": [1, 2], "avar": [[1, 2], [3]], "n_samples": 5}})
    assert state.snapshot is None
    state.set_snapshot({"snapshot": snapshot_dict()})
    assert state.snapshot is not None and state.snapshot.n_samples == 20000


def test_the_services_first_snapshot_without_any_tau_is_not_drawn():
    state = RunState()
    first = StreamingAllan(4, RATE, names=["x", "y", "z", "chip"])
    first.update(np.zeros((1, 4)))
    state.set_snapshot({"snapshot": first.snapshot().to_dict()})
    assert state.snapshot is None
    assert "No Allan snapshot yet" in render.adev_html(state)


def test_a_fragment_that_cannot_be_drawn_says_so_and_the_rest_of_the_page_stays(monkeypatch):
    state = RunState()
    snap = snapshot_dict()
    snap["avar"] = [row[:2] for row in snap["avar"]]  # two columns for x, y, z, chip
    state.set_snapshot({"snapshot": snap})
    assert state.snapshot is None            # the one decoder refuses it before any drawing
    state.set_snapshot({"snapshot": snapshot_dict()})

    def broken(*args, **kwargs):
        raise IndexError("index 2 is out of bounds")

    monkeypatch.setattr(render, "adev_svg", broken)
    parts = render.fragments(state, 0.1)
    assert "Cannot draw this" in parts["adev"] and "IndexError" in parts["adev"]
    assert "Cannot draw this" not in parts["status"] + parts["timeline"]


def test_status_shows_the_services_counts_and_the_rate_offset():
    state = RunState()
    state.join({"run": RUN, "nominal_odr_hz": RATE}, None)
    feed(state, [("status", frames.status_record(
        RUN, 0, {"run": RUN, "samples": 12345, "rate_hz": 124.9, "overruns": 3,
                 "bus_errors": 4, "clock_steps": 5, "subscribers": 6, "sim_time_s": 7200.0,
                 "disk": {"state": "writing", "free_bytes": 2.5e9, "bytes": 1.2e6}},
        0.0, 1e9)),
        ("event", frames.gap_record(RUN, 0, 100, 250, 0.0, 1e9, "overrun"))])
    text = re.sub(r"<[^>]+>", " ", render.status_html(state))
    for want in ("12345 in this run", "-800.0 ppm from nominal", "overruns 3", "bus errors 4",
                 "clock steps 5", "6 on the service", "2.5 GB free", "service 2.0 h",
                 "1 gap, 2 s of samples missing"):
        assert want in text, (want, text)
    assert "{" not in text


def test_a_silent_service_is_called_out_and_the_page_keeps_refreshing(monkeypatch):
    from avard.daemon.web import app

    now = [100.0]
    state = RunState(clock=lambda: now[0])
    assert "Nothing received from the service yet" in render.status_html(state)
    feed(state, a_run(blocks=1))
    assert "alarm" not in render.status_html(state)
    now[0] += 40.0
    assert "Nothing received from the service for 40 s" in render.status_html(state)

    hub = app.Hub(state)
    assert hub.refresh() and not hub.refresh()  # nothing changed: nothing to send
    monkeypatch.setattr(app, "IDLE_REFRESH_S", 0.0)
    assert hub.refresh()  # but ages move on: re-rendered after IDLE_REFRESH_S anyway


# ---- rendering -------------------------------------------------------------------------------


def test_the_adev_plot_has_every_finite_point_of_every_axis_and_the_model():
    from avard.daemon.service.snapshots import fit_snapshot

    state = RunState()
    state.set_snapshot({"snapshot": snapshot_dict()})
    snap = state.snapshot
    fits = fit_snapshot(snap.data)
    assert set(fits) == {"x", "y", "z"}
    state.set_fits(fits, snap)
    svg = render.adev_svg(snap, fits)
    finite = int(np.sum(np.isfinite(snap.data.avar[:, 0])
                        & (snap.data.avar[:, 0] > 0)))
    for axis in "xyz":
        group = re.search(rf'<g class="adev-axis" data-points="(\d+)" data-axis="{axis}"(.*?)</g>',
                          svg, re.S)
        assert group, axis
        assert int(group[1]) == finite == group[2].count('<circle class="pt"')
        assert '<path class="model"' in group[2]
    assert "chip" not in svg  # temperatures are not on the m/s² axis
    html = render.fit_html(state, 0.1)
    assert 'data-term="velocity_random_walk"' in html and "absent" in html


def test_the_fitted_snapshot_is_drawn_with_the_intervals_its_fit_supports():
    """Once the latest snapshot is fitted, the page draws its ADEV with the EDF the fit
    supports (analyze's rule, signal_edf; live_fit.fit_channel), the same numbers the
    service's fit record and watch give; before, the snapshot's own."""
    from avard.daemon.service.snapshots import fit_intervals, fit_record, snapshot_fits

    state = RunState()
    d = snapshot_dict()
    state.set_snapshot({"snapshot": d})
    snap = state.snapshot
    assert state.shown() is snap
    fits = snapshot_fits(snap.data)
    state.set_fits({k: cf.fit for k, cf in fits.items()}, snap, fit_intervals(snap.data, fits))
    shown = state.shown().data
    record = fit_record({"snapshot": d})
    for c, axis in enumerate("xyz"):
        np.testing.assert_array_equal(shown.lo[:, c], fits[axis].allan.lo)
        np.testing.assert_allclose(shown.hi[:, c], record[axis]["hi"], rtol=1e-12)
    assert np.any(shown.edf[:, :3] != snap.data.edf[:, :3])  # the fit raised some EDF
    assert "fit of this snapshot" in render.adev_html(state)


def test_a_term_the_live_guard_holds_back_shows_no_interval_and_no_time_to_target():
    """A term flagged by the decimation guard (live_fit.OTHER_READING, NEAR_THRESHOLD)
    is shown as watch shows it: its value and "not yet resolved", no interval."""
    from dataclasses import replace

    from avard.core.analysis.live_fit import NEAR_THRESHOLD, OTHER_READING
    from avard.daemon.service.snapshots import fit_snapshot

    state = RunState()
    state.set_snapshot({"snapshot": snapshot_dict()})
    snap = state.snapshot
    fits = fit_snapshot(snap.data)
    for note in (OTHER_READING, NEAR_THRESHOLD):
        n = fits["x"].terms["velocity_random_walk"]
        held = replace(fits["x"], terms={**fits["x"].terms,
                                         "velocity_random_walk": replace(n, note=note)})
        state.set_fits({**fits, "x": held}, snap)
        html = render.fit_html(state, 0.1)
        row = re.search(r'<tr data-term="velocity_random_walk">(.*?)</tr>', html, re.S)
        assert row is not None
        x_cell = re.findall(r"<td>(.*?)</td>", row[1], re.S)[0]
        assert "not yet resolved" in x_cell and "[" not in x_cell and "more" not in x_cell


def test_time_to_target_per_tau_follows_the_interval_width():
    state = RunState()
    state.set_snapshot({"snapshot": snapshot_dict()})
    snap = state.snapshot.data
    html = render.targets_html(state, 0.1)
    rows = re.findall(r"<tr><th>([\d.e+-]+)</th>(.*?)</tr>", html)
    assert len(rows) == len(snap.tau)
    adev = np.sqrt(snap.avar[:, 0])
    w = (np.sqrt(snap.hi[:, 0]) - np.sqrt(snap.lo[:, 0])) / adev / 2
    for (_tau, cells), wk in zip(rows, w, strict=True):
        first = re.search(r"±([\d.e+-]+) %", cells)
        assert first[1] == f"{100 * wk:.3g}"   # the width, to the 3 figures shown
        assert ("target reached" in cells.split("</td>")[0]) == (wk <= 0.1)


def test_text_from_the_service_is_escaped_everywhere():
    state = RunState()
    evil = '<script>alert("x")</script>'
    state.join({"run": RUN, "nominal_odr_hz": RATE}, None)
    feed(state, [("event", frames.event_record(RUN, 0, evil, 0.0, 1e9, i0=0,
                                               detail={"k": evil})),
                 ("temp", frames.temp_record(RUN, 0, 0, [evil], [20.0], 0.0, 1e9)),
                 ("event", frames.gap_record(RUN, 1, 10, 5, 0.0, 1e9, evil))])
    for html in render.fragments(state, 0.1).values():
        assert "<script" not in html


# ---- /metrics --------------------------------------------------------------------------------

SAMPLE = re.compile(r'^([a-zA-Z_:][a-zA-Z0-9_:]*)(?:\{(.*)\})? (\S+)$')
LABEL = re.compile(r'([a-zA-Z_][a-zA-Z0-9_]*)="((?:[^"\\]|\\.)*)"(?:,|$)')


def parse_exposition(text: str) -> dict[tuple[str, frozenset], float]:
    """Prometheus text format 0.0.4, from its description: HELP/TYPE comment lines, then
    ``name{label="value",...} number`` lines; label values escape \\, " and newline."""
    assert text.endswith("\n")
    typed: dict[str, str] = {}
    out: dict[tuple[str, frozenset], float] = {}
    for line in text.splitlines():
        if line.startswith("# TYPE "):
            _, _, name, kind = line.split(" ", 3)
            assert kind in ("counter", "gauge") and name not in typed
            typed[name] = kind
            continue
        if line.startswith("# HELP "):
            continue
        m = SAMPLE.match(line)
        assert m, line
        name, labels, value = m.groups()
        assert name in typed, f"{name} has no TYPE line"
        pairs = LABEL.findall(labels or "")
        assert "".join(f'{k}="{v}",' for k, v in pairs).rstrip(",") == (labels or "")
        key = (name, frozenset((k, v.encode().decode("unicode_escape")) for k, v in pairs))
        assert key not in out, f"duplicate sample {key}"
        out[key] = float(value)
    return out


def test_metrics_are_valid_exposition_text_with_the_runs_numbers():
    state = RunState()
    state.join({"run": RUN, "nominal_odr_hz": RATE}, None)
    recs = a_run(blocks=3)
    recs += [("event", frames.gap_record(RUN, 0, 375, 40, 0.0, 1e9, "overrun")),
             ("event", frames.gap_record(RUN, 1, 500, 2, 0.0, 1e9, "bus_error")),
             ("temp", frames.temp_record(RUN, 3, 500, ['od"d\nname'], [19.5], 0.0, 1e9)),
             ("status", frames.status_record(RUN, 0, {"samples": 541, "rate_hz": 124.9,
                                                      "overruns": 1, "subscribers": 2,
                                                      "disk": {"free_bytes": 10**9}},
                                             0.0, 1e9)),
             ("avar", frames.avar_record(RUN, 0, 20000, 20000, snapshot_dict(), 0.0, 1e9))]
    feed(state, recs)
    m = parse_exposition(metrics_text(state))
    assert m[("avard_samples_total", frozenset({("run", RUN)}))] == 541
    assert m[("avard_gaps_total", frozenset({("reason", "overrun")}))] == 1
    assert m[("avard_gap_samples_total", frozenset({("reason", "overrun")}))] == 40
    assert m[("avard_gaps_total", frozenset({("reason", "bus_error")}))] == 1
    assert m[("avard_overruns_total", frozenset({("run", RUN)}))] == 1
    assert m[("avard_rate_offset_ppm", frozenset())] == pytest.approx((124.9 / 125 - 1) * 1e6)
    assert m[("avard_temperature_celsius", frozenset({("sensor", 'od"d\nname')}))] == 19.5
    assert m[("avard_disk_free_bytes", frozenset())] == 1e9
    assert m[("avard_web_samples_received_total", frozenset())] == 375
    snap = state.snapshot.data
    for k, tau in enumerate(snap.tau):
        at = ("tau_seconds", f"{tau:.6g}")
        key = ("avard_adev_meters_per_second_squared", frozenset({("axis", "y"), at}))
        assert m[key] == pytest.approx(math.sqrt(snap.avar[k, 1]))
        key = ("avard_adev_meters_per_second_squared_upper", frozenset({("axis", "y"), at}))
        assert m[key] == pytest.approx(math.sqrt(snap.hi[k, 1]))
        key = ("avard_temperature_adev_celsius", frozenset({("sensor", "chip"), at}))
        assert m[key] == pytest.approx(math.sqrt(snap.avar[k, 3]))
    assert not any(n.startswith("avard_adev") and ("axis", "chip") in lab for n, lab in m)


# ---- HTTP --------------------------------------------------------------------------------------


def _serve(state: RunState, check) -> None:
    from aiohttp.test_utils import TestClient, TestServer
    from avard.daemon.web.app import Hub, make_app

    async def main() -> None:
        hub = Hub(state, refresh_s=0.05)
        async with TestClient(TestServer(make_app(state, hub, endpoint="tcp://h:1"))) as client:
            await check(client, hub)

    asyncio.run(main())


def test_http_routes_are_read_only_self_contained_and_stream_updates():
    state = RunState()
    state.join({"run": RUN, "nominal_odr_hz": RATE}, {"snapshot": snapshot_dict()})
    feed(state, a_run(blocks=2))

    async def check(client, hub) -> None:
        page = await client.get("/?target=5")
        html = await page.text()
        assert page.status == 200
        assert "default-src 'none'" in page.headers["Content-Security-Policy"]
        # everything a late viewer needs is in the first response; only local resources
        assert 'class="adev-axis"' in html and 'id="timeline"' in html
        assert 'value="5"' in html  # the target the viewer asked for
        assert not re.search(r'(src|href)="(?!/)', html)
        for path, kind in (("/static/app.js", "javascript"), ("/static/style.css", "css")):
            r = await client.get(path)
            assert r.status == 200 and kind in r.headers["Content-Type"]
        assert (await client.get("/static/..%2Fapp.py")).status == 404
        for method in ("POST", "PUT", "DELETE"):
            assert (await client.request(method, "/")).status == 405
        metrics = await client.get("/metrics")
        assert metrics.headers["Content-Type"].startswith("text/plain; version=0.0.4")
        parse_exposition(await metrics.text())

        # server-sent events: the current view at once, then every change
        resp = await client.get("/events?target=20")
        assert resp.headers["Content-Type"] == "text/event-stream"
        first = await _next_event(resp)
        assert set(first) == {"status", "adev", "separation", "fit", "targets", "temps",
                              "timeline"}
        assert "±20 %" in first["targets"]
        assert hub.viewers == 1
        feed(state, [("event", frames.gap_record(RUN, 0, 250, 9, 0.0, 1e9, "overrun"))])
        second = await _next_event(resp)
        assert "overrun" in second["timeline"] and "overrun" not in first["timeline"]
        assert "adev" not in second and "targets" not in second  # only what changed
        resp.close()

    _serve(state, check)


async def _next_event(resp) -> dict:
    data = None
    while data is None:
        line = (await asyncio.wait_for(resp.content.readline(), 10)).decode()
        if line.startswith("data: "):
            data = json.loads(line[6:])
    return data


def test_target_in_the_query_is_checked():
    from avard.daemon.web.app import DEFAULT_TARGET, parse_target

    assert parse_target({"target": "5"}) == 0.05
    for bad in ("0", "-3", "nan", "inf", "1e9", "x", None):
        assert parse_target({"target": bad}) == DEFAULT_TARGET


# ---- the command ---------------------------------------------------------------------------


def test_with_curve_the_page_needs_the_keys(tmp_path):
    """A CURVE service: avard web with an authorised key sees the run; without keys it gets
    nothing and the page says so (the keys reach the one Subscriber as in avard watch)."""
    from .web_rig import WebRig

    keys, auth = tmp_path / "keys", tmp_path / "auth"
    auth.mkdir()
    for name in ("server", "web"):
        subprocess.run(avard("keys", "--out", str(keys), "--name", name), check=True,
                       capture_output=True, timeout=60)
    (auth / "web.key").write_bytes((keys / "web.key").read_bytes())
    rig = WebRig(tmp_path, web_args=("--server-key", str(keys / "server.key"), "--client-key",
                                      str(keys / "web.key_secret")),
                 extra_config=f'[curve]\nenabled = true\nserver_secret_key_file = '
                              f'"{keys / "server.key_secret"}"\nauthorized_keys_dir = "{auth}"\n')
    (other,) = free_ports(1)
    stranger = None
    try:
        rig.start_service()
        rig.start_web()
        stranger = subprocess.Popen(
            avard("web", f"tcp://127.0.0.1:{rig.pub}", "--timeout", "0.5", "--listen",
                  f"127.0.0.1:{other}"), stderr=subprocess.DEVNULL)
        deadline = time.monotonic() + 60
        while rig.state()["samples_received"] == 0 and time.monotonic() < deadline:
            time.sleep(0.3)
        assert rig.state()["samples_received"] > 0, rig.read_logs()
        import urllib.request

        def get(path: str) -> bytes:
            with urllib.request.urlopen(f"http://127.0.0.1:{other}{path}", timeout=10) as r:
                return r.read()

        deadline = time.monotonic() + 30
        while True:  # the stranger's server may still be starting
            try:
                state = json.loads(get("/state.json"))
                break
            except OSError:
                assert time.monotonic() < deadline, "the keyless avard web never served"
                time.sleep(0.3)
        time.sleep(2.0)  # a keyless subscriber would have had messages by now
        assert json.loads(get("/state.json"))["samples_received"] == state[
            "samples_received"] == 0
        assert "Nothing received from the service yet" in get("/").decode()
    finally:
        if stranger is not None:
            stranger.terminate()
            stranger.wait(20)
        rig.close()


def test_listen_addresses():
    assert parse_listen("127.0.0.1:8080") == ("127.0.0.1", 8080)
    assert parse_listen("[::1]:9") == ("::1", 9)
    assert is_loopback("127.0.0.1") and is_loopback("::1") and is_loopback("localhost")
    assert not is_loopback("0.0.0.0") and not is_loopback("192.168.1.5")


@pytest.mark.parametrize("listen", ["8080", "host:", "host:99999", ":80"])
def test_a_bad_listen_address_is_one_line_and_exit_2(listen):
    r = subprocess.run(avard("web", "tcp://127.0.0.1:1", "--listen", listen),
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and "--listen" in r.stderr and "HOST:PORT" in r.stderr


def test_another_address_than_loopback_only_when_asked_and_logged():
    (port,) = free_ports(1)
    p = subprocess.Popen(avard("web", "tcp://127.0.0.1:1", "--timeout", "0.2", "--listen",
                               f"0.0.0.0:{port}"), stderr=subprocess.PIPE, text=True)
    try:
        line = p.stderr.readline()
        assert "0.0.0.0" in line and "reachable from the network" in line, line
    finally:
        p.send_signal(signal.SIGTERM)
        assert p.wait(20) == 0
    p = subprocess.Popen(avard("web", "tcp://127.0.0.1:1", "--timeout", "0.2", "--listen",
                               f"127.0.0.1:{port}"), stderr=subprocess.PIPE, text=True)
    try:
        line = p.stderr.readline()
        assert f"http://127.0.0.1:{port}/" in line and "this machine only" in line, line
    finally:
        p.send_signal(signal.SIGTERM)
        # stops on the signal while it still tries to reach the service (a hang fails here
        # with TimeoutExpired; no wall-time figure a loaded machine would break)
        assert p.wait(60) == 0


# ---- the feed threads --------------------------------------------------------------------------


class FakeSubscriber:
    """The Subscriber interface the feed uses, over a list of records."""

    def __init__(self, records: list[tuple[str, dict]], header: dict) -> None:
        self.tracker = LossTracker()
        self.records = list(records)
        self.header: dict | None = header
        self.snapshot: dict | None = None
        self.requests: list[str] = []
        self.closed = False
        # set when the feed asks for more after the last record: it has applied them all
        self.drained = threading.Event()

    @property
    def stats(self):
        return self.tracker.stats

    def connect(self):
        return self

    def recv(self, timeout_s=None):
        if not self.records:
            self.drained.set()
            time.sleep(0.01)
            return None
        topic, rec = self.records.pop(0)
        return self.tracker.observe(topic, rec)

    def request(self, op, args=None, **_kw):
        self.requests.append(op)
        return {"kind": "header", "run": self.tracker.stats.run, "nominal_odr_hz": RATE,
                "i0": 0}

    def close(self):
        self.closed = True


def test_the_feed_fills_the_state_fits_each_new_snapshot_once_and_refetches_the_header():
    from avard.daemon.web.feed import Feed

    new = "20260101T010000Z-bbbbbb"
    snap = snapshot_dict()
    recs = [*a_run(blocks=2),
            ("avar", frames.avar_record(RUN, 0, 20000, 20000, snap, 0.0, 1e9)),
            ("avar", frames.avar_record(RUN, 1, 20000, 20000, snap, 0.0, 1e9)),
            *a_run(new, i0=1000, blocks=2)]
    sub = FakeSubscriber(recs, {"run": RUN, "nominal_odr_hz": RATE, "i0": 0})
    fitted: list[int] = []

    def fit(data: AllanSnapshot) -> dict:
        fitted.append(data.n_samples)
        return {"x": "a fit"}

    state = RunState()
    f = Feed(sub, state, fit=fit, fit_interval_s=0.0)  # type: ignore[arg-type]
    f.start()
    deadline = time.monotonic() + 120  # a bound on a hang only
    while (not sub.drained.is_set() or not state.fits or "header" not in sub.requests) \
            and time.monotonic() < deadline:
        time.sleep(0.02)
    f.stop()
    assert f.error is None and sub.closed
    assert state.runs == [RUN, new]
    assert sub.requests == ["header"]  # only for the new run: the first came on join
    assert state.header["run"] == new
    assert state.fits == {"x": "a fit"} and state.fitted is state.snapshot
    assert 1 <= len(fitted) <= 2 and set(fitted) == {20000}  # never a fit per viewer or message


def test_history_from_the_recording_comes_first_and_live_records_are_not_counted_twice(
        tmp_path):
    from avard.core.io.recording import frame
    from avard.daemon.web.feed import Feed

    old, new = RUN, "20260101T010000Z-bbbbbb"
    disk = [frames.header_record(old, rate_hz=RATE, t_mono=0.0, t_real=1e9, i0=0,
                                 nominal_odr_hz=RATE),
            *[r for _, r in a_run(old, blocks=4)],                      # temps 20.5 … 23.5
            frames.gap_record(old, 0, 300, 20, 2.4, 1e9, "overrun"),
            frames.header_record(new, rate_hz=RATE, t_mono=0.0, t_real=1e9, i0=1000,
                                 nominal_odr_hz=RATE),
            frames.gap_record(new, 0, 500, 500, 0.0, 1e9, "restart"),
            *[r for _, r in a_run(new, i0=1000, blocks=2)]]
    (tmp_path / f"{old}_0000_x.avr").write_bytes(
        b"".join(frame(frames.encode(r)) for r in disk))
    # live: the new run's second block again (already on disk), then two new ones
    live = a_run(new, i0=1125, blocks=3, seq0=1)
    sub = FakeSubscriber(live, {"run": new, "nominal_odr_hz": RATE, "i0": 1000})
    state = RunState()
    f = Feed(sub, state, fit=None,  # type: ignore[arg-type]
             history=RecordingSource(tmp_path))
    f.start()
    assert sub.drained.wait(120)  # every record applied (a bound on a hang only)
    f.stop()
    assert f.error is None
    assert state.runs == [old, new]
    assert state.gaps_by_reason == {"overrun": 1, "restart": 1}  # no inferred second one
    assert state.gap_samples_by_reason == {"overrun": 20, "restart": 500}
    plate = state.temperatures["28-0000plate"]
    assert plate.x == [i / RATE for i in (0, 125, 250, 375, 1000, 1125, 1250, 1375)]
    # disk: 20.5 … 23.5, then 20.5, 21.5; live (values from k = 0): 1125 → 20.5 is the
    # disk's block again and skipped, 1250 → 21.5, 1375 → 22.5
    assert plate.y == [20.5, 21.5, 22.5, 23.5, 20.5, 21.5, 21.5, 22.5]


def test_a_history_directory_that_does_not_exist_is_one_line_and_exit_2(tmp_path):
    r = subprocess.run(avard("web", "tcp://127.0.0.1:1", "--history", str(tmp_path / "no")),
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "--history" in r.stderr


def test_the_temperature_card_says_what_it_covers() -> None:
    """Without --history the plot starts when avard web did, and says so (it said "Whole run
    so far"); with a recording read first it holds the run before."""
    from avard.daemon.web.render import temperatures_html
    from avard.daemon.web.state import RunState

    live = RunState(started=0.0)
    live._temperature("plate", 1.0, 21.5)
    text = temperatures_html(live)
    assert "Since avard web started (1970-01-01 00:00 UTC)" in text
    assert "--history DIR" in text and "Whole run" not in text
    read = RunState(history="/var/lib/avard")
    read._temperature("plate", 1.0, 21.5)
    read.history_done(42)
    assert "The run from the recording in /var/lib/avard, then live" in temperatures_html(read)
    empty = RunState(history="/nowhere")
    empty._temperature("plate", 1.0, 21.5)
    empty.history_done(0)
    assert "nothing was read from --history /nowhere" in temperatures_html(empty)
