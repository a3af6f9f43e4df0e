"""deviations.grid_sums_by_part: the differences of the whole grid taken once, each part's
Gram products added to it, equal bit for bit to grid_sums on each part's own slice (how
thermal_fit.octave_sums_by_part summed them before), for contiguous and strided grids,
empty parts, and a grid longer than one chunk (the fallback)."""

from __future__ import annotations

import numpy as np
import pytest
from avard.core.allan import deviations as dev
from avard.core.allan.deviations import DifferenceSums, grid_sums, grid_sums_by_part


def _per_part(q: np.ndarray, sp: int, cut: np.ndarray) -> list[DifferenceSums]:
    out = [DifferenceSums.zeros(q.shape[1]) for _ in range(len(cut) - 1)]
    for g, part in enumerate(out):
        j0, j1 = int(cut[g]), int(cut[g + 1])
        if j1 > j0:
            grid_sums(q[j0:j1 + 2 * sp], sp, 0, part, 2)
    return out


@pytest.mark.parametrize("stride", [1, 3])
@pytest.mark.parametrize("sp", [1, 2, 7, 64])
def test_the_same_sums_as_grid_sums_per_part(stride: int, sp: int) -> None:
    rng = np.random.default_rng(sp * 10 + stride)
    p = np.cumsum(rng.standard_normal((5000, 4)) * [1e-3, 2.0, 1e5, 1e-9], axis=0)
    q = p[::stride]
    n_d = len(q) - 2 * sp
    cut = np.array([0, 0, 17, n_d // 3, n_d // 3, n_d // 2 + 5, n_d])  # empty parts too
    want = _per_part(q, sp, cut)
    got = [DifferenceSums.zeros(4) for _ in range(len(cut) - 1)]
    grid_sums_by_part(q, sp, cut, got)
    for w, g in zip(want, got, strict=True):
        assert g.n == w.n
        assert np.array_equal(g.s2, w.s2)  # bit for bit
    assert sum(g.n for g in got) == n_d


def test_a_grid_longer_than_a_chunk_falls_back_to_grid_sums(monkeypatch) -> None:
    monkeypatch.setattr(dev, "_CHUNK", 64)
    rng = np.random.default_rng(5)
    q = np.cumsum(rng.standard_normal((1000, 2)), axis=0)
    cut = np.array([0, 300, 996])
    want = _per_part(q, 2, cut)
    got = [DifferenceSums.zeros(2) for _ in range(2)]
    grid_sums_by_part(q, 2, cut, got)
    for w, g in zip(want, got, strict=True):
        assert g.n == w.n and np.array_equal(g.s2, w.s2)
