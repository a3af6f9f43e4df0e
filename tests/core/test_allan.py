"""Batch Allan/Hadamard estimators against published reference values and allantools."""

from __future__ import annotations

import allantools
import numpy as np
import pytest
from avard.core.allan.deviations import (
    AllanResult,
    allan_variance,
    avar,
    edf_greenhall,
    oavar,
    ohvar,
    pavar,
    tau_grid,
)
from avard.core.errors import DataError


def nbs14_1000() -> np.ndarray:
    """NIST SP 1065 NBS14 1000-point set: n0 = 1234567890, n ← 16807 n mod (2³¹ − 1)."""
    n, out = 1234567890, []
    for _ in range(1000):
        out.append(n / 2147483647)
        n = 16807 * n % 2147483647
    return np.array(out)


NBS14_10_PHASE = np.array([0, 103.11111, 123.22222, 157.33333, 166.44444, 48.55555,
                           -96.33333, -2.22222, 111.88889, 0])

# (kind, reference deviations at τ = 1, 10, 100) from ../shared/notes/allan.md
NBS14_1000_REF = {
    "avar": (2.922319e-01, 9.965736e-02, 3.897804e-02),
    "oavar": (2.922319e-01, 9.159953e-02, 3.241343e-02),
    "ohvar": (2.943883e-01, 9.581083e-02, 3.237638e-02),
}


@pytest.mark.parametrize("kind", sorted(NBS14_1000_REF))
def test_nbs14_1000_point(kind: str) -> None:
    res = allan_variance(nbs14_1000(), 1.0, [1, 10, 100], kind=kind)
    np.testing.assert_allclose(res.dev, NBS14_1000_REF[kind], rtol=1e-6)


def test_nbs14_10_point() -> None:
    y = np.diff(NBS14_10_PHASE)  # phase in τ0 units → rate data
    np.testing.assert_allclose(avar(y, 1.0, [1, 2]).dev, [91.22945, 115.8082], rtol=1e-6)
    np.testing.assert_allclose(oavar(y, 1.0, [1, 2]).dev, [91.22945, 85.95287], rtol=1e-6)


# Stable32 OADEV of PHASE.DAT, 68.3 % interval, white FM: m → (σ, min σ, max σ)
STABLE32 = {1: (2.9223e-01, 2.8515e-01, 2.9987e-01), 8: (1.0570e-01, 1.0038e-01, 1.1198e-01),
            64: (3.6237e-02, 3.1755e-02, 4.3377e-02), 128: (2.7674e-02, 2.3045e-02, 3.7027e-02)}


def test_stable32_phase_dat_confidence_bounds() -> None:
    y = nbs14_1000()
    y = y - y.mean()  # PHASE.DAT is the NBS14 frequency with its mean removed
    ms = sorted(STABLE32)
    res = oavar(y, 1.0, ms, alpha=0)  # Stable32 table is for white FM
    ref = np.array([STABLE32[m] for m in ms])
    np.testing.assert_allclose(res.dev, ref[:, 0], rtol=2e-3)
    np.testing.assert_allclose(res.dev_lo, ref[:, 1], rtol=2e-3)
    np.testing.assert_allclose(res.dev_hi, ref[:, 2], rtol=2e-3)


def test_stable32_quantiles_reproduce_its_printed_bounds() -> None:
    """With Stable32's χ² quantiles (A&S 26.4.17 with its 26.2.22 coefficients above 100
    degrees of freedom) the bounds at m = 1 and 8 (EDF 782 and 166) equal Stable32's printed
    digits; the exact quantiles miss them by 1.4e-4 to 3.7e-4. At m = 64 and 128 (EDF 21 and
    9.6) Stable32 iterates its quantile to about four digits: within 1e-4."""
    ms = sorted(STABLE32)
    res = oavar(nbs14_1000(), 1.0, ms, alpha=0, quantiles="stable32")
    assert res.quantiles == "stable32"
    for k, m in enumerate(ms):
        _, lo, hi = STABLE32[m]
        if m in (1, 8):
            assert (float(f"{res.dev_lo[k]:.4e}"), float(f"{res.dev_hi[k]:.4e}")) == (lo, hi)
        else:
            np.testing.assert_allclose([res.dev_lo[k], res.dev_hi[k]], [lo, hi], rtol=1e-4)
    exact = oavar(nbs14_1000(), 1.0, ms, alpha=0)
    assert exact.quantiles == "exact"
    np.testing.assert_array_equal(exact.dev_lo[2:], res.dev_lo[2:])  # EDF <= 100: the same
    assert np.all(np.abs(exact.dev_lo[:2] / res.dev_lo[:2] - 1) > 1e-4)


def test_analyze_cli_with_stable32_quantiles_prints_stable32s_bounds(tmp_path) -> None:
    """`avard analyze nbs14.csv --rate 1 --json --quantiles stable32`: the 68 % bounds at
    m = 1 and 8 equal Stable32's printed digits (its α there is avard's: white FM), at m = 64
    within 1e-4, and the JSON says which quantiles were used."""
    import json
    import subprocess
    import sys

    p = tmp_path / "nbs14.csv"
    p.write_text("y\n" + "".join(f"{float(v)!r}\n" for v in nbs14_1000()))
    out = subprocess.run([sys.executable, "-m", "avard.daemon.cli", "analyze", str(p),
                          "--rate", "1", "--json", "--quantiles", "stable32",
                           "--noise-id", "powerlaw"],
                         capture_output=True, text=True, check=True)
    ch = json.loads(out.stdout)["channels"]["y"]
    assert ch["quantiles"] == "stable32"
    tau = [int(t) for t in ch["tau_s"]]
    for m in (1, 8, 64):
        k = tau.index(m)
        assert ch["alpha"][k] == 0
        got = [ch["adev_lo"][k], ch["adev_hi"][k]]
        if m < 64:
            assert [float(f"{v:.4e}") for v in got] == list(STABLE32[m][1:])
        else:
            np.testing.assert_allclose(got, STABLE32[m][1:], rtol=1e-4)


@pytest.mark.parametrize("rate", [1.0, 3.0, 100.0])
def test_agrees_with_allantools_overlapping(rate: float) -> None:
    y = np.random.default_rng(7).normal(0.3, 2.0, 20000)
    tau, dev, _, n = allantools.oadev(y, rate=rate, data_type="freq", taus="octave")
    res = oavar(y, rate)
    np.testing.assert_allclose(res.tau[: tau.size], tau, rtol=1e-12)
    np.testing.assert_allclose(res.dev[: dev.size], dev, rtol=1e-10)
    np.testing.assert_array_equal(res.n[: n.size], n)


def test_agrees_with_allantools_hadamard_and_nonoverlapping() -> None:
    y = np.cumsum(np.random.default_rng(8).normal(size=5000)) * 1e-3 + \
        np.random.default_rng(9).normal(size=5000)
    _, dev, _, _ = allantools.ohdev(y, rate=10.0, data_type="freq", taus="octave")
    np.testing.assert_allclose(ohvar(y, 10.0).dev[: dev.size], dev, rtol=1e-10)
    _, dev, _, _ = allantools.adev(y, rate=10.0, data_type="freq", taus="octave")
    np.testing.assert_allclose(avar(y, 10.0).dev[: dev.size], dev, rtol=1e-10)


def test_partial_overlap_matches_explicit_sum() -> None:
    """pavar with stride s is Σ over i = 0, s, 2s, … of (X[i+2m] − 2X[i+m] + X[i])²/(2m²M)."""
    y = np.random.default_rng(3).normal(size=3001)
    x = np.concatenate([[0.0], np.cumsum(y - y[0])])
    for m, s in [(16, 2), (12, 5), (7, 7), (5, 1)]:
        i = np.arange(0, x.size - 2 * m, s)
        dd = x[i + 2 * m] - 2 * x[i + m] + x[i]
        ref = np.sum(dd**2) / (2 * m**2 * i.size)
        res = pavar(y, 2.0, [m / 2.0], stride=s)
        assert res.n[0] == i.size and res.stride[0] == s
        np.testing.assert_allclose(res.var[0], ref, rtol=1e-12)


def test_default_pavar_stride_is_cascade() -> None:
    res = pavar(np.random.default_rng(1).normal(size=5000), 1.0)
    assert list(res.stride[:7]) == [1, 1, 1, 1, 2, 4, 8]


def test_integer_counts_exact_and_offset_invariant() -> None:
    """Raw counts summed in int64: an offset of 1 g (256000 LSB) changes nothing, bit for bit."""
    rng = np.random.default_rng(4)
    counts = rng.integers(-300, 300, size=(50000, 2))
    a = allan_variance(counts, 100.0)
    b = allan_variance(counts + np.array([256000, -256000]), 100.0)
    np.testing.assert_array_equal(a.var, b.var)
    c = allan_variance(counts.astype(np.float64), 100.0)
    np.testing.assert_allclose(a.var, c.var, rtol=1e-9)


def test_white_noise_oadev_tau0_equals_sigma_and_constant_is_zero() -> None:
    rng = np.random.default_rng(5)
    res = oavar(rng.normal(0.0, 0.02, 200000), 100.0, [0.01])
    assert res.dev[0] == pytest.approx(0.02, rel=0.01)
    zero = oavar(np.full(1000, 9.81), 100.0)
    np.testing.assert_array_equal(zero.var, 0.0)


def test_multichannel_columns_and_covariance() -> None:
    rng = np.random.default_rng(6)
    y = rng.normal(size=(20000, 3))
    res = oavar(y, 50.0, names=["x", "y", "z"])
    assert res.var.shape == (res.tau.size, 3) and res.cov.shape == (res.tau.size, 3, 3)
    for c in range(3):
        np.testing.assert_allclose(res.channel(c).var, oavar(y[:, c], 50.0).var, rtol=1e-12)
    assert res.channel(1).names == ("y",)
    w = np.array([1.0, -0.5, 2.0])
    comb = oavar(y @ w, 50.0)
    np.testing.assert_allclose(np.einsum("i,kij,j->k", w, res.cov, w), comb.var, rtol=1e-9)


def test_confidence_interval_brackets_and_level() -> None:
    y = np.random.default_rng(10).normal(size=10000)
    r68 = oavar(y, 1.0)
    r95 = oavar(y, 1.0, ci=0.95)
    assert np.all(r68.lo < r68.var) and np.all(r68.var < r68.hi)
    assert np.all(r95.lo < r68.lo) and np.all(r95.hi > r68.hi)
    assert np.all(r68.edf > 0)
    # non-overlapping has fewer degrees of freedom than overlapping at the same τ
    r_non = avar(y, 1.0)
    assert np.all(r_non.edf[2:] < r68.edf[2 : r_non.edf.size])


def test_noise_identification_in_result() -> None:
    rng = np.random.default_rng(11)
    white = oavar(rng.normal(size=100000), 1.0, [1, 4, 16, 64])
    assert np.all(white.alpha == 0)
    rw = oavar(np.cumsum(rng.normal(size=100000)), 1.0, [1, 4, 16, 64])
    assert np.all(rw.alpha == -2)
    d = np.diff(rng.normal(size=100001))
    wpm = oavar(d, 1.0, [1, 4, 16, 64], noise_id="powerlaw")
    assert np.all(wpm.alpha == 2)
    # the default reads rate data: float samples with no known LSB hold no PM type, so the
    # white-PM record is read as white FM, with white FM's EDF for rate data (the phase the
    # samples' exact running sum: GR's F = ∞, edf.edf_greenhall's rate_data)
    rate = oavar(d, 1.0, [1, 4, 16, 64])
    assert np.all(rate.alpha == 0)
    np.testing.assert_allclose(rate.edf, [edf_greenhall(0, 2, m, 1, len(d) + 1, rate_data=True)
                                          for m in (1, 4, 16, 64)])


def test_gaps_split_segments() -> None:
    rng = np.random.default_rng(12)
    y = rng.normal(size=4000)
    split = oavar(y, 1.0, [1, 2, 4, 8], gaps=[1500])
    a, b = oavar(y[:1500], 1.0, [1, 2, 4, 8]), oavar(y[1500:], 1.0, [1, 2, 4, 8])
    np.testing.assert_array_equal(split.n, a.n + b.n)
    expect = (a.var * a.n + b.var * b.n) / (a.n + b.n)
    np.testing.assert_allclose(split.var, expect, rtol=1e-12)


def test_tau_grids() -> None:
    assert list(tau_grid(100, 1.0, "octave", 2)) == [1, 2, 4, 8, 16, 32]
    assert list(tau_grid(1000, 1.0, "decade", 2)) == [1, 2, 5, 10, 20, 50, 100, 200, 500]
    assert list(tau_grid(9, 1.0, "all", 2)) == [1, 2, 3, 4]
    assert list(tau_grid(100, 10.0, [0.1, 0.2, 0.21, 1.0], 2)) == [1, 2, 10]


@pytest.mark.parametrize(
    ("y", "rate", "kw", "msg"),
    [
        (np.array([1.0, np.nan, 2.0, 3.0]), 1.0, {}, "sample 1"),
        (np.ones((3, 4, 5)), 1.0, {}, "shape"),
        (np.ones(100), 0.0, {}, "rate_hz"),
        (np.ones(100), float("nan"), {}, "rate_hz"),
        (np.ones(1), 1.0, {}, "samples"),
        (np.ones(100), 1.0, {"kind": "mvar"}, "kind"),
        (np.ones(100), 1.0, {"taus": "weekly"}, "taus"),
        (np.ones(100), 10.0, {"taus": [0.01]}, "shorter than one sample"),
        (np.array(["a", "b", "c"]), 1.0, {}, "dtype"),
        (np.ones(100), 1.0, {"stride": 2}, "pavar"),
    ],
)
def test_bad_input_raises_data_error(y, rate, kw, msg) -> None:
    with pytest.raises(DataError, match=msg):
        allan_variance(y, rate, **kw)


def test_tau_longer_than_record_is_nan_with_zero_count() -> None:
    res = oavar(np.random.default_rng(0).normal(size=100), 1.0, [1, 10, 80])
    assert res.n[2] == 0 and np.isnan(res.var[2]) and np.isnan(res.lo[2])
    assert np.all(np.isfinite(res.var[:2]))


def test_result_is_frozen_and_serialisable() -> None:
    res = oavar(np.random.default_rng(0).normal(size=(500, 2)), 1.0)
    assert isinstance(res, AllanResult)
    with pytest.raises(AttributeError):
        res.kind = "avar"  # type: ignore[misc]
    d = res.to_dict()
    assert d["kind"] == "oavar" and len(d["var"]) == res.tau.size


def test_hadamard_ignores_a_linear_rate_drift_exactly_for_counts() -> None:
    """A rate ramp y = a + b·k makes the phase quadratic: its third differences vanish, so the
    Hadamard variance of integer counts is unchanged bit for bit, while AVAR grows as τ²."""
    rng = np.random.default_rng(13)
    counts = rng.integers(-50, 50, size=20000)
    ramp = counts + 3 * np.arange(20000)
    np.testing.assert_array_equal(ohvar(ramp, 100.0).var, ohvar(counts, 100.0).var)
    a_ramp, a_flat = oavar(ramp, 100.0), oavar(counts, 100.0)
    assert a_ramp.var[-1] > 100 * a_flat.var[-1]


def test_alpha_can_be_imposed_per_tau() -> None:
    y = np.random.default_rng(14).normal(size=(5000, 2))
    res = oavar(y, 1.0, [1, 2, 4], alpha=[0, -1, -2])
    np.testing.assert_array_equal(res.alpha, [[0, 0], [-1, -1], [-2, -2]])
    with pytest.raises(DataError, match="alpha"):
        oavar(y, 1.0, [1, 2, 4], alpha=[0, 1, 0, 1])
    with pytest.raises(DataError, match="alpha"):
        oavar(y, 1.0, [1, 2], alpha=-3)  # AVAR does not converge there


def test_the_snapshot_decoder_round_trips_and_refuses_what_does_not_fit() -> None:
    import msgpack
    from avard.core.allan.streaming import AllanSnapshot, StreamingAllan
    from avard.core.errors import FormatError

    y = np.random.default_rng(15).normal(size=(3000, 2))
    acc = StreamingAllan(2, 10.0, names=["a", "b"])
    acc.update(y)
    snap = acc.snapshot()
    back = AllanSnapshot.from_dict(msgpack.unpackb(msgpack.packb(snap.to_dict())))
    for key in ("tau", "m", "stride", "avar", "cov", "n", "edf", "lo", "hi", "alpha"):
        np.testing.assert_array_equal(getattr(back, key), getattr(snap, key))
    assert (back.names, back.kind, back.n_samples) == (("a", "b"), "pavar", 3000)
    one = back.channel(1)                          # what the noise fit takes
    np.testing.assert_array_equal(one.var, acc.result().var[:, 1])
    assert one.var.ndim == 1 and one.names == ("b",) and one.cov.shape == (len(one.tau), 1, 1)
    d = snap.to_dict()
    for broken, match in (({k: v for k, v in d.items() if k != "tau"}, "tau"),
                          ({**d, "avar": [row[:1] for row in d["avar"]]}, "avar has shape"),
                          ({**d, "tau": [1, [2, 3]]}, "does not decode"),
                          ({**d, "names": 5}, "names"), ([1, 2], "a map")):
        with pytest.raises(FormatError, match=match):
            AllanSnapshot.from_dict(broken)
