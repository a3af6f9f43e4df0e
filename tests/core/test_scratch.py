"""The Allan kernels' work memory (core/allan/scratch.py): an analyze's passes, read one after
another, hand the first pass's mapped history to the next (``histories_passed_on``) and give
it back at the end, without changing a bit of the result."""

from __future__ import annotations

import contextlib
import threading
from pathlib import Path

import numpy as np
import pytest
from avard.core.allan import scratch
from avard.core.allan.overlapping import PIECE
from avard.core.io.source import open_record


def _owner(a: np.ndarray) -> np.ndarray:
    """The array that owns a view's memory."""
    while a.base is not None:
        a = a.base
    return a


def test_a_history_nothing_holds_is_handed_on_within_the_block_only() -> None:
    with scratch.histories_passed_on():
        a = scratch.mapped_zeros((2, 1000))
        a[:] = 5.0
        held = scratch.mapped_zeros((1, 700))  # still referred to: never handed out
        held[:] = 3.0
        base = id(_owner(a))  # an id: a reference would keep the history from being free
        del a
        b = scratch.mapped_zeros((1, 1500))  # fits in the first one's memory, zeroed
        assert id(_owner(b)) == base and not b.any()
        assert id(_owner(held)) != base and (held == 3.0).all()
        other: list[np.ndarray] = []
        t = threading.Thread(target=lambda: other.append(scratch.mapped_zeros((1, 10))))
        t.start()
        t.join()
        assert other[0].base is None  # that thread maps its own
        kept = scratch._local.histories
        with scratch.histories_passed_on():  # nested: the outer block's list goes on
            c = scratch.mapped_zeros((1, 100))
            assert scratch._local.histories is kept and any(_owner(c) is x for x in kept)
        assert scratch._local.histories is kept
    assert getattr(scratch._local, "histories", None) is None
    after = scratch.mapped_zeros((1, 1500))
    assert after.base is None  # given back: a fresh history


def test_a_worker_that_keeps_its_histories_keeps_them(monkeypatch: pytest.MonkeyPatch
                                                      ) -> None:
    monkeypatch.setattr(scratch, "_reused", [])  # as reuse_histories() in a worker
    with scratch.histories_passed_on():
        a = scratch.mapped_zeros((1, 100))
        assert any(_owner(a) is x for x in scratch._reused)
    assert scratch._reused and getattr(scratch._local, "histories", None) is None


def test_passes_sharing_a_history_give_the_same_bits(tmp_path: Path,
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    """A record read in three passes (one channel's history at a time), the second and third
    in the first one's memory, against each pass mapping its own: the same OADEV, EDF, α,
    lines and fit, to the bit."""
    from avard.core.analysis import engine

    n = 1 << 15
    rng = np.random.default_rng(8)
    y = rng.normal(0, 1e-3, (n, 3)) + np.array([0.0, 0.1, 9.81])
    y[:, 2] += np.cumsum(rng.normal(0, 2e-5, n))
    path = tmp_path / "three.npz"
    np.savez(path, accel=y, rate_hz=50.0)
    monkeypatch.setattr(engine, "PASS_BUDGET_BYTES", 8 * (2 * (n // 4) + PIECE))
    assert engine.oadev_pass_groups([0, 1, 2], n) == [[0], [1], [2]]
    maps: list[int | None] = []  # the ids of the memory owners (a reference would hold them)
    inner = scratch.mapped_zeros

    def seen(shape: tuple[int, ...], dtype: type = np.float64) -> np.ndarray:
        out = inner(shape, dtype)
        maps.append(None if out.base is None else id(_owner(out)))
        return out

    from avard.core.allan import overlapping

    monkeypatch.setattr(overlapping, "mapped_zeros", seen)
    shared = engine.analyze(open_record(str(path)))
    assert len(maps) == 3 and maps[0] is not None and maps[1] == maps[0] == maps[2]
    monkeypatch.setattr(engine, "histories_passed_on", contextlib.nullcontext)
    maps.clear()
    own = engine.analyze(open_record(str(path)))
    assert all(m is None for m in maps)  # each pass its own
    assert shared.to_dict() == own.to_dict()
