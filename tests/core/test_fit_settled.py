"""fit._settled, the noise fit's iteration stop: the same answer as
np.allclose(new, old, rtol=1e-5, atol=0) (its fast comparison for finite values, allclose
itself otherwise), at the boundary, at zero and with infinities and NaN."""

from __future__ import annotations

import numpy as np
from avard.core.model.fit import _settled


def test_equals_allclose() -> None:
    rng = np.random.default_rng(0)
    cases = []
    for _ in range(2000):
        old = rng.standard_normal(6) * 10.0 ** rng.uniform(-30, 5, 6)
        old[rng.uniform(size=6) < 0.2] = 0.0
        new = old * (1 + rng.choice([0.0, 1e-6, 1e-5, -1e-5, 2e-5, 1e-3], size=6))
        cases.append((new, old))
    old = np.array([1.0, 0.0, 3.0])
    cases += [(old + np.array([1e-5, 0.0, 0.0]), old),  # exactly at the boundary
              (np.array([1e-300, 0.0, 3.0]), old),  # a zero that moved
              (np.array([np.inf, 0.0, 3.0]), np.array([np.inf, 0.0, 3.0])),
              (np.array([np.nan, 0.0, 3.0]), old), (old, np.array([np.nan, 0.0, 3.0]))]
    for new, old in cases:
        assert _settled(new, old) == np.allclose(new, old, rtol=1e-5, atol=0)
