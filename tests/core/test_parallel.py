"""Exact parallel analysis (issue #29): a record cut into chunks by time, each chunk's part
of the OADEV and of the spectrum, the parts added up — equal to one pass over the record."""

from __future__ import annotations

import itertools
from functools import partial

import numpy as np
import pytest
from avard.core.allan.noise_id import Lag1Ladder
from avard.core.allan.overlapping import LADDER_REACH, OadevPart, OverlappingAllan
from avard.core.analysis.engine import analyze
from avard.core.analysis.options import AnalyzeOptions
from avard.core.analysis.parallel import Chunk, alignment, plan_chunks
from avard.core.analysis.spectrum import WelchAccumulator
from avard.core.errors import DataError
from avard.core.io.source import open_record
from hypothesis import given, settings
from hypothesis import strategies as st


def _feed(acc: OverlappingAllan | WelchAccumulator, y: np.ndarray, bounds: list[int],
          lo: int, hi: int, block: int) -> None:
    """Samples [lo, hi) of y in blocks of ``block``, with a gap at every segment end."""
    for s0, s1 in itertools.pairwise(bounds):
        a, b = max(s0, lo), min(s1, hi)
        if a >= b:
            continue
        for i in range(a, b, block):
            acc.update(y[i:min(i + block, b)])
        if b == s1:
            acc.gap()


def _chunked(y, bounds, ms, cuts, *, covariance=False, block=4099) -> OadevPart:
    n = len(y)
    edges = [0, *cuts, n]
    parts = []
    for a, b in itertools.pairwise(edges):
        acc = OverlappingAllan(y.shape[1], 10.0, ms, covariance=covariance, own_from=a,
                               own_until=b if b < n else None)
        _feed(acc, y, bounds, 0, min(n, b + LADDER_REACH * int(ms[-1])), block)
        parts.append(acc.part())
    total = parts[0]
    for p in parts[1:]:
        total = total + p
    return total


def _ladder_gap(a: Lag1Ladder, b: Lag1Ladder) -> float:
    """Largest relative difference between two ladders' sums (b re-referenced to a's)."""
    diff = Lag1Ladder(a.c, a.dmax, cross=a.cross)
    diff.add(a)
    diff.add(b, -1)
    ta, td = a.totals(), diff.totals()
    worst = 0.0
    for f in Lag1Ladder.FIELDS:
        scale = np.max(np.abs(ta[f])) or 1.0
        worst = max(worst, float(np.max(np.abs(td[f]))) / scale)
    return worst


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), channels=st.integers(1, 3), n_gaps=st.integers(0, 3),
       n_cuts=st.integers(1, 4), counts=st.booleans(), covariance=st.booleans(),
       off_grid=st.booleans())
def test_chunk_parts_add_up_to_one_pass(seed, channels, n_gaps, n_cuts, counts, covariance,
                                        off_grid):
    """Cuts on the longest τ's grid or anywhere (``off_grid``: an average of some τ then
    straddles each cut, and belongs to the earlier chunk alone)."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(6000, 20000))
    y = rng.normal(0, 1e-3, (n, channels)) + np.cumsum(rng.normal(0, 3e-6, (n, channels)), 0)
    y += 9.81
    if counts:  # integer raw counts: exact int64 running sums
        y = np.round(y * 1e4).astype(np.int32)
    ms = 2 ** np.arange(int(rng.integers(4, 10)))
    gaps = sorted(rng.choice(np.arange(200, n - 200), n_gaps, replace=False).tolist())
    bounds = [0, *gaps, n]
    align = int(rng.integers(1, int(ms[-1]))) if off_grid and ms[-1] > 1 else int(ms[-1])
    points = [s0 + j * align for s0, s1 in itertools.pairwise(bounds)
              for j in range(1, (s1 - s0) // align + 1) if s0 + j * align < s1]
    if not points:
        return
    cuts = sorted(rng.choice(points, min(n_cuts, len(points)), replace=False).tolist())

    one = OverlappingAllan(channels, 10.0, ms, covariance=covariance)
    _feed(one, y, bounds, 0, n, 4099)
    total = _chunked(y, bounds, ms, cuts, covariance=covariance)
    assert total.n_samples == n
    got = OverlappingAllan.from_part(total, 10.0, covariance=covariance).result()
    ref = one.result()
    assert np.array_equal(got.n, ref.n)
    ok = np.isfinite(ref.var)
    np.testing.assert_array_equal(np.isfinite(got.var), ok)
    np.testing.assert_allclose(got.var[ok], ref.var[ok], rtol=1e-12, atol=0)
    np.testing.assert_array_equal(got.alpha, ref.alpha)
    np.testing.assert_allclose(got.edf[ok], ref.edf[ok], rtol=1e-12)
    if covariance:
        np.testing.assert_allclose(got.cov, ref.cov, rtol=1e-12, atol=1e-30)
    for k in range(len(ms)):
        assert _ladder_gap(one._ladders[k], total.ladders[k]) < 1e-12


def test_parts_add_associatively() -> None:
    rng = np.random.default_rng(4)
    n = 12000
    y = rng.normal(0, 1e-3, (n, 2))
    ms = 2 ** np.arange(8)
    edges = [0, 2560, 6144, 9216, n]
    parts = []
    for a, b in itertools.pairwise(edges):
        acc = OverlappingAllan(2, 10.0, ms, own_from=a, own_until=b if b < n else None)
        _feed(acc, y, [0, n], 0, min(n, b + LADDER_REACH * 128), 1000)
        parts.append(acc.part())
    left = (parts[0] + parts[1]) + (parts[2] + parts[3])
    right = parts[0] + (parts[1] + (parts[2] + parts[3]))
    np.testing.assert_array_equal(left.n, right.n)
    np.testing.assert_allclose(left.s2, right.s2, rtol=1e-13)
    for a_lad, b_lad in zip(left.ladders, right.ladders, strict=True):
        assert _ladder_gap(a_lad, b_lad) < 1e-13


def test_a_merge_of_independent_chunks_loses_what_straddles_the_cuts() -> None:
    """Why the chunk reads past its end: without it (each chunk alone, as
    ``StreamingAllan.merge`` pools segments) the long-τ differences across a cut are lost."""
    rng = np.random.default_rng(8)
    n = 8192
    y = rng.normal(0, 1e-3, (n, 1))
    ms = 2 ** np.arange(11)
    one = OverlappingAllan(1, 10.0, ms)
    one.update(y)
    alone = [OverlappingAllan(1, 10.0, ms) for _ in range(2)]
    alone[0].update(y[:4096])
    alone[1].update(y[4096:])
    lost = one.part().n - (alone[0].part() + alone[1].part()).n
    np.testing.assert_array_equal(lost, 2 * ms - 1)  # the 2m − 1 differences across the cut
    assert lost[-1] / one.part().n[-1] > 0.3  # a third of the longest τ's differences
    exact = _chunked(y, [0, n], ms, [4096])
    assert np.array_equal(exact.n, one.part().n)


def test_welch_parts_add_up_to_one_spectrum() -> None:
    rng = np.random.default_rng(2)
    n, nper = 40000, 1024
    y = rng.normal(0, 1e-3, (n, 2)) + 9.81
    y[:, 0] += 1e-3 * np.sin(2 * np.pi * 3.3 * np.arange(n) / 100.0)
    bounds = [0, 17000, n]
    one = WelchAccumulator(2, 100.0, nper)
    _feed(one, y, bounds, 0, n, 3000)
    total = WelchAccumulator(2, 100.0, nper)
    for a, b in [(0, 8192), (8192, 17000 + 4 * 512), (17000 + 4 * 512, n)]:
        w = WelchAccumulator(2, 100.0, nper)
        _feed(w, y, bounds, a, min(n, b + nper // 2) if b < n else n, 3000)
        total.add(w.part())
    assert total.n_seg == one.n_seg
    np.testing.assert_allclose(total.result()[1], one.result()[1], rtol=1e-12)


def test_a_long_block_gives_the_spectrum_of_one_worker_blocks() -> None:
    """A block longer than ``SEGMENT_BATCH`` (a parallel chunk's) has its segments
    transformed a batch at a time: the same segments and power sums as one-worker blocks."""
    from avard.core.analysis import spectrum

    rng = np.random.default_rng(8)
    n, nper = 3 * spectrum.SEGMENT_BATCH + 777, 2048
    y = rng.normal(0, 1e-3, (n, 2)) + 1e-3 * np.sin(np.arange(n) / 30.0)[:, None]
    calls = []
    real = np.fft.rfft

    def counted(a, *args, **kwargs):
        calls.append(a.shape[0])
        return real(a, *args, **kwargs)

    long_, short = WelchAccumulator(2, 100.0, nper), WelchAccumulator(2, 100.0, nper)
    np.fft.rfft, saved = counted, np.fft.rfft
    try:
        long_.update(y)
    finally:
        np.fft.rfft = saved
    for i in range(0, n, spectrum.SEGMENT_BATCH):
        short.update(y[i:i + spectrum.SEGMENT_BATCH])
    assert long_.n_seg == short.n_seg == (n - nper) // (nper // 2) + 1
    assert max(calls) <= spectrum.SEGMENT_BATCH // (nper // 2) + 1 and len(calls) >= 3
    np.testing.assert_allclose(long_.part().power, short.part().power, rtol=1e-12)


def test_chunks_are_cut_on_the_alignment_of_their_own_segment() -> None:
    bounds = [0, 1000, 70000, 100000]
    chunks = plan_chunks(bounds, 3, 4096, 16384)
    assert chunks[0].start == 0 and chunks[-1].stop == 100000
    for c in chunks[1:]:
        seg = max(b for b in bounds[:-1] if b <= c.start)
        assert c.start > seg and (c.start - seg) % 4096 == 0
    for a, b in itertools.pairwise(chunks):
        assert a.stop == b.start and a.read_to == min(100000, a.stop + 16384)
    # no stretch longer than the alignment: one chunk, the whole record
    assert plan_chunks([0, 3000, 6000], 4, 4096, 16384) == [Chunk(0, 6000, 6000)]
    assert alignment(1 << 14) == 8192 and alignment(None) == 1


def _assert_one_workers(one, par) -> None:
    """``par`` has ``one``'s ADEV and α to 1e-12, its EDF, lines (frequency 1e-12,
    amplitude 1e-9) and terms (presence, value 1e-9) to 1e-9. The EDF is the fit's: a
    drift the time domain holds short of its level sets the longest τ's EDF through its
    floor (``NoiseFit.drift_floor``), a continuous function of the block means, which a cut
    stream sums in another order (equal to one pass's to 1e-13,
    ``test_block_sums_of_chunks_add_up_to_one_passs_block_means``); the likelihood's
    profile carries that to 2e-12 of the EDF, so the EDF is held as the terms are."""
    assert par.n_samples == one.n_samples
    for name, ch in one.channels.items():
        a, b = ch.allan, par.channels[name].allan
        np.testing.assert_allclose(b.dev, a.dev, rtol=1e-12)
        np.testing.assert_array_equal(b.alpha, a.alpha)
        np.testing.assert_allclose(b.edf, a.edf, rtol=1e-9)
        assert len(par.channels[name].lines) == len(ch.lines)
        for la, lb in zip(ch.lines, par.channels[name].lines, strict=True):
            assert lb["frequency_hz"] == pytest.approx(la["frequency_hz"], rel=1e-12)
            assert lb["amplitude"] == pytest.approx(la["amplitude"], rel=1e-9)
        for term, e in ch.fit.terms.items():
            f = par.channels[name].fit.terms[term]
            assert f.present == e.present
            if e.present:
                assert f.value == pytest.approx(e.value, rel=1e-9)


@pytest.mark.parametrize("workers", [2, 3])
def test_analyze_on_workers_equals_one_worker(tmp_path, monkeypatch, workers) -> None:
    from avard.core.analysis import parallel

    monkeypatch.setattr(parallel, "cores", lambda: 4)  # three workers even on two cores
    rng = np.random.default_rng(11)
    n = 1 << 17
    y = rng.normal(0, 1e-3, (n, 3)) + np.cumsum(rng.normal(0, 2e-6, (n, 3)), axis=0)
    y += np.array([0.0, 0.0, 9.81])
    y[:, 1] += 3e-4 * np.sin(2 * np.pi * 1.7 * np.arange(n) / 100.0)
    path = tmp_path / "r.npz"
    np.savez(path, accel=y, rate_hz=100.0)
    one = analyze(open_record(path))
    par = analyze(open_record(path), AnalyzeOptions(workers=workers))
    _assert_one_workers(one, par)


def _spy_plans(monkeypatch) -> list[list[list[Chunk]]]:
    """The chunk plans of the parallel analyses that follow."""
    from avard.core.analysis import parallel

    plans: list[list[list[Chunk]]] = []
    real = parallel.plan_passes

    def spy(*args, **kwargs):
        plans.append(real(*args, **kwargs))
        return plans[-1]

    monkeypatch.setattr(parallel, "plan_passes", spy)
    return plans


def _off_grid(plan: list[list[Chunk]], bounds: list[int], m_max: int) -> bool:
    """Some cut of ``plan`` falls off the longest τ's grid of its segment."""
    cuts = [c.start for chunks in plan for c in chunks[1:]]
    return any((c - max(b for b in bounds[:-1] if b <= c)) % m_max for c in cuts)


def test_cuts_off_the_tau_grid_with_gaps_equal_one_worker(tmp_path, monkeypatch) -> None:
    """Records pooled as the segments of one (a gap between each), one channel cut into 2
    and 3 chunks: the cuts fall on the Welch hop, off the longest τ's grid, so averages of
    the long τ straddle them; the result is one worker's."""
    from avard.core.analysis.engine import analyze_records

    rng = np.random.default_rng(40)
    paths = []
    for k, n in enumerate((70000, 23000, 52000)):
        y = rng.normal(0, 1e-3, n) + np.cumsum(rng.normal(0, 2e-6, n))
        y += 3e-4 * np.sin(2 * np.pi * 1.7 * np.arange(n) / 100.0)
        p = tmp_path / f"r{k}.npz"
        np.savez(p, accel=y + 9.81, rate_hz=100.0)
        paths.append(p)
    from avard.core.analysis import engine

    plans = _spy_plans(monkeypatch)
    ladders: list[list[Lag1Ladder]] = []  # the noise identification's sums behind α
    finish = engine._finish_pass

    def kept(sa, *args, **kwargs):
        ladders.append(list(sa._ladders))
        return finish(sa, *args, **kwargs)

    monkeypatch.setattr(engine, "_finish_pass", kept)
    one = analyze_records([open_record(p) for p in paths])
    for chunks in (2, 3):
        par = analyze_records([open_record(p) for p in paths], chunks=chunks)
        m_max = int(par.channels["ch0"].allan.m[-1])
        assert len(plans[-1][0]) == chunks
        assert _off_grid(plans[-1], [0, 70000, 93000, 145000], m_max)
        _assert_one_workers(one, par)
        assert max(_ladder_gap(a, b) for a, b in zip(ladders[0], ladders[-1],
                                                      strict=True)) < 1e-12


def test_three_axes_cut_off_the_tau_grid_equal_one_worker(tmp_path, monkeypatch) -> None:
    """Three axes on two workers, the input screen judging blocks of 4096 in the chunks:
    the cut pass is cut on the screen's blocks, off the longest τ's grid; the result is one
    worker's."""
    rng = np.random.default_rng(41)
    n = 150000
    y = rng.normal(0, 1e-3, (n, 3)) + np.cumsum(rng.normal(0, 2e-6, (n, 3)), axis=0)
    y[:, 1] += 3e-4 * np.sin(2 * np.pi * 1.7 * np.arange(n) / 100.0)
    path = tmp_path / "r.npz"
    np.savez(path, accel=y + np.array([0.0, 0.0, 9.81]), rate_hz=100.0)
    plans = _spy_plans(monkeypatch)
    one = analyze(open_record(path), AnalyzeOptions(block=4096))
    par = analyze(open_record(path), AnalyzeOptions(block=4096, workers=2))
    assert sorted(len(p) for p in plans[-1]) == [1, 1, 2]
    assert _off_grid(plans[-1], [0, n], int(par.channels["x"].allan.m[-1]))
    _assert_one_workers(one, par)


def test_analyze_on_workers_reads_r_n_again_as_one_worker(tmp_path) -> None:
    """A channel whose long τ B1 calls PM gets its deferred R(n) read again after the
    parallel pass, as after one pass: the same α at every τ."""
    rng = np.random.default_rng(21)
    n = 1 << 15
    pm = np.diff(rng.normal(0, 1e-3, n + 1))  # white PM as rate data: differenced white
    y = np.stack([pm, rng.normal(0, 1e-3, n)], axis=1)
    path = tmp_path / "pm.npz"
    np.savez(path, accel=y, rate_hz=10.0, axes=np.array(["pm", "fm"]))
    one = analyze(open_record(path), AnalyzeOptions(find_sinusoids=False))
    par = analyze(open_record(path), AnalyzeOptions(find_sinusoids=False, workers=2))
    for name in ("pm", "fm"):
        a, b = one.channels[name].allan, par.channels[name].allan
        np.testing.assert_array_equal(b.alpha, a.alpha)
        np.testing.assert_allclose(b.dev, a.dev, rtol=1e-12)


def test_workers_must_be_a_positive_whole_number() -> None:
    for bad in (0, -1, 1.5, True, "two"):
        with pytest.raises(DataError, match="workers"):
            AnalyzeOptions(workers=bad)


def test_a_worker_that_dies_is_an_error_not_a_wait(tmp_path, monkeypatch) -> None:
    """A worker killed mid-chunk (out of memory, a signal) ends the analysis with an error
    that says so: a pool that lost a task would otherwise wait for it forever."""
    import os

    from avard.core.analysis import parallel
    from avard.core.errors import AvardError

    rng = np.random.default_rng(3)
    path = tmp_path / "r.npz"
    np.savez(path, accel=rng.normal(0, 1e-3, (1 << 16, 2)), rate_hz=100.0)
    real = parallel.chunk_part

    def dies_on_the_second(job, i, *flag):
        if i == 1 or job.names == ["ch1"]:  # a chunk of the second channel, or the second
            os._exit(9)  # the forked worker vanishes, as under the OOM killer
        return real(job, i, *flag)

    monkeypatch.setattr(parallel, "chunk_part", dies_on_the_second)
    with pytest.raises(AvardError, match=r"worker process .* died"):
        analyze(open_record(path), AnalyzeOptions(workers=2))


def test_more_workers_than_cores_run_on_the_cores_and_say_so(tmp_path, monkeypatch,
                                                             caplog) -> None:
    """--workers far above the cores: one line says so, the analysis runs on as many
    processes as cores (more would be no faster and would each hold a history) and its
    result is one worker's; planning such a count stays a few comparisons."""
    from avard.core.analysis import parallel

    monkeypatch.setattr(parallel, "cores", lambda: 2)
    pools: list[int] = []
    real_pool = parallel.ProcessPoolExecutor

    def counted(n, **kwargs):
        pools.append(n)
        return real_pool(n, **kwargs)

    monkeypatch.setattr(parallel, "ProcessPoolExecutor", counted)
    rng = np.random.default_rng(12)
    n = 1 << 17
    y = rng.normal(0, 1e-3, (n, 3)) + np.cumsum(rng.normal(0, 2e-6, (n, 3)), axis=0)
    path = tmp_path / "r.npz"
    np.savez(path, accel=y + np.array([0.0, 0.0, 9.81]), rate_hz=100.0)
    one = analyze(open_record(path))
    with caplog.at_level("WARNING", logger="avard.core.analysis.engine"):
        par = analyze(open_record(path), AnalyzeOptions(workers=64))
    said = [r.getMessage() for r in caplog.records if "workers=64" in r.getMessage()]
    assert len(said) == 1 and "2 worker processes" in said[0]
    assert pools and max(pools) <= 2
    _assert_one_workers(one, par)
    made = [0]
    makespan = parallel._makespan

    def count(*args):
        made[0] += 1
        return makespan(*args)

    monkeypatch.setattr(parallel, "_makespan", count)
    plan = parallel.plan_passes(3, [0, 1 << 24], 64, 8192, 1 << 22)
    assert made[0] <= 64 and len(plan) == 3
    for chunks in plan:
        assert chunks[0].start == 0 and chunks[-1].stop == 1 << 24


def test_the_workers_are_forked_with_the_parents_objects_frozen(tmp_path, monkeypatch):
    """The workers start with this process's objects out of the collector's reach (their
    collections would otherwise copy every page those objects sit on), and this process
    gets them back once the workers are forked."""
    import gc
    import os

    from avard.core.analysis import parallel

    seen = tmp_path / "frozen"
    real = parallel.chunk_part

    def noted(job, i, *flag):
        with open(seen, "a") as f:
            f.write(f"{os.getpid()} {gc.get_freeze_count()}\n")
        return real(job, i, *flag)

    monkeypatch.setattr(parallel, "chunk_part", noted)
    rng = np.random.default_rng(5)
    path = tmp_path / "r.npz"
    np.savez(path, accel=rng.normal(0, 1e-3, (1 << 16, 2)), rate_hz=100.0)
    assert gc.get_freeze_count() == 0
    analyze(open_record(path), AnalyzeOptions(workers=2))
    rows = [line.split() for line in seen.read_text().splitlines()]
    assert rows and all(int(pid) != os.getpid() and int(n) > 1000 for pid, n in rows)
    assert gc.get_freeze_count() == 0


def test_a_record_cut_short_while_the_workers_read_is_an_error(tmp_path, monkeypatch) -> None:
    """The record changes under the workers (a chunk finds fewer samples than planned): said,
    not a silently shorter analysis."""
    from avard.core.analysis import parallel

    rng = np.random.default_rng(4)
    y = rng.normal(0, 1e-3, (1 << 16, 1))
    job = parallel._Job(lambda verify: iter([(y[:40000], False)]), None, ["x"], 100.0,
                        2 ** np.arange(10), None, len(y), False,
                        [parallel.Chunk(0, 32768, 36864), parallel.Chunk(32768, 65536, 65536)])
    with pytest.raises(DataError, match="changed while it was analysed"):
        parallel.chunk_part(job, 1)


def test_a_record_shorter_than_its_header_is_refused_on_workers_as_on_one(tmp_path) -> None:
    """An .npz whose accel header promises more rows than its member holds (a copy cut
    short): the chunks past its end read short, and the analysis ends in the one line one
    worker gives, never an ADEV of the rows that are there."""
    import io
    import zipfile

    from avard.core.errors import FormatError

    rng = np.random.default_rng(8)
    y = rng.normal(0, 1e-3, (1 << 17, 3))
    raw = io.BytesIO()
    np.lib.format.write_array(raw, y)
    rate = io.BytesIO()
    np.lib.format.write_array(rate, np.float64(100.0))
    path = tmp_path / "short.npz"
    with zipfile.ZipFile(path, "w", zipfile.ZIP_STORED) as z:
        z.writestr("accel.npy", raw.getvalue()[:len(raw.getvalue()) - y.nbytes // 3])
        z.writestr("rate_hz.npy", rate.getvalue())
    for workers in (1, 2):
        with pytest.raises(FormatError, match="truncated"):
            analyze(open_record(path), AnalyzeOptions(workers=workers, block=8192))


def test_a_damaged_npz_is_refused_on_workers_as_on_one(tmp_path) -> None:
    """The parallel pass checks the member's CRC as the first pass of one worker does: a
    flipped bit is an error, never an ADEV."""
    from avard.core.errors import FormatError

    rng = np.random.default_rng(7)
    path = tmp_path / "r.npz"
    np.savez(path, accel=rng.normal(0, 1e-3, (1 << 16, 2)), rate_hz=100.0)
    raw = bytearray(path.read_bytes())
    raw[len(raw) // 2] ^= 0x10  # one bit inside the accel member's data
    path.write_bytes(bytes(raw))
    for workers in (1, 2):
        with pytest.raises(FormatError, match="CRC"):
            analyze(open_record(path), AnalyzeOptions(workers=workers))


def test_concurrent_parallel_passes_keep_their_own_records(tmp_path) -> None:
    """Two analyses on one executor at once (avard fleet's threads): each gets its own
    record's result, whatever the interleaving."""
    from concurrent.futures import ThreadPoolExecutor

    from avard.core.analysis.engine import analyze_records

    paths = []
    for scale, name in ((1e-3, "a.npz"), (1.0, "b.npz")):
        p = tmp_path / name
        np.savez(p, accel=np.random.default_rng(1).normal(0, scale, (1 << 15, 1)), axes=["x"],
                 rate_hz=100.0)
        paths.append(p)
    alone = [analyze(open_record(p)).channels["x"].allan.dev for p in paths]
    with ThreadPoolExecutor(4) as ex, ThreadPoolExecutor(2) as callers:
        futs = [callers.submit(analyze_records, [open_record(p)], chunks=3, executor=ex)
                for p in paths for _ in range(3)]
        got = [f.result().channels["x"].allan.dev for f in futs]
    for i, dev in enumerate(got):
        np.testing.assert_allclose(dev, alone[i // 3], rtol=1e-12)


def test_a_record_the_screen_cuts_is_analysed_on_one_worker_alike(tmp_path) -> None:
    """A shock the input screen cuts out is a gap no chunk plan knew of: the parallel pass
    reads short and the pass is read on one worker, so the result is one worker's."""
    rng = np.random.default_rng(12)
    n = 1 << 16
    y = rng.normal(0, 1e-3, (n, 3))
    y[40000:40003] += 0.5  # a shock on every axis, 500 σ
    path = tmp_path / "shock.npz"
    np.savez(path, accel=y, rate_hz=100.0)
    one = analyze(open_record(path))
    par = analyze(open_record(path), AnalyzeOptions(workers=2))
    assert one.meta["screen"].stretches  # the screen did cut the shock
    assert par.n_samples == one.n_samples
    for name, ch in one.channels.items():
        np.testing.assert_array_equal(par.channels[name].allan.dev, ch.allan.dev)


@pytest.mark.parametrize("axis", [0, 2])
def test_a_shock_on_one_axis_is_found_by_the_chunks_whatever_is_analysed(tmp_path,
                                                                         axis) -> None:
    """The chunks judge each axis on its own and the first pass also the axes no pass
    analyses: a shock on one axis only (here, one not analysed when only x is asked for)
    is cut exactly as one worker cuts it, and a clean record says the screen ran and cut
    nothing."""
    rng = np.random.default_rng(13)
    n = 1 << 17
    y = rng.normal(0, 1e-3, (n, 3))
    clean = tmp_path / "clean.npz"
    np.savez(clean, accel=y, rate_hz=100.0)
    y[90000:90002, axis] += 0.2  # 200 σ on one axis, in the second half
    path = tmp_path / "shock.npz"
    np.savez(path, accel=y, rate_hz=100.0)
    opts = {"channels": ("x",)}
    one = analyze(open_record(path), AnalyzeOptions(**opts))
    par = analyze(open_record(path), AnalyzeOptions(workers=2, **opts))
    cut = [(s.first, s.last) for s in one.meta["screen"].stretches]
    assert cut and cut == [(s.first, s.last) for s in par.meta["screen"].stretches]
    np.testing.assert_array_equal(par.channels["x"].allan.dev, one.channels["x"].allan.dev)
    ok = analyze(open_record(clean), AnalyzeOptions(workers=2, **opts))
    assert ok.meta["screen"].done and not ok.meta["screen"].stretches


def test_the_passes_are_planned_for_the_soonest_end() -> None:
    """Three channels on two workers: two passes whole and one cut in two (a cut makes its
    chunks read the record's start again); one channel on two workers is cut in two; the
    plan's longest worker is never longer than cutting every pass alike."""
    from avard.core.analysis.parallel import _chunk_costs, _makespan, plan_passes

    n, align, reach_ = 1 << 24, 1 << 20, 1 << 22
    three = plan_passes(3, [0, n], 2, align, reach_)
    assert sorted(len(p) for p in three) == [1, 1, 2]
    assert len(plan_passes(1, [0, n], 2, align, reach_)[0]) == 2
    for passes, workers in ((3, 2), (2, 3), (4, 4), (5, 2)):
        plan = plan_passes(passes, [0, n], workers, align, reach_)
        best = _makespan([c for p in plan for c in _chunk_costs(p, n)], workers)
        for k in range(1, workers + 1):
            alike = plan_chunks([0, n], k, align, reach_)
            assert best <= _makespan(_chunk_costs(alike, n) * passes, workers) + 1e-9
        for p in plan:  # every pass covers the record once
            assert p[0].start == 0 and p[-1].stop == n
            assert all(a.stop == b.start for a, b in itertools.pairwise(p))


def _counted_screen(monkeypatch) -> list[int]:
    """Count the input screen's judgments of a block in this process (forked workers count
    in their own copies)."""
    from avard.core.io.screen import stream as screen

    calls = [0]
    real = screen.screen_accel

    def counted(a):
        calls[0] += 1
        return real(a)

    monkeypatch.setattr(screen, "screen_accel", counted)
    return calls


@pytest.mark.parametrize("workers", [2, 3])
def test_after_a_screen_cut_one_worker_takes_the_chunks_verdicts(tmp_path, monkeypatch,
                                                                 workers) -> None:
    """Shocks in several chunks, on different axes (one of them an axis a pass of its own
    reads, one in the record's last block): the one-worker read that follows the chunks'
    cut judges nothing again, and cuts exactly the rows, with the same log and ADEV, as one
    worker judging the record itself."""
    from avard.core.analysis import parallel

    monkeypatch.setattr(parallel, "cores", lambda: 4)  # three workers even on two cores
    rng = np.random.default_rng(21)
    n = 1 << 18
    y = rng.normal(0, 1e-3, (n, 3))
    y[30000:30002, 0] += 0.3
    y[150000, 2] += 0.3
    y[200000:200004, 1] -= 0.3
    y[n - 5, 2] += 0.3
    path = tmp_path / "shocks.npz"
    np.savez(path, accel=y, rate_hz=100.0)
    calls = _counted_screen(monkeypatch)
    one = analyze(open_record(path))
    judged_by_one = calls[0]
    calls[0] = 0
    par = analyze(open_record(path), AnalyzeOptions(workers=workers))
    assert judged_by_one > 0 and calls[0] == 0
    cut = [(s.channel, s.kind, s.first, s.last) for s in one.meta["screen"].stretches]
    assert len(cut) == 4
    assert cut == [(s.channel, s.kind, s.first, s.last) for s in par.meta["screen"].stretches]
    assert par.n_samples == one.n_samples
    for name, ch in one.channels.items():
        np.testing.assert_array_equal(par.channels[name].allan.dev, ch.allan.dev)
        np.testing.assert_array_equal(par.channels[name].allan.alpha, ch.allan.alpha)


def test_a_chunk_told_of_a_cut_only_judges_the_blocks_it_owns() -> None:
    """Once another chunk's screen cut something (the shared flag), a chunk's sums are of no
    use: it sends none, only its verdicts on its own blocks (none outside them), and a chunk
    that finds a cut itself sets the flag for the others."""
    from avard.core.analysis import parallel

    class Flag:
        def __init__(self, on: bool) -> None:
            self.on = on

        def is_set(self) -> bool:
            return self.on

        def set(self) -> None:
            self.on = True

    rng = np.random.default_rng(5)
    n, block = 1 << 16, 1 << 13
    y = rng.normal(0, 1e-3, (n, 2))
    y[1000, 0] += 0.5  # in the first chunk, before the second's own blocks
    y[40000, 1] += 0.5  # in the second chunk's

    def read(verify: bool = False):
        for i in range(0, n, block):
            yield y[i:i + block], False

    job = parallel._Job(read, None, ["x", "y"], 100.0, 2 ** np.arange(8), None, n, False,
                        [parallel.Chunk(0, 32768, 33792), parallel.Chunk(32768, n, n)],
                        screen=[0, 1])
    second = parallel.chunk_part(job, 1, Flag(True))
    assert second.part is None and second.power is None
    assert list(second.cuts) == [40000 // block * block]
    assert 40000 % block in second.cuts[40000 // block * block]
    flag = Flag(False)
    first = parallel.chunk_part(job, 0, flag)
    assert first.part is None and flag.on and list(first.cuts) == [0]
    clean = parallel._Job(read, None, ["x", "y"], 100.0, 2 ** np.arange(8), None, n, False,
                          job.chunks, screen=None)
    whole = parallel.chunk_part(clean, 1, Flag(False))
    assert whole.part is not None and not whole.cuts


def test_a_pass_is_handed_on_as_soon_as_its_chunks_are_in() -> None:
    """``run_passes(on_pass=...)`` gives a pass's sums while the other passes' chunks still
    run (analyze fits it meanwhile): here the second pass's chunks wait until the first
    pass has been handed on, which they would never see if passes were handed on at the
    end; and what is handed on is what run_passes returns."""
    import threading
    from concurrent.futures import ThreadPoolExecutor

    from avard.core.analysis.parallel import PassSpec, run_passes

    rng = np.random.default_rng(8)
    n = 1 << 14
    y = rng.normal(0, 1e-3, (n, 2))
    first_in = threading.Event()
    waited: list[bool] = []

    def read(col: int, *, verify: bool = False):
        if col == 1:
            waited.append(first_in.wait(60))  # a chunk of the second pass
        for i in range(0, n, 4096):
            yield y[i:i + 4096, col:col + 1], False

    handed: dict[int, tuple] = {}

    def on_pass(p, acc, welch, got):
        handed[p] = (acc, welch, got)
        if p == 0:
            first_in.set()

    specs = [PassSpec(partial(read, c), None, [f"ch{c}"]) for c in (0, 1)]
    with ThreadPoolExecutor(4) as ex:
        out = run_passes(specs, 100.0, 2 ** np.arange(6), None, n, [0, n], 2, executor=ex,
                         on_pass=on_pass)
    assert waited and all(waited)
    assert sorted(handed) == [0, 1]
    for p in (0, 1):
        assert handed[p][0] is out[p][0] and handed[p][2] == out[p][2] == n


def test_a_worker_hands_out_a_history_again_only_when_nothing_refers_to_it(monkeypatch):
    """A worker's later chunks take an earlier chunk's OADEV ring (its pages mapped), never
    while any array made from it lives, and always zeroed; an idle one too small for the
    next is given back rather than kept beside it."""
    from avard.core.allan import scratch

    monkeypatch.setattr(scratch, "_reused", [])  # as reuse_histories() in a worker
    a = scratch.mapped_zeros((2, 1000))
    a[:] = 5.0
    view = a[:, 10:20]
    del a
    b = scratch.mapped_zeros((2, 1000))
    assert b.base is not view.base and not b.any()  # a slice still holds the first
    b[:] = 7.0
    del view, b
    c = scratch.mapped_zeros((2, 500))
    assert len(scratch._reused) == 2 and any(c.base is x for x in scratch._reused)
    assert not c.any()
    del c
    d = scratch.mapped_zeros((3, 1000))  # larger than both, which are idle
    assert len(scratch._reused) == 1 and d.base is scratch._reused[0]


def test_a_chunk_reading_longer_blocks_judges_each_screen_block_alone(monkeypatch
                                                                     ) -> None:
    """A local chunk reads ``CHUNK_BLOCKS`` one-worker blocks at a time (and takes longer
    OADEV pieces): the input screen still judges each one-worker block it owns on its own
    (a chunk starting inside a read block included), once each, with the verdicts one
    worker's screen gives that block; and on a clean record the chunks' parts, read in long
    blocks, add up to one pass in one-worker blocks."""
    from avard.core.analysis import parallel
    from avard.core.io import screen

    rng = np.random.default_rng(29)
    n, sb = 1 << 16, 1 << 11
    big = parallel.CHUNK_BLOCKS * sb
    clean = rng.normal(0, 1e-3, (n, 2)) + np.cumsum(rng.normal(0, 2e-6, (n, 2)), axis=0)
    y = clean.copy()
    y[5000, 0] += 0.5  # first chunk, third one-worker block of the first read block
    y[3 * sb + 7, 1] -= 0.5  # the second chunk's first block, inside that read block
    y[n - 3, 0] += 0.5  # the record's last block
    grid = 2 ** np.arange(9)
    cut = 3 * sb  # inside the first read block
    chunks = [parallel.Chunk(0, cut, cut + LADDER_REACH * int(grid[-1])),
              parallel.Chunk(cut, n, n)]

    def reader(data, size):
        def read(verify: bool = False):
            for i in range(0, n, size):
                yield data[i:i + size], False
        return read

    judged = []
    real = screen.screen_accel

    def counted(a):
        judged.append(len(a))
        return real(a)

    job = parallel._Job(reader(y, big), None, ["x", "y"], 100.0, grid, None, n, False,
                        chunks, screen=[0, 1], screen_block=sb)
    monkeypatch.setattr(screen, "screen_accel", counted)
    got = [parallel.chunk_part(job, i) for i in range(2)]
    monkeypatch.setattr(screen, "screen_accel", real)
    assert judged == [sb] * (n // sb)  # every one-worker block once, whole
    want = {}
    for b0 in range(0, n, sb):
        bad = real(y[b0:b0 + sb])
        if bad.any():
            want[b0] = np.flatnonzero(bad)
    assert sorted(want) == [4096, 3 * sb, n - sb]
    assert sorted(got[0].cuts) == [4096] and sorted(got[1].cuts) == [3 * sb, n - sb]
    for r in got:
        for b0, rows in r.cuts.items():
            np.testing.assert_array_equal(rows, want[b0])
    job = parallel._Job(reader(clean, big), None, ["x", "y"], 100.0, grid, 1024, n, False,
                        chunks, screen=[0, 1], screen_block=sb)
    parts = [parallel.chunk_part(job, i) for i in range(2)]
    assert all(not r.cuts for r in parts)
    total = parts[0].part + parts[1].part
    one = OverlappingAllan(2, 100.0, grid, n_total=n, defer_rn=True)
    welch = WelchAccumulator(2, 100.0, 1024)
    for blk, _end in reader(clean, sb)():
        one.update(blk)
        welch.update(blk)
    a = OverlappingAllan.from_part(total, 100.0, n_total=n, defer_rn=True).result()
    b = one.result()
    np.testing.assert_allclose(a.dev, b.dev, rtol=1e-12)
    np.testing.assert_array_equal(a.alpha, b.alpha)
    power = parts[0].power.power + parts[1].power.power
    np.testing.assert_allclose(power, welch.part().power, rtol=1e-12)


def test_the_workers_exit_by_themselves_once_the_last_chunk_is_in(tmp_path) -> None:
    """The workers are told to exit when the last chunk is in (they unmap their histories
    while the parent finishes the last pass): none is left running, each ended cleanly, and
    the result is one worker's."""
    import multiprocessing

    rng = np.random.default_rng(31)
    n = 1 << 17
    y = rng.normal(0, 1e-3, (n, 3))
    path = tmp_path / "r.npz"
    np.savez(path, accel=y, rate_hz=100.0)
    par = analyze(open_record(path), AnalyzeOptions(workers=2))
    children = multiprocessing.active_children()
    for child in children:
        child.join(timeout=120)  # a bound on a hang, not a timing
    assert all(not c.is_alive() and c.exitcode == 0 for c in children)
    one = analyze(open_record(path))
    for name, ch in one.channels.items():
        np.testing.assert_allclose(par.channels[name].allan.dev, ch.allan.dev, rtol=1e-12)


def _white_records(tmp_path, n: int = 1 << 14) -> list:
    """The x axis of white-noise-only records (seeds 1, 2, 3, 9) on which one and two
    workers' last-bit differences once chose a different composition in
    ``signal_edf.model_edf`` (the white FM type's EDF ties the point bound there)."""
    paths = []
    for seed in (1, 2, 3, 9):
        y = np.random.default_rng(seed).normal(0, 1e-3, (n, 3))[:, 0]
        p = tmp_path / f"w{seed}.npz"
        np.savez(p, accel=y, rate_hz=100.0)
        paths.append(p)
    return paths


def test_white_noise_alone_gives_one_workers_edf_on_two(tmp_path) -> None:
    """On white noise alone the printed EDF (the model bound, at the long τ) is one
    worker's to 1e-12, as are the ADEV, α and terms: the tie between the white FM type's
    EDF and the bound is not decided by the last bit of two sums of the same AVAR."""
    from avard.core.analysis.engine import analyze_records

    for path in _white_records(tmp_path):
        one = analyze_records([open_record(path)])
        par = analyze_records([open_record(path)], chunks=2)
        assert not np.array_equal(par.channels["ch0"].allan.dev,
                                  one.channels["ch0"].allan.dev)  # (really summed apart)
        _assert_one_workers(one, par)


def test_model_edf_does_not_amplify_the_last_bit_of_the_fit(tmp_path, monkeypatch) -> None:
    """θ moved by 1e-13 relative (each way, and each component alone) moves the printed
    EDF by under 1e-9 relative on white noise alone, where the model bound decides it."""
    from dataclasses import replace

    from avard.core.analysis import engine, signal_edf

    seen = []
    real = signal_edf.with_signal_edf

    def kept(allan, fit):
        seen.append((allan, fit))
        return real(allan, fit)

    monkeypatch.setattr(engine, "with_signal_edf", kept)
    for path in _white_records(tmp_path):
        analyze(open_record(path))
    assert len(seen) == 4
    raised = 0
    for allan, fit in seen:
        base = real(allan, fit).edf
        raised += int(np.any(base > allan.edf))  # the bound does set the printed EDF
        for k in [None, *range(len(fit.theta))]:
            for sign in (1.0, -1.0):
                step = np.full(len(fit.theta), 1e-13 * sign) if k is None else \
                    np.where(np.arange(len(fit.theta)) == k, 1e-13 * sign, 0.0)
                moved = real(allan, replace(fit, theta=fit.theta * (1.0 + step))).edf
                np.testing.assert_allclose(moved, base, rtol=1e-9)
    assert raised == 4
