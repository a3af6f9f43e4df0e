"""Write docs/real-data.md: `avard explain` on the three real ADIS16405 static runs.

    .venv/bin/python docs/scripts/real_data_explain.py [--data ../shared/data/imudata]
                                                      [--out docs/real-data.md]

For each run and axis: the five-term base model, what it gets wrong (misfit ranges in sigmas),
the causes found with their evidence, and the gain of the extended model on the run itself
(fit data), on its second half (models refitted on the first half) and held out on each of
the other runs (models fitted on this run predict the other). The data are not copied into the
repository (CC BY-NC-SA 4.0, see the data README); only numbers derived from them are written.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from avard.core.explain import ChannelExplanation, explain
from avard.core.explain_report import term_changes

HERE = Path(__file__).resolve().parent
DEFAULT_DATA = HERE.parents[2] / "shared" / "data" / "imudata"
RUNS = ("adis16405_run1", "adis16405_run2", "adis16405_run3")


class _Run:
    """A record as explain reads it (the .npz has accel, rate_hz, axes; no temperatures)."""

    def __init__(self, path: Path):
        with np.load(path, allow_pickle=False) as z:
            self.accel = np.asarray(z["accel"], dtype=float)
            self.rate_hz = float(z["rate_hz"])
            self.names = [str(a) for a in z["axes"]]
        self.temperature_c = None
        self.temperature_names: list[str] = []
        self.source = path.name


def _g(x: float | None) -> str:
    return "n/a" if x is None else f"{x:.3g}"


def _finding(f: dict) -> str:
    p = ", ".join(f"{k} = {v:.4g}" for k, v in f["params"].items())
    return f"{f['cause']} ({p})"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA)
    ap.add_argument("--out", type=Path, default=HERE.parent / "real-data.md")
    args = ap.parse_args(argv)
    paths = [args.data / f"{r}.npz" for r in RUNS]
    missing = [p for p in paths if not p.exists()]
    if missing:
        print(f"real data not found: {', '.join(map(str, missing))}", file=sys.stderr)
        return 2
    runs = {r: _Run(p) for r, p in zip(RUNS, paths, strict=True)}
    t0 = time.time()
    own: dict[str, dict[str, ChannelExplanation]] = {}
    cross: dict[tuple[str, str], dict[str, ChannelExplanation]] = {}
    for r in RUNS:
        own[r] = explain(runs[r]).channels
        for s in RUNS:
            if s != r:
                cross[(r, s)] = explain(runs[r], holdout=runs[s]).channels
        print(f"{r} done after {time.time() - t0:.0f} s", file=sys.stderr)

    md = [
        "# avard explain on real data: three ADIS16405 static runs",
        "",
        "Produced by `docs/scripts/real_data_explain.py` (do not edit by hand). Data: three "
        "static runs of an Analog Devices ADIS16405 IMU at 100 Hz, 1,000,000 samples (2.78 h) "
        "each, from the R package `imudata` (SMAC-Group; S. Guerrier, J. Balamuta, G. Bakalli, "
        "R. Molinari et al.), CC BY-NC-SA 4.0; read from `../shared/data/imudata/`, never "
        "copied into this repository. No temperature channel was recorded, so the temperature "
        "cause cannot be tested on them.",
        "",
        "Units are SI (m/s², s, Hz). Gains are ratios of EDF-weighted χ² per degree of "
        "freedom, base (five IEEE terms) over extended model: above 1 the extension describes "
        "the data better. *Fit* is the run itself; *2nd half*: models refitted on the first "
        "half predict the second; *run k*: the models fitted on this run (cause parameters "
        "unchanged) predict run k.",
        "",
        "## What the five-term model gets wrong, and the cause",
        "",
    ]
    md += _narrative(own)
    xg = [ch.holdout_gain for chans in cross.values() for ch in chans.values()
          if ch.holdout_gain is not None]
    if xg:
        md.append(f"- Held out on the *other* runs (models and cause parameters from one run "
                  f"predict another): gain {min(xg):.3g}–{max(xg):.3g} (median "
                  f"{np.median(xg):.3g}) over the 18 run pairs × axes; below 1 in "
                  f"{sum(g < 1 for g in xg)} of them. The line's frequency moves between runs "
                  "(0.54–0.57 Hz) and its amplitude by tens of percent, so the gain is smaller "
                  "across runs than within one.")
    steps = [(r, ax, f["params"]["time_s"]) for r in RUNS for ax, ch in own[r].items()
             for f in ch.findings if f["cause"] == "bias_step"]
    if steps:
        record_s = len(runs[RUNS[0]].accel) / runs[RUNS[0]].rate_hz
        together = sorted({f"{r[-4:]} {a1}/{a2} at {t1:.0f}/{t2:.0f} s"
                           for r, a1, t1 in steps for r2, a2, t2 in steps
                           if r == r2 and a1 < a2 and abs(t1 - t2) < 0.005 * record_s})
        sizes = [abs(f["params"]["size"]) for r in RUNS for ch in own[r].values()
                 for f in ch.findings if f["cause"] == "bias_step"]
        md += ["", f"Bias steps ({len(steps)} on {len({(r, a) for r, a, _ in steps})} of 9 "
               f"axis-runs, sizes {min(sizes):.3g}–{max(sizes):.3g} m/s², below one "
               "quantization step) are weaker claims: they pass their test "
               "(≥ 6 robust σ of the window contrasts) and do not hurt on held-out data, but "
               "the coarse quantization and the wandering line make the contrasts less "
               "Gaussian than the test assumes. "
               + (f"Steps on two axes of one run within 0.5 % of the record "
                  f"({record_s * 0.005:.0f} s: {'; '.join(together)})"
                  " point to a real event in that run; the others are candidates to look at "
                  "in the time series, not established causes." if together else
                  "No two axes of a run step together; treat them as candidates to look at in "
                  "the time series, not as established causes.")]
    md += ["", "## Findings and gains per run and axis", "",
           "| run | axis | base χ²/dof | findings (claimed) | gain fit | gain 2nd half | "
           + " | ".join(f"gain {s[-4:]}" for s in RUNS) + " |",
           "|---|---|---|---|---|---|" + "---|" * len(RUNS)]
    for r in RUNS:
        for ax, ch in own[r].items():
            gains = []
            for s in RUNS:
                gains.append("–" if s == r else _g(cross[(r, s)][ax].holdout_gain))
            md.append(f"| {r[-4:]} | {ax} | {ch.base.chi2_dof:.3g} | "
                      + ("; ".join(_finding(f) for f in ch.findings) or "none")
                      + f" | {_g(ch.gain)} | {_g(ch.holdout_gain)} | " + " | ".join(gains) + " |")
    md += ["", "Causes found on a run but not claimed because their gain did not hold on "
           "held-out data:", ""]
    any_dropped = False
    for key, chans in [((r, "2nd half"), own[r]) for r in RUNS] + \
            [((r, f"held out on {s[-4:]}"), cross[(r, s)]) for (r, s) in cross]:
        for ax, ch in chans.items():
            for d in ch.dropped:
                any_dropped = True
                md.append(f"- {key[0][-4:]} {ax} ({key[1]}): {d}")
    if not any_dropped:
        md.append("- none")
    md += ["", "## IEEE coefficients: base → extended (68.3 % interval)", ""]
    for r in RUNS:
        md += [f"### {r}", "", "| axis | term | base | extended |", "|---|---|---|---|"]
        for ax, ch in own[r].items():
            for term, b, e in term_changes(ch):
                md.append(f"| {ax} | {term} | {b} | {e} |")
        md.append("")
    md += ["## Evidence (run1)", ""]
    for ax, ch in own[RUNS[0]].items():
        for f in ch.findings:
            md.append(f"- {ax}, {f['cause']}: {f['evidence']}")
    md += ["", f"Computed in {time.time() - t0:.0f} s.", ""]
    args.out.write_text("\n".join(md), encoding="utf-8")
    print(f"wrote {args.out}", file=sys.stderr)
    return 0


def _narrative(own: dict[str, dict[str, ChannelExplanation]]) -> list[str]:
    """The headline numbers, computed (not typed) from the results."""
    out = []
    lines = [(r, ax, f) for r in RUNS for ax, ch in own[r].items() for f in ch.findings
             if f["cause"] == "sinusoid"]
    if lines:
        fs = np.array([f["params"]["frequency_hz"] for _, _, f in lines])
        amps = np.array([f["params"]["amplitude"] for _, _, f in lines])
        main = fs[(fs > 0.4) & (fs < 0.7)]
        out.append(
            f"- **A periodic disturbance near {np.median(main):.3g} Hz** "
            f"(found {len(main)} times over 3 runs × 3 axes, frequencies "
            f"{main.min():.4g}–{main.max():.4g} Hz, amplitudes {amps.min():.3g}–"
            f"{amps.max():.3g} m/s²). Its Allan bump peaks at τ ≈ 0.371/f0 ≈ "
            f"{0.371 / np.median(main):.2g} s. The five IEEE terms cannot make a bump, so the "
            "fit spreads it into the bias-instability floor: B is overestimated, and the "
            "true floor and the rate random walk behind it are hidden.")
    b_ratio = []
    for r in RUNS:
        for ch in own[r].values():
            tb, te = ch.base.terms(), ch.extended.terms()
            if tb["bias_instability"]["value"] and te["bias_instability"]["value"]:
                b_ratio.append(tb["bias_instability"]["value"] / te["bias_instability"]["value"])
    if b_ratio:
        out.append(f"- **Bias instability**: base/extended B = {min(b_ratio):.2g}–"
                   f"{max(b_ratio):.2g}× over the nine axis-runs: the five-term model reads the "
                   "line as bias instability.")
    q = [f for r in RUNS for ch in own[r].values() for f in ch.findings
         if f["cause"] == "quantization"]
    flt = [f for r in RUNS for ch in own[r].values() for f in ch.findings
           if f["cause"] == "filter"]
    if q:
        lsb = q[0]["params"]["lsb"]
        out.append(f"- **Quantization**: every value sits on a grid of {lsb:.4g} m/s² "
                   f"({lsb / 9.80665 * 1e3:.3g} mg), claimed on {len(q)} of 9 axis-runs; as "
                   "rate data its rounding noise is white and adds to N (not the IEEE "
                   "3Q²/τ² term, which the base fit leaves at zero).")
    if flt:
        bw = np.array([f["params"]["bandwidth_hz"] for f in flt])
        out.append(f"- **The sensor's own filter**: at τ of one to a few samples the ADEV "
                   f"falls below the white-noise line; a low-pass of {bw.min():.3g}–"
                   f"{bw.max():.3g} Hz (2nd-order Butterworth equivalent) explains it, "
                   f"claimed on {len(flt)} of 9 axis-runs.")
    others = sorted({f["cause"] for r in RUNS for ch in own[r].values() for f in ch.findings}
                    - {"sinusoid", "quantization", "filter"})
    if others:
        out.append("- Also claimed on some axis-runs: " + ", ".join(others)
                   + " (see the table: these are specific to one run or axis).")
    gains = [ch.holdout_gain for r in RUNS for ch in own[r].values()
             if ch.holdout_gain is not None]
    if gains:
        out.append(f"- Held-out gain on the second half of each run: {min(gains):.3g}–"
                   f"{max(gains):.3g} (median {np.median(gains):.3g}).")
    return out


if __name__ == "__main__":
    sys.exit(main())
