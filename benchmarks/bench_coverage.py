"""Coverage of avard's printed OADEV intervals on records from an independent generator.

``python -m benchmarks coverage [--records 200] [--hours 1,12,60] [--mixes plain,sine,drift]
[--noise-id avard] [--seed 1] [--path analyze|estimator|live] [--workers 1]``

Records come from tests/support/coverage_gen.py (numpy only, nothing of avard's): white +
flicker + random walk ("plain"), the same plus a slow sinusoid of random phase ("sine"), plus
a linear drift ("drift"); 1 h at 10 Hz, 12 h and 60 h at 1 Hz. ("steep", a drift ten times
as steep, which the fit resolves as a ramp, checks the EDF the fit's resolved terms give; it
is not one of the issue's mixes.) The white noise meets the flicker floor at τ = 30 s and
the flicker floor meets the random walk at 3000 s, so the short record is white and flicker,
the long ones flicker and random walk. The truth at each τ is the closed-form AVAR of the
generated noise plus, for the sinusoid and the drift, the ensemble mean of the exact OADEV
of the noise-free signal. At every printed τ (avard's default octave grid) with at least 5
non-overlapping averages, the share of records whose 68.3 % interval holds the truth is
counted; the issue asks 60–76 % at every such τ.

``--path analyze`` (the default) counts the interval ``avard analyze`` prints: the record
goes through ``analysis.engine.analyze`` as a stream (input screen, Welch lines, fit, and
the fit's deterministic share of the EDF: ``analysis/signal_edf.py``); ``--path estimator``
the bare estimator's (``allan_variance``), without the fit; ``--path live`` the service's
snapshot (the cascade fed a minute at a time, ``analysis/live_fit.fit_channel``: its fit
and analyze's EDF rule on it). ``--workers 2`` runs the
(length, mix) rows on two processes. ``--detail`` prints the share at every τ, and on the
analyze path split by what the record resolved: the slow sinusoid found or not, the drift
test's verdict (resolved, a floor, neither), since a deterministic part the record cannot
resolve does not scatter inside an interval that is given the noise's EDF.

With 200 records a share has a standard error of 3.3 points, so 60–76 % is ±2.4 standard
errors about 68.3 %: one τ in 60 falls outside by chance alone.
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np
from avard.core.allan.deviations import AllanResult, allan_variance

from tests.support.coverage_gen import Mix, flicker_avar, noise_avar, record

if TYPE_CHECKING:
    from avard.core.analysis.drift import DriftLikelihood

LENGTHS = {1: 10.0, 12: 1.0, 60: 1.0}  # hours: sample rate (Hz)
TAU_WHITE_FLICKER = 30.0  # s: white meets the flicker floor
TAU_FLICKER_WALK = 3000.0  # s: the flicker floor meets the random walk
MIN_AVERAGES = 5
BAND = (0.60, 0.76)
MIXES = ("plain", "sine", "drift", "steep")  # (the order seeds each mix's generator)


def mix_for(kind: str, n: int, rate_hz: float) -> Mix:
    """The levels (per sample) of mix ``kind`` for an n-sample record at ``rate_hz``."""
    m1, m2 = TAU_WHITE_FLICKER * rate_hz, TAU_FLICKER_WALK * rate_hz
    floor = 1.0 / m1
    base = Mix(s2=1.0, h=floor / (2 * math.log(2)), q2=3 * floor / m2)
    if kind == "plain":
        return base
    if kind == "sine":  # period T/6; its AVAR at half a period (0.405 A²) equals the noise's
        period = n / 6
        level = float(noise_avar(base, n, np.array([period / 2]))[0])
        return Mix(base.s2, base.h, base.q2, math.sqrt(level / 0.405), period)
    if kind in ("drift", "steep"):  # its AVAR (d m)²/2 equals the noise's at m = T/10
        # ("steep": at T/100, a drift the fit resolves as a ramp, which checks the EDF the
        # fit's resolved deterministic terms give, analysis/signal_edf.py)
        m = n / 10 if kind == "drift" else n / 100
        level = float(noise_avar(base, n, np.array([m]))[0])
        return Mix(base.s2, base.h, base.q2, drift=math.sqrt(2 * level) / m)
    raise SystemExit(f"unknown mix {kind!r}; use plain, sine, drift or steep")


#: where each printed EDF came from (``--detail``): the estimator's own rule, raised by the
#: fit's noise mixture bound, raised by a resolved deterministic share, held at the record's
#: support (the cap bound: what the raise asked for was more)
RULES = ("own", "mixture", "share", "cap")


def edf_rules(printed_edf: np.ndarray, own: np.ndarray, mixture: np.ndarray,
              share: np.ndarray, cap: np.ndarray) -> np.ndarray:
    """One row per τ of RULES: 1 where that rule set the printed EDF (the cap may be set
    with the raise that hit it)."""
    tol = 1e-9
    at_own = np.abs(printed_edf - own) <= tol * own
    at_cap = (np.abs(printed_edf - cap) <= tol * cap) & ~at_own
    raised_by_mix = ~at_own & (np.nan_to_num(mixture) > own) & ~(share > 0)
    raised_by_share = ~at_own & (share > 0)
    return np.array([at_own, raised_by_mix, raised_by_share, at_cap], dtype=float).T


def true_psd(mix: Mix) -> Callable[[np.ndarray], np.ndarray]:
    """The generated noise's two-sided PSD in cycles per sample (the flicker's Fourier
    series read as its continuous 1/f spectrum)."""
    return lambda nu: (mix.s2 + mix.h / (2.0 * np.abs(nu))
                       + mix.q2 / (4.0 * np.sin(np.pi * nu) ** 2))


#: per record analysed in this process: whether the slow-sinusoid search resolved one
#: (``ChannelAnalysis.slow``; on a record without one, a false detection)
SLOW_FOUND: list[bool] = []
#: per record analysed in this process: the time-domain drift test's verdict on the fit the
#: EDF is from (``DRIFT_VERDICTS``): a drift the record cannot resolve leaves a part that does
#: not scatter inside an interval given the noise's EDF, so the shares differ by verdict
DRIFT_VERDICT: list[str] = []
DRIFT_VERDICTS = ("resolved", "floor", "neither")


def printed(y: np.ndarray, rate: float, noise_id: str = "avard", path: str = "analyze",
            detail: bool = False) -> tuple[AllanResult, np.ndarray, np.ndarray | None]:
    """The OADEV result whose interval is counted: what ``avard analyze`` prints (the
    default options, the record a one-channel stream), or the bare estimator's; with the
    share of the AVAR the fit's resolved deterministic terms were given at each τ, and with
    ``detail`` which rule set each τ's EDF (``edf_rules``) and, in a last column, the
    estimator's own EDF (it is run again for it)."""
    if path == "estimator":
        r = allan_variance(y, rate, noise_id=noise_id)
        return r, np.zeros(len(r.tau)), None
    if path == "live":
        # the service's snapshot: the cascade fed a minute at a time, its one fit
        # (live_fit.fit_channel: the decimation guard and analyze's signal_edf)
        from avard.core.allan.streaming import StreamingAllan
        from avard.core.analysis.live_fit import fit_channel
        from avard.core.analysis.signal_edf import signal_share as share_of

        sa = StreamingAllan(1, rate, names=["x"])
        step = max(1, int(60 * rate))
        for i in range(0, len(y), step):
            sa.update(y[i:i + step])
        cf = fit_channel(sa.snapshot().channel(0))
        return cf.allan, share_of(cf.fit, cf.allan), None
    from avard.core.analysis.engine import analyze
    from avard.core.analysis.options import AnalyzeOptions
    from avard.core.analysis.signal_edf import signal_share
    from avard.core.io.source import RecordFormat, RecordInfo, StreamSource

    info = RecordInfo(source="coverage", format=RecordFormat.STREAM, rate_hz=rate,
                      names=("x",), n_samples=len(y))
    blocks = ((y[i:i + 65536, None], None, False) for i in range(0, len(y), 65536))
    ch = analyze(StreamSource(info, blocks), AnalyzeOptions(noise_id=noise_id)).channels["x"]
    SLOW_FOUND.append(ch.slow is not None and ch.slow.sine is not None)
    fit = ch.fit if ch.slow_fit is None else ch.slow_fit  # (the fit the EDF is from)
    DRIFT_VERDICT.append("resolved" if "rate_ramp" in fit.resolved_apart
                         else "floor" if fit.drift_floor > 0 else "neither")
    share = signal_share(fit, ch.allan)
    rules = None
    if detail:
        from avard.core.allan.noise_id import fm_support_edf
        from avard.core.analysis.signal_edf import unresolved_noise_edf

        a = ch.allan
        k = len(a.tau)
        own = allan_variance(y, rate, noise_id=noise_id).edf[:k]
        cap = np.array([fm_support_edf(2, int(m), 1, len(y) + 1) for m in a.m])
        rules = np.column_stack([edf_rules(np.asarray(a.edf), own,
                                           unresolved_noise_edf(fit, a), share, cap), own])
    return ch.allan, share, rules


@dataclass(frozen=True)
class Coverage:
    """One (length, mix): the τ counted, the share of records covering the truth at each."""

    hours: int
    mix: str
    records: int
    tau: np.ndarray
    share: np.ndarray
    edf_mean: np.ndarray
    signal: np.ndarray  # the noise-free signal's share of the true AVAR at each τ
    # the EDF the estimates actually scatter with, 2·truth²/mean((σ̂² − truth)²) over the
    # records (their scatter about the truth, as an EDF): above edf_mean, the printed
    # intervals are wider than the scatter, and the share over-covers
    edf_seen: np.ndarray
    alpha_mean: np.ndarray
    # the mean share of the AVAR the fit's resolved deterministic terms were given (0 on the
    # estimator path), and the share of records where it was given any at that τ
    fit_share: np.ndarray
    fit_raised: np.ndarray
    # what the same records' intervals would cover with the true deterministic part and the
    # generator's spectrum given to the printed rule (``signal_edf.with_parts_edf``: the
    # noise part's EDF and the exact cross term; an oracle, what resolving can do at best)
    share_known: np.ndarray
    # (``--detail``) per τ, the share of records whose EDF each of RULES set
    rules: np.ndarray | None = None
    # (``--detail``) the EDF the noise part alone scatters with (the record less its
    # noise-free signal, through the bare estimator): what the noise's printed EDF aims at
    noise_seen: np.ndarray | None = None
    # records where the slow-sinusoid search resolved one (analyze path), and the share of
    # those (and of the others) whose interval holds the truth at each τ
    slow_found: int = 0
    share_found: np.ndarray | None = None
    share_unfound: np.ndarray | None = None
    # (``--detail``) the EDF the generator's noise mixture has at each τ (``noise_edf``):
    # what ``noise_seen`` scatters about over many records; a row's records whose noise
    # scatters far from it are lucky or unlucky at that τ, whatever the printed rule
    noise_expected: np.ndarray | None = None
    # (analyze path) per DRIFT_VERDICTS, the records with that verdict and their shares
    by_verdict: tuple[tuple[str, int, np.ndarray], ...] = ()

    def outside(self) -> list[float]:
        return [float(t) for t, s in zip(self.tau, self.share, strict=True)
                if not BAND[0] <= s <= BAND[1]]


def noise_edf(mix: Mix, n: int, ms: np.ndarray) -> np.ndarray:
    """The EDF of the OADEV of the generator's white + flicker + random walk at averaging
    factors ``ms`` of an n-sample record: the mixture's Greenhall–Riley quadratic form
    (``edf.edf_mixture``, rate data's exact phase) at the generator's own composition."""
    from avard.core.allan.edf import edf_mixture

    m = np.asarray(ms, dtype=float)
    levels = np.array([mix.s2 / m, flicker_avar(n, mix.h, m),
                       mix.q2 * (2 * m * m + 1) / (6 * m)])
    return np.array([edf_mixture((0, -1, -2), levels[:, k], 2, int(mk), 1, n + 1,
                                 rate_data=True) for k, mk in enumerate(m)])


def coverage(hours: int, mix_kind: str, records: int, seed: int,
             noise_id: str = "avard", path: str = "analyze", detail: bool = False
             ) -> Coverage:
    """The coverage of one (length, mix) over ``records`` records."""
    rate = LENGTHS[hours]
    n = round(hours * 3600 * rate)
    mix = mix_for(mix_kind, n, rate)
    rng = np.random.default_rng([seed, hours, MIXES.index(mix_kind)])
    lo, hi, clean_var, edf, var, alpha, shares, results = [], [], [], [], [], [], [], []
    rules: list[np.ndarray] = []
    own: list[np.ndarray] = []  # the estimator's own EDF (the oracle's noise part)
    noise_only: list[np.ndarray] = []
    ms = None
    found0 = len(SLOW_FOUND)
    verdict0 = len(DRIFT_VERDICT)
    for _ in range(records):
        y, clean = record(mix, n, rng)
        r, share, rule = printed(y, rate, noise_id, path, detail)
        if rule is not None:
            own.append(rule[:, len(RULES)])
        keep = n // r.m >= MIN_AVERAGES
        if rule is not None:
            rules.append(rule[keep, :len(RULES)])
            noise_only.append(allan_variance(y - clean, rate, r.m[keep] / rate).var)
        shares.append(share[keep])
        ms = r.m[keep]
        lo.append(r.lo[keep])
        hi.append(r.hi[keep])
        edf.append(r.edf[keep])
        var.append(r.var[keep])
        alpha.append(r.alpha[keep])
        results.append(r)
        if mix.sine_amplitude or mix.drift:
            clean_var.append(allan_variance(clean, rate, ms / rate, alpha=0).var)
    assert ms is not None
    noise = noise_avar(mix, n, ms)
    signal = np.mean(clean_var, axis=0) if clean_var else np.zeros(len(ms))
    truth = noise + signal
    inside = (np.array(lo) <= truth) & (truth <= np.array(hi))
    found = np.array(SLOW_FOUND[found0:] or [False] * records, dtype=bool)
    verdicts = np.array(DRIFT_VERDICT[verdict0:])
    by_verdict = tuple((v, int(np.sum(verdicts == v)), inside[verdicts == v].mean(axis=0))
                       for v in DRIFT_VERDICTS if len(verdicts) and np.any(verdicts == v))
    seen = 2.0 * truth**2 / np.mean((np.array(var) - truth) ** 2, axis=0)
    known = np.full(len(ms), np.nan)
    if clean_var and own:
        known[:] = 0.0
        from avard.core.analysis.signal_edf import with_parts_edf

        f0 = 1.0 / mix.sine_period if mix.sine_amplitude else 0.0
        for r, own_edf in zip(results, own, strict=True):
            k = len(ms)
            pad = np.zeros(len(r.m) - k)
            # the oracle: the true deterministic part and the generator's own spectrum
            # given to the printed rule (what resolving the signal could do at best)
            o = with_parts_edf(replace(r, edf=own_edf), [(np.concatenate([signal, pad]), f0)],
                               np.concatenate([truth, pad + 1.0]),
                               np.concatenate([noise, pad + 1.0]), true_psd(mix),
                               within_support=False)
            known += (o.lo[:k] <= truth) & (truth <= o.hi[:k])
        known /= len(results)
    return Coverage(hours, mix_kind, records, ms / rate, inside.mean(axis=0),
                    np.mean(edf, axis=0), signal / truth, seen, np.mean(alpha, axis=0),
                    np.mean(shares, axis=0), np.mean(np.array(shares) > 0, axis=0), known,
                    np.mean(rules, axis=0) if rules else None,
                    2.0 * noise**2 / np.mean((np.array(noise_only) - noise) ** 2, axis=0)
                    if noise_only else None, int(np.sum(found)),
                    inside[found].mean(axis=0) if found.any() else None,
                    inside[~found].mean(axis=0) if (~found).any() else None,
                    noise_edf(mix, n, ms) if noise_only else None, by_verdict)


def record_drift(y: np.ndarray, rate: float) -> DriftLikelihood | None:
    """Analyze's time-domain drift test on one record as the engine runs it: the AVAR fit and
    the block means of ``drift.drift_block`` (``drift.channel_drift``)."""
    from avard.core.analysis import drift as dr
    from avard.core.model.fit import fit_noise

    n, b = len(y), dr.drift_block(len(y))
    allan = allan_variance(y, rate)
    return dr.channel_drift(fit_noise(allan), y[: n // b * b].reshape(-1, b).mean(axis=1),
                            b / rate, allan)


def drift_test(hours: int, kind: str, records: int, seed: int) -> str:
    """The calibration of analyze's time-domain drift test (``--drift-test``;
    ``analysis.drift.channel_drift``, the test analyze and explain share): per record the
    likelihood ratio's signed z of a drift against a random walk (K profiled past the AVAR
    fit's upper K), on the block means the engine uses. The share of records past analyze's
    level (two-sided 1 %) and past 0.1 %, z's mean and spread (1 where the null is right),
    and how often the slope's 68 % profile interval holds the true drift."""
    from avard.core.analysis import drift as dr

    rate = LENGTHS[hours]
    n = round(hours * 3600 * rate)
    mix = mix_for(kind, n, rate)
    rng = np.random.default_rng([seed, hours, MIXES.index(kind), 77])
    z, held = [], 0
    for _ in range(records):
        y, _clean = record(mix, n, rng)
        lik = record_drift(y, rate)
        if lik is None:
            continue
        z.append(lik.z)
        held += lik.slope_lo <= mix.drift * rate <= lik.slope_hi
    za = np.array(z)
    return (f"{hours} h {kind}: past {dr.two_sided_z(dr.LEVEL):.2f} (analyze's level) in "
            f"{np.mean(np.abs(za) >= dr.two_sided_z(dr.LEVEL)):.1%}, past 3.29 in "
            f"{np.mean(np.abs(za) > 3.29):.1%}; z mean {za.mean():.2f}, spread {za.std():.2f}; "
            f"the slope's 68 % interval holds the true drift in {held / max(1, len(za)):.1%} "
            f"({len(za)} records tested)")


def _row(job: tuple[int, str, int, int, str, str, bool]) -> Coverage:
    return coverage(*job)


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks coverage", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--records", type=int, default=200)
    ap.add_argument("--hours", default="1,12,60")
    ap.add_argument("--mixes", default="plain,sine,drift")
    ap.add_argument("--noise-id", default="avard")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--path", choices=("analyze", "estimator", "live"), default="analyze")
    ap.add_argument("--workers", type=int, default=1, help="processes for the rows (≤ 2)")
    ap.add_argument("--detail", action="store_true", help="print the share at every τ")
    ap.add_argument("--drift-test", action="store_true",
                    help="instead: the calibration of analyze's time-domain drift test on "
                         "each mix (drift_test)")
    args = ap.parse_args(argv)
    hours = [int(h) for h in args.hours.split(",")]
    if any(h not in LENGTHS for h in hours):
        ap.error(f"--hours takes some of {sorted(LENGTHS)}")
    cpu0 = time.process_time()
    if args.drift_test:
        for h in hours:
            for kind in args.mixes.split(","):
                print(drift_test(h, kind, args.records, args.seed), flush=True)
        return 0
    print(f"OADEV 68.3 % interval coverage ({args.path}), noise_id={args.noise_id}, "
          f"{args.records} records per row, τ with >= {MIN_AVERAGES} averages (asked: "
          f"{BAND[0]:.0%}–{BAND[1]:.0%})")
    print("| record | mix | τ counted (s) | lowest | highest | τ outside 60–76 % |")
    print("|---|---|---|---|---|---|")
    bad = 0
    jobs = [(h, kind, args.records, args.seed, args.noise_id, args.path, args.detail)
            for h in hours for kind in args.mixes.split(",")]
    pool = None
    rows: Iterator[Coverage]
    if args.workers > 1:
        import multiprocessing

        pool = multiprocessing.get_context("fork").Pool(min(args.workers, 2))
        rows = pool.imap(_row, jobs)
    else:
        rows = map(_row, jobs)
    for c in rows:
        h, kind = c.hours, c.mix
        out = c.outside()
        bad += len(out)
        print(f"| {h} h at {LENGTHS[h]:g} Hz | {kind} | {c.tau[0]:g}–{c.tau[-1]:g} "
              f"({len(c.tau)}) | {c.share.min():.1%} | {c.share.max():.1%} | "
              f"{', '.join(f'{t:g}' for t in out) or 'none'} |", flush=True)
        if args.path == "analyze":
            print(f"    slow sinusoid resolved in {c.slow_found} of {c.records} records"
                  + (" (each a false detection: this mix has none)" if kind != "sine"
                     else ""), flush=True)
        if args.detail:
            for t, s, e, g, v, a, fs, fr, k in zip(c.tau, c.share, c.edf_mean, c.signal,
                                                   c.edf_seen, c.alpha_mean, c.fit_share,
                                                   c.fit_raised, c.share_known, strict=True):
                print(f"    τ {t:9.1f} s  coverage {s:6.1%}  mean EDF {e:10.1f}  "
                      f"seen {v:10.1f}  mean α {a:5.2f}  signal {g:6.1%} of the AVAR  "
                      f"fit's share {fs:6.1%} (given in {fr:6.1%} of records)  "
                      f"with the true part {k:6.1%}")
            for name, sh in (("resolved", c.share_found), ("not resolved", c.share_unfound)):
                if sh is not None and c.slow_found:
                    print(f"    coverage where a slow sinusoid was {name}: "
                          + " ".join(f"{v:.0%}" for v in sh))
            for verdict, count, sh in c.by_verdict:
                print(f"    coverage where the drift test's verdict was {verdict} "
                      f"({count} records): " + " ".join(f"{v:.0%}" for v in sh))
            if c.rules is not None and c.noise_seen is not None:
                expected = (c.noise_expected if c.noise_expected is not None
                            else np.full(len(c.tau), np.nan))
                for t, row, ns, ne in zip(c.tau, c.rules, c.noise_seen, expected,
                                          strict=True):
                    print(f"    τ {t:9.1f} s  EDF set by: " + "  ".join(
                        f"{name} {v:6.1%}" for name, v in zip(RULES, row, strict=True))
                        + f"  (noise alone scatters with {ns:9.1f}; the generator's "
                        f"mixture has {ne:9.1f})")
    if pool is not None:
        pool.close()
        pool.join()  # (its CPU is counted once it is reaped)
    import resource

    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    print(f"CPU {time.process_time() - cpu0 + kids.ru_utime + kids.ru_stime:.0f} s "
          "(process time, workers included)")
    return 0 if bad == 0 else 1
