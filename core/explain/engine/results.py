"""What explain returns: one axis's explanation and the record's, with their text and JSON."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from avard.core.analysis.results import Analysis, ChannelAnalysis
from avard.core.explain import coupling_change as cchange
from avard.core.explain.causes import Finding
from avard.core.explain.holdout import (
    EVENTS,
    ChannelHoldout,
    Holdout,
)
from avard.core.explain.thermal_fit import (
    ThermalFit,
)
from avard.core.explain.verdict import MisfitRange, Verdict, compensation_worse_at, judge
from avard.core.io.screen import ScreenLog
from avard.core.model.fit import NoiseFit
from numpy.typing import NDArray

# --------------------------------------------------------------------------------------------
# results


@dataclass
class ChannelExplanation:
    """One axis: analyze's result (``base``), the extended fit, what was tested and found,
    the base model's misfit ranges and the temperature-compensated AVAR (or None)."""

    name: str
    base: ChannelAnalysis
    extended: NoiseFit
    findings: list[Finding]
    misfit: list[MisfitRange]
    thermal: ThermalFit | None = None
    compensated_var: NDArray[np.float64] | None = None
    contributions: dict[str, NDArray[np.float64]] = field(default_factory=dict)
    #: AVAR with only the temperature part removed (the thermal fit's compensated curve)
    thermal_compensated_var: NDArray[np.float64] | None = None
    #: the extended model's own misfit ranges (τ beyond 3 σ)
    ext_misfit: list[MisfitRange] = field(default_factory=list)
    #: whether the extended model describes the axis (``verdict.judge``), set by explain
    verdict: Verdict | None = None
    #: τ (fitted or not) where the compensation makes the ADEV worse beyond its interval
    #: (then the compensated ADEV is not given)
    compensation_worse_s: list[float] = field(default_factory=list)

    def compensation_dict(self) -> dict[str, Any] | None:
        """The temperature compensation (``avard analyze --temperature``): the thermal fit
        and the compensated ADEV at the channel's τ (m/s²), or None."""
        if self.thermal is None or self.thermal_compensated_var is None:
            return None
        worse = self._worse(self.thermal_compensated_var)
        if worse:
            return {**self.thermal.to_dict(), "compensated_adev": None,
                    "compensated_withheld": _withheld(worse), "units": {}}
        return {**self.thermal.to_dict(),
                "compensated_adev": np.sqrt(self.thermal_compensated_var).tolist(),
                "units": {"compensated_adev": "m/s^2"}}

    @property
    def claimed(self) -> list[Finding]:
        return [f for f in self.findings if f.claimed]

    @property
    def gain(self) -> float:
        """χ²/dof of the base fit over the extended one (1: no change)."""
        b, e = self.base.fit.chi2_dof, self.extended.chi2_dof
        return b / e if math.isfinite(b) and math.isfinite(e) and e > 0 else float("nan")

    def to_dict(self) -> dict[str, Any]:
        ext = self.extended.to_dict()
        tau = self.base.allan.tau
        out: dict[str, Any] = {
            "base": self.base.to_dict(),
            "extended": {"terms": ext["terms"], "fit": ext["fit"],
                         "components": [_extra_dict(e) for e in self.extended.extra]},
            "findings": [f.to_dict() for f in self.findings],
            "misfit": self.misfit,
            "gain": self.gain,
            "verdict": None if self.verdict is None else self.verdict.to_dict(),
            "thermal": None if self.thermal is None else self.thermal.to_dict(),
            "compensated": None,
            "compensated_withheld": None,
        }
        if self.compensated_var is not None:
            if self.compensation_worse_s:
                out["compensated_withheld"] = _withheld(self.compensation_worse_s)
            else:
                out["compensated"] = {"tau_s": tau.tolist(),
                                      "adev": np.sqrt(self.compensated_var).tolist()}
        return out

    def _worse(self, comp_var: NDArray[np.float64]) -> list[float]:
        a = self.base.allan
        return compensation_worse_at(np.asarray(a.tau, dtype=float), a.hi, comp_var)

    def judge(self, held: ChannelHoldout | None, record_reason: str | None = None,
              screen: ScreenLog | None = None) -> None:
        """Set ``verdict`` from the extended fit and the held-out χ² (``held``: this axis's
        ``holdout.ChannelHoldout`` or None; ``record_reason``: why the held-out test asked
        for could not run on the record at all); when it fails, the claimed causes'
        parameters are model-dependent, and their intervals are withheld where held-out
        data reject."""
        # a warm-up or a step predicts nothing in other data: no held-out test of them
        hx: tuple[float | None, int] = (None, 0)
        missing: str | None = None
        if held is not None and held.folds and held.note is None:
            # with the prediction's own uncertainty: the mechanism's parameters were fitted
            # on the other half (``holdout.Fold.chi2_ext_pred``)
            hx = (held.chi2_ext_pred, held.n_points)
        elif held is not None and held.causes and held.note is None:
            # asked, a mechanism to predict, and no fold ran: the in-sample χ² is not the test
            missing = held.reason or "no held-out fold could be fitted"
        elif held is None and record_reason is not None and any(
                f.claimed and f.cause not in (*EVENTS, "sinusoid", "periodic")
                for f in self.findings):
            # asked, and the record itself could not be split (too short): the same
            missing = record_reason
        self.verdict = judge(self.extended.chi2_dof, self.extended.dof, self.ext_misfit, *hx,
                             heldout_missing=missing,
                             changed=cchange.change_line(self.findings))
        if self.verdict.explained:
            return
        chan = None if screen is None or self.thermal is None else self.thermal.channel
        coarse = None if screen is None or chan is None else screen.coarse(chan, cause=True)
        if coarse is not None:
            # the misfit may be the coarse log's, whose temperature the model reconstructs
            # (``screen.ScreenLog.coarse``)
            self.verdict = replace(self.verdict, suspect=f"temperature '{chan}': {coarse}")
        for f in self.findings:
            if f.claimed and f.cause not in ("sinusoid", "periodic"):
                f.model_dependent = True
                if self.verdict.heldout_rejects and f.intervals:
                    f.intervals_if_model_held, f.intervals = f.intervals, {}


def _withheld(worse: list[float]) -> str:
    return ("not given: the compensation makes the ADEV worse than uncompensated beyond its "
            "68 % interval at τ " + ", ".join(f"{t:.3g}" for t in worse[:8])
            + (" …" if len(worse) > 8 else "") + " s (it removes a signal the axis does not "
            "carry there)")


def _extra_dict(e: dict[str, Any]) -> dict[str, Any]:
    return {k: e[k] for k in ("cause", "label", "params", "present", "lo", "hi", "unit")
            if k in e}


@dataclass
class Explanation:
    """The whole result: analyze's ``Analysis`` of the record, one ``ChannelExplanation`` per
    axis, the AVAR of each temperature channel (K², for the report) and the slow-view block."""

    analysis: Analysis
    channels: dict[str, ChannelExplanation]
    temperature: dict[str, Any] = field(default_factory=dict)
    block_s: float = 0.0
    #: the held-out measure (None only when explain was asked not to make it)
    holdout: Holdout | None = None
    #: what the input screen masked (core/io/screen/), None for blocks that bypassed it
    screen: ScreenLog | None = None
    #: the record's temperature channels the thermal model could not use, with why (a log
    #: without two readings, or one value throughout): said, never dropped in silence
    temperature_unused: dict[str, str] = field(default_factory=dict)

    @property
    def source(self) -> str:
        return self.analysis.source

    @property
    def rate_hz(self) -> float:
        return self.analysis.rate_hz

    def to_dict(self) -> dict[str, Any]:
        """JSON shape (SI units; NaN is written as null by the command)."""
        ho = None if self.holdout is None else self.holdout.to_dict()
        return {"source": self.source, "rate_hz": self.rate_hz,
                "n_samples": self.analysis.n_samples, "units": "SI",
                "holdout_gain": None if ho is None else ho["holdout_gain"],
                "holdout": ho,
                "screened": None if self.screen is None else self.screen.to_dict(),
                # the held-out record's (--holdout FILE), screened by the same rules
                "holdout_screened": None if self.holdout is None
                else self.holdout.screen_dict(),
                "temperature_unused": dict(self.temperature_unused),
                "channels": {k: {**v.to_dict(), "caveats": self.caveats(k)}
                             for k, v in self.channels.items()}}

    def caveats(self, channel: str) -> list[str]:
        """The caveats said under the channel's findings in the text and the report (a
        coupling on a recording of several short runs: ``report.runs_caveat``), for the
        JSON: the same lines, so ``--json`` says what the text says."""
        from avard.core.explain.report import runs_caveat  # report imports this module

        ch = self.channels[channel]
        caveat = (runs_caveat(self) if any(f.cause == "temperature" for f in ch.claimed)
                  else None)
        change = cchange.change_line(ch.findings) or cchange.hedged_line(ch.findings)
        return [c for c in (change, caveat) if c is not None]


def _s(v: float | None) -> str:
    return "—" if v is None else f"{v:.3g}"
