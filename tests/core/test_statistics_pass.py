"""The --stat pass's averaging (core/analysis/statistics.py): block splits do not matter,
nothing is averaged across a segment end, the longest segment is the one used, and a record
longer than announced is an error rather than a silent overwrite."""

from __future__ import annotations

import numpy as np
import pytest
from avard.core.allan.extension import decimate
from avard.core.analysis.statistics import _Averager
from avard.core.errors import DataError


def test_any_block_split_gives_the_averages_of_the_whole() -> None:
    y = np.random.default_rng(0).standard_normal((1000, 2))
    for sizes in ([1000], [7] * 142 + [6], [333, 1, 666]):
        avg = _Averager(2, 6, 1000)
        i = 0
        for s in sizes:
            avg.push(y[i:i + s], False)
            i += s
        got, segments = avg.longest()
        assert segments == 1
        np.testing.assert_allclose(got, decimate(y, 6), rtol=1e-12)


def test_segments_are_not_averaged_across_and_the_longest_is_used() -> None:
    y = np.arange(100.0)[:, None]
    avg = _Averager(1, 4, 100)
    avg.push(y[:30], True)  # 7 averages, 2 samples dropped at the segment's end
    avg.push(y[30:100], True)  # 17 averages
    got, segments = avg.longest()
    assert segments == 2
    np.testing.assert_allclose(got[:, 0], decimate(y[30:98], 4)[:, 0])


def test_a_record_longer_than_announced_is_an_error() -> None:
    avg = _Averager(1, 2, 10)
    with pytest.raises(DataError, match="longer than its sample count"):
        avg.push(np.zeros((40, 1)), False)
