"""The transients' stated minima: the smallest excursion, warm-up (in the fit) and drift a record
of these noise terms detects at z = 5 (a power statement, never a floor)."""

from __future__ import annotations

import math

import numpy as np
from avard.core.analysis.drift import DRIFT_BLOCKS
from avard.core.explain import causes as cz
from avard.core.explain.transients.scan import MAX_BLOCKS, _column


def min_detectable_excursion(n_white: float, b_inst: float, k_rrw: float, record_s: float,
                             duration_s: float, z: float = 5.0, blocks: int = 1024) -> float:
    """The stated minimum of an excursion (m/s²): z standard errors of its size in the GLS
    fit (its Fisher information) with noise N, B, K over ``record_s``, the excursion
    ``duration_s`` long in the middle of the record."""
    dt = record_s / blocks
    t = (np.arange(blocks) + 0.5) * dt
    g_cov = cz._noise_cov(t, dt, n_white, b_inst, k_rrw)
    L = np.linalg.cholesky(g_cov)
    t0 = 0.5 * (record_s - duration_s)
    cols = np.column_stack([np.ones_like(t), t, _column(
        "excursion", {"start_s": t0, "end_s": t0 + duration_s}, t, dt)])
    a = np.linalg.solve(L, cols)
    return float(z * math.sqrt(np.linalg.inv(a.T @ a)[2, 2]))


def min_detectable_warmup_in_fit(n_white: float, b_inst: float, k_rrw: float,
                                 record_s: float, time_constant_s: float, z: float = 5.0,
                                 blocks: int = MAX_BLOCKS) -> float:
    """The stated minimum of a warm-up in the compound fit (m/s²): z standard errors of its
    size by GLS with noise N, B, K over ``record_s``, with the offset, the slope and its T
    fitted beside it (the Fisher information with the column ∂/∂T; a scale of that column
    leaves the size's error unchanged, so the minimum does not depend on the size). For
    T ≪ record it is ``causes.min_detectable_warmup``'s regime; from T ≈ record/6 on, the
    line and T take most of e^(−t/T) and the minimum rises well above it."""
    dt = record_s / blocks
    t = (np.arange(blocks) + 0.5) * dt
    L = np.linalg.cholesky(cz._noise_cov(t, dt, n_white, b_inst, k_rrw))
    e = np.exp(-t / time_constant_s)
    a = np.linalg.solve(L, np.column_stack([np.ones_like(t), t, e,
                                            t / time_constant_s**2 * e]))
    return float(z * math.sqrt(np.linalg.inv(a.T @ a)[2, 2]))


def min_detectable_drift(n_white: float, b_inst: float, k_rrw: float, record_s: float,
                         z: float = 5.0, blocks: int = DRIFT_BLOCKS) -> float:
    """The stated minimum of a drift (m/s³): z standard errors of its slope in the GLS fit
    with noise N, B, K over ``record_s`` (the Fisher information of the slope, the random
    walk in the covariance)."""
    dt = record_s / blocks
    t = (np.arange(blocks) + 0.5) * dt
    L = np.linalg.cholesky(cz._noise_cov(t, dt, n_white, b_inst, k_rrw))
    a = np.linalg.solve(L, np.column_stack([np.ones_like(t), t - t.mean()]))
    return float(z * math.sqrt(np.linalg.inv(a.T @ a)[1, 1]))
