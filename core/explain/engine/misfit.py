"""Where a fitted model leaves the measured Allan variance, and which tau the fit used."""

from __future__ import annotations

import math

import numpy as np
from avard.core.explain.engine.slow import MISFIT_SIGMA
from avard.core.explain.verdict import MisfitRange
from avard.core.model.fit import NoiseFit
from numpy.typing import NDArray

# --------------------------------------------------------------------------------------------
# misfit


def misfit_ranges(tau: NDArray, var: NDArray, model_var: NDArray, edf: NDArray,
                  sigma: float = MISFIT_SIGMA) -> list[MisfitRange]:
    """Contiguous τ ranges where |z| ≥ sigma, z = (σ̂² − σ²)/(σ²√(2/ν)) (var(σ̂²) = 2σ⁴/ν,
    NIST SP 1065 §5.3), with the largest |z|, its direction and the measured ADEV over the
    model's there (σ̂/σ, the misfit's size in the curve's own terms)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        z = (var - model_var) / (model_var * np.sqrt(2.0 / edf))
    z = np.where(np.isfinite(z), z, 0.0)
    out: list[MisfitRange] = []
    i = 0
    while i < len(z):
        if abs(z[i]) >= sigma:
            j = i
            while j + 1 < len(z) and abs(z[j + 1]) >= sigma and np.sign(z[j + 1]) == np.sign(z[i]):
                j += 1
            k = i + int(np.argmax(np.abs(z[i:j + 1])))
            out.append({"tau_range_s": [float(tau[i]), float(tau[j])],
                        "max_sigma": float(z[k]),
                        "adev_ratio": float(np.sqrt(var[k] / model_var[k]))
                        if var[k] > 0 and model_var[k] > 0 else math.nan,
                        "direction": "above" if z[k] > 0 else "below"})
            i = j + 1
        else:
            i += 1
    return out


def _used(fit: NoiseFit, tau: NDArray) -> NDArray[np.bool_]:
    return (tau >= fit.tau_min_s * (1 - 1e-9)) & (tau <= fit.tau_max_s * (1 + 1e-9))


# --------------------------------------------------------------------------------------------
# the stream


Block = tuple[NDArray[np.float64], NDArray[np.float64] | None, bool]


def _why_unused(t: NDArray | None, refused: str | None = None) -> str | None:
    """Why a temperature channel's slow view cannot drive the thermal model, or None where
    it can (every block has a value, and they vary). ``refused``: the input screen's reason
    to refuse the log as a whole (a log in °F: ``ScreenLog.refused``)."""
    if refused:
        return refused
    if t is None or not len(t) or not np.all(np.isfinite(t)):
        return "fewer than two readings"
    if not np.ptp(t) > 0:
        return f"one value throughout ({float(t[0]):.4g} °C): nothing to regress on"
    return None
