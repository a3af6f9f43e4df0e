"""Restore after restarts feeds back every recorded sample, whatever run wrote it (#16 item 1).

Runs that record samples but are SIGKILLed before their first checkpoint leave the state
file of an earlier run behind. The next start must replay everything recorded after that
checkpoint, including the killed runs' samples; the final accumulators then equal the
offline Allan of the whole recording and an independent numpy overlapping AVAR (NIST SP 1065
eq. 12 with the stride of ``avard.core.allan.streaming``), to 1e-12.
"""

from __future__ import annotations

import itertools
import math
import signal
import time
from pathlib import Path

import numpy as np
from avard.core.allan.streaming import StreamingAllan
from avard.core.io import frames
from avard.core.io.recording import RecordingReader, load_recording, replay_allan, scan_frames

from .test_faults_sigkill import NotifySocket, _spawn

CONFIG = """
[allan]
snapshot_interval_s = 2.0
checkpoint_interval_s = 3600.0
[recording]
fsync_interval_s = 0.5
block_s = 0.5
[publish]
enabled = false
[sensor]
poll_hz = 4.0
"""


def _numpy_avar(path: Path, rate: float, overlap: int,
                ms: np.ndarray) -> tuple[int, np.ndarray, list[int]]:
    """Pooled partially overlapping AVAR of x, y, z from the raw records, written apart from
    avard's readers: the samples the service fed are those of each run from the first index
    at which every temperature channel of that run has a reading; segments end at every gap
    record, run change and index jump."""
    recs = list(RecordingReader(path))
    runs: dict[str, dict] = {}
    for r in recs:
        if r["kind"] == "header" and r["run"] not in runs:
            runs[r["run"]] = {"scale": r["scale_m_s2_per_count"],
                              "names": list(r["temperature_channels"]), "first": {}}
    for r in recs:
        if r["kind"] == "temp":
            first = runs[r["run"]]["first"]
            for name, v in zip(r["names"], r["values_c"], strict=True):
                if v is not None and name not in first:
                    first[name] = r["i0"]
    segments: list[list[np.ndarray]] = [[]]
    lengths = [0]                              # every recorded sample, per segment
    run, nxt = None, None
    for r in recs:
        if r["kind"] == "gap" or (r["kind"] == "header" and r["run"] != run):
            run = r["run"] if r["kind"] == "header" else run
            segments.append([])
            lengths.append(0)
            nxt = None
        elif r["kind"] == "raw":
            info = runs[r["run"]]
            if nxt is not None and r["i0"] != nxt:
                segments.append([])
                lengths.append(0)
            nxt = r["i0"] + r["n"]
            lengths[-1] += r["n"]
            if len(info["first"]) < len(info["names"]):
                continue
            start = max(info["first"].values(), default=0)
            keep = r["i0"] + np.arange(r["n"]) >= start
            segments[-1].append(np.asarray(r["counts"], float)[keep] * info["scale"])
    n_total = 0
    sums, counts = np.zeros((len(ms), 3)), np.zeros(len(ms))
    for seg in segments:
        if not seg:
            continue
        y = np.concatenate(seg)
        if not len(y):                         # recorded before every channel had a reading
            continue
        n_total += len(y)
        x = np.concatenate([np.zeros((1, 3)), np.cumsum(y - y[0], axis=0)]) / rate
        for k, m in enumerate(ms):
            stride = max(1, m // overlap)
            i = np.arange(0, len(x) - 2 * m, stride)
            d = x[i + 2 * m] - 2 * x[i + m] + x[i]
            sums[k] += (d**2).sum(axis=0)
            counts[k] += len(i)
    tau = ms / rate
    return (n_total, sums / (2 * tau[:, None] ** 2 * counts[:, None]),
            [n for n in lengths if n])


def _wait_for_fed_sample(path: Path, before: int, timeout_s: float = 60.0) -> bool:
    """Wait until the newest run (the one after ``before`` earlier runs) has a raw sample
    recorded at or after the first index where every temperature channel has a reading: the
    first sample the service feeds to the accumulators. Polls the recording (a torn tail is
    what a live writer leaves, and the reader skips it)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        runs: list[str] = []
        names: dict[str, list[str]] = {}
        first: dict[str, int] = {}
        last_raw = -1
        for r in RecordingReader(path):
            if r["kind"] == "header" and r["run"] not in names:
                runs.append(r["run"])
                names[r["run"]] = list(r["temperature_channels"])
                # the newest run's own readings and samples only: an earlier run's had
                # passed the test as soon as the new run's header was on disk, before it
                # recorded any sample (the kill then left a run with none; flaky under load)
                first, last_raw = {}, -1
            if not runs or r.get("run") != runs[-1]:
                continue
            if r["kind"] == "temp":
                for name, v in zip(r["names"], r["values_c"], strict=True):
                    if v is not None:
                        first.setdefault(name, r["i0"])
            elif r["kind"] == "raw":
                last_raw = max(last_raw, r["i0"] + r["n"] - 1)
        if (len(runs) > before and len(first) == len(names[runs[-1]])
                and last_raw >= max(first.values(), default=0)):
            return True
        time.sleep(0.05)
    return False


def test_runs_killed_before_their_first_checkpoint_are_replayed_on_restore(tmp_path):
    (tmp_path / "avard.toml").write_text(CONFIG)
    notify = NotifySocket(tmp_path / "notify.sock")
    ckpt = tmp_path / "rec" / "allan-state.ckpt"
    try:
        p = _spawn(tmp_path, notify, 1, "--duration", "3")
        assert p.wait(timeout=120) == 0
        first_ckpt = ckpt.read_bytes()         # written at the clean stop
        for k in range(3):
            notify.drain()                     # READY=1 of this run, not of the last
            p = _spawn(tmp_path, notify, 10 + k)
            assert notify.wait_ready(), "no READY=1 within 60 s"
            # a sample the service fed is on disk; no checkpoint is due (one hour away)
            assert _wait_for_fed_sample(tmp_path / "rec", before=k + 1), \
                "no fed sample recorded within 60 s"
            p.send_signal(signal.SIGKILL)
            p.wait(timeout=30)
            assert ckpt.read_bytes() == first_ckpt   # killed before its first checkpoint
        p = _spawn(tmp_path, notify, 20, "--duration", "3")
        assert p.wait(timeout=120) == 0
    finally:
        notify.close()
    log = (tmp_path / "stderr-20.log").read_text()
    assert "restored the Allan accumulators" in log
    runs = {r["run"] for r in RecordingReader(tmp_path / "rec") if r["kind"] == "raw"}
    assert len(runs) == 5                      # every run recorded samples
    state = frames.decode(next(scan_frames(ckpt.read_bytes())).payload)["state"]
    final = StreamingAllan.from_state(state)
    snap = final.snapshot()
    offline = replay_allan(tmp_path / "rec").snapshot()
    assert snap.n_samples == offline.n_samples
    np.testing.assert_allclose(snap.avar, offline.avar, rtol=1e-12, atol=0)
    ms = np.asarray(snap.m)
    n, avar, lengths = _numpy_avar(tmp_path / "rec", final.rate_hz, final.overlap, ms)
    assert n == snap.n_samples
    ok = np.isfinite(avar[:, 0])               # levels with at least one difference
    assert ok.sum() >= 6
    np.testing.assert_allclose(np.asarray(snap.avar)[ok, :3], avar[ok], rtol=1e-12, atol=0)
    # avard analyze splits this killed-and-restarted recording where the service did
    bounds = load_recording(tmp_path / "rec").meta["segment_bounds"]
    assert len(lengths) >= 5 and np.diff(bounds).tolist() == lengths


def test_the_first_checkpoint_comes_one_interval_after_the_first_sample(tmp_path):
    """Not at once (the Allan worker's timers used to start at t = 0 when its first chunk held
    only marks, so every run checkpointed immediately)."""
    from avard.daemon.compose import simulated_service
    from avard.daemon.config import load_config

    cfg = load_config(None, **{"recording.data_dir": str(tmp_path / "rec"),
                               "publish.enabled": False, "sensor.poll_hz": 1.0,
                               "allan.checkpoint_interval_s": 5.0})
    # paced (2× real time): drains are then small, as on the device, and the timers act
    # within one read of the Allan stage (its 0.25 s batch, 0.5 s of data at 2×) of their time
    svc, _sims, _emu = simulated_service(cfg, "quiet-lab", seed=2, speed=2.0)
    svc.run(17.0)
    recs = list(RecordingReader(tmp_path / "rec"))
    raw = [r for r in recs if r["kind"] == "raw"]
    t0 = min(r["t_mono"] for r in raw)         # the first sample's time (a block's first)
    ckpts = [r for r in recs if r["kind"] == "checkpoint"]
    # How many checkpoints come depends on how the threads were scheduled (at most one per
    # chunk the Allan stage takes, and a lagging stage takes long chunks), so the test asks
    # what does not: every checkpoint before the one of the clean stop comes at a sample time
    # past a new deadline t0 + k·5 s (never before the first, and at most one per interval);
    # the reader stops at 17 s of sample time, so there is at least one; and together their
    # checks cover every recorded sample, each taking up where the last one ended.
    due = [math.floor((c["t_mono"] - t0) / 5.0 + 1e-9) for c in ckpts[:-1]]
    assert due and due[0] >= 1, [c["t_mono"] - t0 for c in ckpts]
    assert all(a < b for a, b in itertools.pairwise(due)), due
    spans = [(c["check"]["from"], c["check"]["to"]) for c in ckpts]
    assert spans[0][0] == raw[0]["i0"] and spans[-1][1] == raw[-1]["i0"] + raw[-1]["n"], spans
    assert all(a[1] == b[0] for a, b in itertools.pairwise(spans)), spans
