"""What ``avard analyze`` returns: per channel the Allan result, the fit and the lines
(``ChannelAnalysis``), the whole record (``Analysis``) and the ``--json`` shape of both."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from avard.core.analysis.slow_sine import SlowSearch
    from avard.core.io.source import RecordInfo
    from avard.core.model.fit import NoiseFit

#: Estimator names as they appear in the table, the JSON and the csv.
ESTIMATORS = {
    "oadev": "fully overlapping ADEV (OADEV, NIST SP 1065 eq. 12; Stable32 'Overlapping Allan')",
    "cascade": "partially overlapping ADEV (stride m/8 above m = 8; avard's streaming cascade)",
}
#: The estimator as a figure's legend names it.
ESTIMATOR_LABELS = {"oadev": "OADEV", "cascade": "cascade ADEV (stride m/8)"}
#: SI unit of each per-τ array of a channel in ``--json`` ("1": dimensionless).
ADEV_UNITS = {"tau_s": "s", "adev": "m/s^2", "adev_lo": "m/s^2", "adev_hi": "m/s^2",
              "edf": "1", "alpha": "1"}
# ---------------------------------------------------------------------------------------------
# the analysis


@dataclass
class ChannelAnalysis:
    """One channel: its Allan result (AllanResult, one channel), the fit, the lines found."""

    name: str
    allan: Any
    fit: NoiseFit
    lines: list[dict[str, float]] = field(default_factory=list)
    estimator: str = "oadev"
    psd: Any = None  # psd.ChannelPsd when asked for (analyze(psd=True))
    #: the search for a slow sinusoid below the line finder's band (``slow_sine.py``; None:
    #: not run), and the fit with the one it resolved (None: none), which sets the printed
    #: EDF; ``fit`` is without it, the base model ``avard explain`` reads
    slow: SlowSearch | None = None
    slow_fit: NoiseFit | None = None

    def drift_summary(self, fit: NoiseFit | None = None) -> dict[str, Any]:
        """Where the rate ramp R comes from and the drift floor (``analysis/drift.py``):
        ``rate_ramp_from`` "time_domain" (the block means' GLS slope tested against a random
        walk resolved it apart from the AVAR), "allan_fit" (the AVAR fit's own term) or None
        (no R claimed); ``floor``: the ramp at the slope's 68 % interval's near end where the
        time domain finds a drift short of its level (0: none; no claim, but that much of
        the AVAR does not scatter and the printed EDF counts it), in ``unit``;
        ``interval_noise``: where either is reported, the noise the slope's interval (R's
        interval, the floor's end) was computed under, a key of ``drift.INTERVAL_NOISE``
        ("refit_less_line", or a fallback to the AVAR fit's N and B that says why), None
        where neither is. ``fit``: another fit of this channel (``slow_fit``) in place of
        the base model."""
        from avard.core.model.terms import UNITS

        fit = self.fit if fit is None else fit
        r = fit.terms.get("rate_ramp")
        source = ("time_domain" if "rate_ramp" in fit.resolved_apart
                  else "allan_fit" if r is not None and r.present else None)
        said = source == "time_domain" or fit.drift_floor > 0
        return {"rate_ramp_from": source, "floor": float(fit.drift_floor),
                "unit": UNITS["rate_ramp"],
                "interval_noise": (fit.drift_interval_noise or None) if said else None}

    def to_dict(self) -> dict[str, Any]:
        a = self.allan
        d: dict[str, Any] = {
            "estimator": self.estimator, "tau_s": _list(a.tau), "adev": _list(a.dev),
            "adev_lo": _list(a.dev_lo), "adev_hi": _list(a.dev_hi), "edf": _list(a.edf),
            "alpha": _list(a.alpha), "units": dict(ADEV_UNITS)}
        if getattr(a, "quantiles", "exact") != "exact":  # said only when not the default
            d["quantiles"] = a.quantiles
        if getattr(a, "noise_id", "avard") != "avard":  # the rule behind alpha, likewise
            d["noise_id"] = a.noise_id
        fd = self.fit.to_dict()
        d["terms"] = fd["terms"]
        d["sinusoids"] = [{"frequency_hz": s["frequency_hz"], "amplitude": s["amplitude"],
                           **({"amplitude_interval": [s["amplitude_lo"], s["amplitude_hi"]]}
                              if "amplitude_lo" in s else {}),
                           **({"disturbance": int(s["group"])} if "group" in s else {})}
                          for s in self.lines]
        d["fit"] = {k: _num(v) for k, v in fd["fit"].items()}
        d["drift"] = self.drift_summary()
        if self.slow is not None:
            d["slow_sinusoid"] = self.slow.to_dict()
            if self.slow_fit is not None:
                # the noise terms and the drift test beside the resolved sinusoid: the base
                # model's terms above read it as noise (a K of the sinusoid's AVAR), and the
                # drift it hid from the first test is tested again beside it
                d["slow_sinusoid"]["terms_beside"] = self.slow_fit.to_dict()["terms"]
                d["slow_sinusoid"]["drift_beside"] = self.drift_summary(self.slow_fit)
        if self.psd is not None:
            d["psd"] = self.psd.to_dict()
        return d


@dataclass
class Analysis:
    """The whole ``avard analyze`` result: source, rate (Hz), sample count, channels."""

    source: str
    rate_hz: float
    n_samples: int
    channels: dict[str, ChannelAnalysis]
    meta: dict[str, Any] = field(default_factory=dict)
    estimator: str = "oadev"
    #: the record's description (core.io.source.RecordInfo): format, sensor, recording summary
    info: RecordInfo | None = None

    def to_dict(self) -> dict[str, Any]:
        """The ``--json`` shape of issue 4 (SI units; NaN written as null)."""
        d = {"source": self.source, "rate_hz": float(self.rate_hz),
             "n_samples": int(self.n_samples), "estimator": self.estimator,
             "estimator_description": ESTIMATORS[self.estimator],
             "channels": {k: c.to_dict() for k, c in self.channels.items()}}
        if self.info is not None and self.info.sensor_name is not None:
            d["sensor"] = self.info.sensor_name     # which sensor (a rig's: --sensor NAME)
        rec = self.recording_summary()
        if rec is not None:
            d["recording"] = rec
        if "oadev_cut" in self.meta:
            d["oadev_cut"] = self.meta["oadev_cut"]
        screen = self.meta.get("screen")
        if screen is not None:
            d["screened"] = screen.to_dict()
        return d

    def recording_summary(self) -> dict[str, Any] | None:
        """For a service recording: its segments (split at every gap record and restart),
        gap records, and what damage cost or duplication repeated, in samples (index ranges);
        None for a file."""
        if self.info is None or self.info.recording is None:
            return None
        return self.info.recording.to_dict()


def _num(v: Any) -> float | None:
    if v is None:
        return None
    v = float(v)
    return v if math.isfinite(v) else None


def _list(a: Any) -> list[float | None]:
    return [_num(v) for v in np.asarray(a, dtype=float).ravel()]
