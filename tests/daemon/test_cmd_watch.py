"""`avard watch`: the view's numbers, time-to-target, and one view over a real stream."""

from __future__ import annotations

import math
import re
import threading

import numpy as np
import pytest
import zmq
from avard.core.allan.streaming import StreamingAllan
from avard.core.io import frames as F
from avard.daemon import cli
from avard.daemon.commands.watch import WatchView, fmt_duration, time_to_target
from avard.daemon.net.publisher import RequestServer
from avard.daemon.net.subscriber import StreamStats

RATE = 125.0
SIGMA = 1e-3  # m/s² white noise per sample → VRW = σ/√rate


def _snapshot(n: int = 1 << 15, seed: int = 0) -> dict:
    rng = np.random.default_rng(seed)
    sa = StreamingAllan(4, RATE, names=["x", "y", "z", "plate"])
    y = rng.normal(0.0, SIGMA, size=(n, 4))
    y[:, 3] += 21.0
    sa.update(y)
    return sa.snapshot().to_dict()


def test_time_to_target_scales_with_duration() -> None:
    # ±20 % after 1000 s: ±10 % needs 4× the duration, i.e. 3000 s more
    assert time_to_target(1.0, 0.8, 1.2, 1000.0, 0.1) == pytest.approx(3000.0)
    assert time_to_target(1.0, 0.95, 1.05, 1000.0, 0.1) == 0.0
    assert time_to_target(None, None, None, 1000.0, 0.1) is None
    assert time_to_target(1.0, 0.8, 1.2, 0.0, 0.1) is None
    assert fmt_duration(3000.0) == "50 min" and fmt_duration(90) == "90 s"
    assert fmt_duration(7.2e4) == "20.0 h" and fmt_duration(math.inf) == "never"


def test_view_with_a_service_fit() -> None:
    snap = _snapshot(1 << 12)
    T = snap["n_samples"] / RATE
    fit = {"terms": {
        "velocity_random_walk": {"value": 1e-4, "lo": 0.8e-4, "hi": 1.2e-4,
                                 "unit": "m/s/sqrt(s)", "present": True},
        "bias_instability": {"value": None, "lo": None, "hi": 3e-6, "unit": "m/s^2",
                             "present": False}}}
    view = WatchView(target=0.1, taus=(0.1, 1.0))
    view.set_snapshot(snap, fit)
    text = view.render(StreamStats(), "tcp://h:1")
    line = next(ln for ln in text.splitlines() if "velocity_random_walk" in ln)
    assert f"~{fmt_duration(3 * T)} more" in line and "1.000e-04 [8.000e-05, 1.200e-04]" in line
    assert re.search(r"bias_instability\s+not resolved \(< 3\.000e-06 m/s\^2\)", text)
    assert "(service;" in text
    # ADEV rows at the octaves nearest 0.1 s and 1 s, with the snapshot's numbers
    tau = np.asarray(snap["tau"])
    k = int(np.argmin(np.abs(np.log(tau / 1.0))))
    adev_x = math.sqrt(snap["avar"][k][0])
    row = next(ln for ln in text.splitlines() if ln.strip().startswith(f"{tau[k]:.4g} "))
    assert f"{adev_x:.3e}" in row


def test_view_fits_locally_without_a_service_fit() -> None:
    view = WatchView(target=0.1)
    view.set_snapshot(_snapshot())
    vrw = view.fits["x"]["terms"]["velocity_random_walk"]
    assert vrw["present"]
    expected = SIGMA / math.sqrt(RATE)
    assert vrw["lo"] < vrw["value"] < vrw["hi"]
    assert abs(vrw["value"] - expected) / expected < 0.05
    assert "(fitted here;" in view.render(StreamStats())
    # the request socket's answer (a whole avar record) is unwrapped the same way
    other = WatchView()
    other.set_snapshot(F.avar_record("r", 0, 1, 1, _snapshot(1 << 12), 0.0, 0.0,
                                     fit={"terms": {}}))
    assert other.fit_source == "service" and other.snapshot.n_samples == 1 << 12


def test_watch_once_over_a_real_stream(capsys: pytest.CaptureFixture) -> None:
    ctx = zmq.Context()
    pub = ctx.socket(zmq.XPUB)
    pub.setsockopt(zmq.LINGER, 0)
    pub.bind("tcp://127.0.0.1:*")
    endpoint = pub.getsockopt_string(zmq.LAST_ENDPOINT)
    srv = RequestServer("tcp://127.0.0.1:*", {"header": lambda a: {}}).start()
    result: dict = {}
    thread = threading.Thread(target=lambda: result.setdefault("rc", cli.main(
        ["watch", endpoint, "--request", srv.endpoint, "--once", "--timeout", "0.5",
         "--wait", "20", "--target", "0.05"])))
    thread.start()
    try:
        for _ in range(5):
            assert pub.poll(10_000), "watch never subscribed"
            pub.recv()
        send = lambda topic, rec: pub.send_multipart([topic.encode(), F.encode(rec)])  # noqa: E731
        for seq in range(4):
            if seq != 2:
                counts = np.zeros((32, 3), dtype=np.int32)
                send("raw", F.raw_record("run-w", seq, 32 * seq, counts, 0.0, 0.0,
                                         rate_hz=125.0007, chip_temp_c=24.25))
        send("temp", F.temp_record("run-w", 0, 100, ["plate", "air"], [21.5, None], 0.0, 0.0))
        send("avar", F.avar_record("run-w", 0, 128, 1 << 15, _snapshot(), 0.0, 0.0))
        thread.join(60)
    finally:
        srv.stop()
        pub.close()
        ctx.term()
    assert result["rc"] == 0
    out = capsys.readouterr().out
    assert "run run-w" in out and "125.0007 Hz fitted ODR" in out
    assert "96 received; lost in transport 32" in out
    assert "raw 3 (1 lost)" in out
    assert "plate 21.50 °C, air — °C, chip 24.2 °C" in out
    assert "x [m/s²]" in out and "plate [°C]" in out
    assert re.search(r"velocity_random_walk\s+\d\.\d{3}e-05 \[", out)


@pytest.mark.parametrize(
    "snapshot",
    [
        {"tau": [1, [2, 3]], "avar": [[1.0]]},                 # ragged
        {"tau": ["a", "b"], "avar": [[1.0], [2.0]]},           # strings
        {"tau": [1.0, 2.0], "avar": {"x": 1}},                 # wrong type
        {"tau": [1.0, 2.0], "avar": [[1.0]], "names": 5},      # short arrays, bad names
        "not a map",
    ],
)
def test_view_survives_hostile_snapshots(snapshot: object) -> None:
    view = WatchView(fit_locally=True)
    view.set_snapshot({"snapshot": snapshot, "fit": {"terms": {"quantization": 5}}})
    text = view.render(StreamStats())
    assert text.startswith("avard watch")


def _full_view() -> WatchView:
    view = WatchView(target=0.1, taus=(0.1, 1, 10, 100, 1000))
    view.set_snapshot(_snapshot(1 << 16))
    view.temps = {"plate": 21.5, "air": 22.125}
    view.chip_temp_c = 24.3
    view.odr_hz = 125.0007
    view.run = "20261123T2000Z-ab12"
    view.events = ["gap of 32 samples (overrun)"]
    return view


@pytest.mark.parametrize(("width", "height"), [(80, 24), (120, 40)])
def test_the_view_fits_the_terminal_with_the_essentials_on_it(width: int, height: int) -> None:
    view = _full_view()
    stats = StreamStats()
    stats.samples_received, stats.samples_lost = 4096, 64
    lines = view.render(stats, "tcp://raspberrypi.local:5555", width=width,
                        height=height).splitlines()
    assert len(lines) <= height and max(map(len, lines)) <= width
    text = "\n".join(lines)
    assert "125.0007 Hz fitted ODR" in text
    assert "4096 received; lost in transport 64" in text
    assert "plate 21.50 °C, air 22.12 °C, chip 24.3 °C" in text
    # ADEV at every shown τ, each accelerometer channel with its interval
    snap = view.snapshot
    tau = snap.tau
    for want in (0.1, 1.0, 10.0, 100.0):
        k = int(np.argmin(np.abs(np.log(tau / want))))
        row = next(ln for ln in lines if ln.strip().startswith(f"{tau[k]:.4g} "))
        for c in range(3):
            v = math.sqrt(snap.avar[k, c])
            lo, hi = math.sqrt(snap.lo[k, c]), math.sqrt(snap.hi[k, c])
            if width >= 120:   # room for the interval's ends
                assert f"{v:.3e} [{lo:.2e}, {hi:.2e}]" in row
            else:              # the interval as −/+ percent of the value
                m = re.search(rf"{v:.3e} -([\d.]+)/\+([\d.]+)%", row)
                assert m is not None, row
                assert float(m.group(1)) == pytest.approx((v - lo) / v * 100, rel=0.05, abs=0.06)
                assert float(m.group(2)) == pytest.approx((hi - v) / v * 100, rel=0.05, abs=0.06)
    # the fit with its time to the target interval, for every accelerometer channel
    vrw = {ch: f["terms"]["velocity_random_walk"] for ch, f in view.fits.items()}
    assert set(vrw) == {"x", "y", "z"}
    for est in vrw.values():
        assert f"{est['value']:.3e}" in text
    if width >= 120:
        assert re.search(r"velocity_random_walk\s+\S+ \[\S+, \S+\] m/s/sqrt\(s\)\s+reached",
                         text)
    else:
        n_row = next(ln for ln in lines if ln.strip().startswith("N [m/s/√s]"))
        assert n_row.count(" ok") == 3 and n_row.count("±") == 3
    assert "gap of 32 samples" in text


def test_a_short_terminal_keeps_the_first_lines_and_says_there_is_more() -> None:
    lines = _full_view().render(StreamStats(), "tcp://h:1", width=80, height=10).splitlines()
    assert len(lines) == 10
    assert lines[1].startswith("rate") and lines[-1].startswith("…")


def test_without_a_terminal_nothing_is_cut() -> None:
    text = _full_view().render(StreamStats(), "tcp://h:1")
    assert "…" not in text and "plate [°C]" in text   # every channel, full intervals


# ---- how old the view is; skipping stale snapshots; endpoints ---------------------------------


class _Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def test_a_view_behind_the_stream_fits_only_the_newest_snapshot() -> None:
    from avard.daemon.net.subscriber import Message

    view = WatchView(target=0.1)
    snaps = [_snapshot(1 << 12, seed=k) for k in range(5)]
    for k, snap in enumerate(snaps):  # five snapshots queued before the view is drawn
        view.update(Message("avar", F.avar_record("r", k, (k + 1) << 12, 1 << 12, snap,
                                                  0.0, 0.0)))
    assert view.fits_computed == 0
    view.render(StreamStats())
    view.render(StreamStats())
    assert view.fits_computed == 1
    # ... and that one fit is of the last snapshot
    newest = WatchView(target=0.1)
    newest.set_snapshot(snaps[-1])
    assert view.fits == newest.fits


def test_the_view_says_how_old_it_is_and_when_nothing_arrives() -> None:
    from avard.daemon.net.subscriber import Message

    clock = _Clock()
    view = WatchView(clock=clock)
    clock.t = 12.0
    text = view.render(StreamStats(), "tcp://pi:5555")
    assert "nothing received from tcp://pi:5555 in 12 s: is the service running there" in text
    counts = np.zeros((125, 3), dtype=np.int32)
    view.update(Message("avar", F.avar_record("r", 0, 1000, 1000, _snapshot(1 << 12),
                                               0.0, 0.0, fit={"terms": {}})))
    view.update(Message("raw", F.raw_record("r", 0, 1000 + 2 * 125, counts, 0.0, 0.0)))
    clock.t = 14.0
    line = next(ln for ln in view.render(StreamStats()).splitlines()
                if ln.startswith("data "))
    assert line == ("data      arriving; snapshot received 2 s ago, 3 s of data behind the "
                    "newest sample")
    clock.t = 30.0
    assert "nothing new for 18 s: the view below is that old" in view.render(StreamStats())


@pytest.mark.parametrize(("endpoint", "words"), [
    ("tcp://127.0.0.1:100000", "port 100000 is not a TCP port (1–65535)"),
    ("tcp://127.0.0.1:0", "port 0 is not a TCP port"),
    ("tcp://no-such-host.invalid:5555", "'no-such-host.invalid' does not resolve"),
    ("tcp://127.0.0.1", "write tcp://HOST:PORT"),
])
def test_watch_refuses_an_endpoint_it_cannot_reach_in_one_line(
        endpoint: str, words: str, capsys: pytest.CaptureFixture) -> None:
    assert cli.main(["watch", endpoint]) == 2
    err = capsys.readouterr().err.strip()
    assert words in err and len(err.splitlines()) == 1, err
    assert "is the service running" not in err
