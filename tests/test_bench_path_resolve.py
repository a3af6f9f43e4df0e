"""What one record of the weekend benchmark's two-path row resolves
(``benchmarks/bench_path_ident.py``: ``block_noise_cov``, ``record_resolves``), read by
``bench_explain_weekend.score_resolved``.

The block means' noise covariance must be the generator's own (its white, random walk and
Kasdin flicker, the last two started at the record's start), summed directly; the
non-centrality of the dT/dt rival and the Cramér–Rao deviations must follow the record's own
drive: the plate's start (the generator's lag starts at the room's first value, not on the
HVAC cycle) is what tells two paths from a dT/dt term.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchmarks.bench_path_ident import LAMBDA_95, block_noise_cov


def test_the_block_noise_covariance_is_the_generators_summed_directly():
    n, m, rate = 120, 10, 10.0
    N, B, K = 1.6e-4, 2e-5, 2e-6
    k = np.arange(1, n)
    h = np.concatenate([[1.0], np.cumprod((k - 1 + 0.5) / k)])
    H = np.array([[h[i - j] if i >= j else 0.0 for j in range(n)] for i in range(n)])
    idx = np.arange(n)
    full = (N**2 * rate * np.eye(n) + B**2 * H @ H.T
            + K**2 / rate * (np.minimum.outer(idx, idx) + 1.0))
    A = np.kron(np.eye(n // m), np.full((1, m), 1.0 / m))
    assert block_noise_cov(n, m, rate, N, B, K) == pytest.approx(A @ full @ A.T, rel=1e-10)


def test_a_95_percent_choice_needs_a_noncentrality_of_about_eleven():
    # Φ(√λ/2) = 0.95
    assert 0.5 * (1 + math.erf(math.sqrt(LAMBDA_95) / 2 / math.sqrt(2))) == pytest.approx(0.95)


@pytest.mark.slow
def test_the_two_path_row_resolves_its_mechanism_by_the_plates_start():
    """On the row's default seeds: 30004, whose plate starts 0.45 K from its cycle, tells two
    paths from the dT/dt term (λ far above 11) and still leaves c₂ beyond ±10 % and L2
    beyond ±20 %; 30017, whose plate starts 0.09 K off, does not tell them apart (λ under
    11) and leaves c₂ beyond ±50 % (Cramér–Rao, all four parameters unknown)."""
    from benchmarks.bench_explain_weekend import _whiten, rows_paths
    from benchmarks.bench_path_ident import ID_BLOCK, record_resolves

    row = next(r for r in rows_paths() if r.name == "path: two paths")
    w = row.weekend
    wh = _whiten(int(w.hours * 3600 * w.rate_hz), ID_BLOCK, float(w.rate_hz))
    truth = {**row.truth, "lag_s": 0.0}
    clear = record_resolves(w, 30004, truth, wh)
    murky = record_resolves(w, 30017, truth, wh)
    c2, L2 = abs(truth["coefficient_2"]), truth["lag_2_s"]
    assert clear["lambda_rate"] > 3 * LAMBDA_95 and murky["lambda_rate"] < LAMBDA_95
    assert clear["sd_coefficient_2"] > 0.1 * c2 and clear["sd_lag_2_s"] > 0.2 * L2
    assert murky["sd_coefficient_2"] > 0.5 * c2
