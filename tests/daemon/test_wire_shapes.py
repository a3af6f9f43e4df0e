"""The `avar` record keeps every array's shape on the wire (docs/wire-format.md: "lists of
lists, so every array has its full shape"; K ≥ 1 because no snapshot is sent before the
first τ point, where (0, C) arrays would arrive as a shapeless [])."""

from __future__ import annotations

import numpy as np
import pytest
from avard.core.allan.feed import AllanFeed
from avard.core.allan.streaming import AllanSnapshot, StreamingAllan
from avard.core.errors import AvardError
from avard.core.io import frames
from avard.daemon.service.allan_stage import AllanStage
from avard.daemon.service.publisher_stage import RequestHandlers
from avard.daemon.service.ring import Ring
from avard.daemon.service.snapshots import SnapshotBoard

TEMPS = ["chip", "plate"]
C = 3 + len(TEMPS)


def _stage() -> tuple[AllanStage, AllanFeed]:
    ring = Ring(1000, mark_capacity=8)
    allan = StreamingAllan(C, 125.0, overlap=8, names=["x", "y", "z", *TEMPS])
    feed = AllanFeed(allan, 1e-5, TEMPS)
    stage = AllanStage(ring.consumer("allan"), allan, feed, run_id="run", real_offset=0.0,
                       rate_hz=lambda: 124.9, emit=ring.mark, on_checkpoint=None,
                       snapshot_interval_s=1e9, checkpoint_interval_s=1e9)
    return stage, feed


def test_no_avar_record_before_the_first_tau_point() -> None:
    stage, feed = _stage()
    assert stage.snapshot_record() is None
    feed.temp(0, TEMPS, [21.0, 20.5])
    feed.raw(0, np.ones((1, 3), np.int32))   # one sample: no difference of two averages yet
    assert stage.snapshot_record() is None
    feed.raw(1, np.ones((1, 3), np.int32))   # the second gives the first τ point (m = 1)
    assert stage.snapshot_record() is not None


def test_every_snapshot_array_keeps_its_shape_through_the_wire() -> None:
    stage, feed = _stage()
    rng = np.random.default_rng(1)
    feed.temp(0, TEMPS, [21.0, 20.5])
    feed.raw(0, rng.integers(-500, 500, (4000, 3)).astype(np.int32))
    rec = stage.snapshot_record()
    assert rec is not None
    snap = frames.unpack_arrays(frames.decode(frames.encode(rec)))["snapshot"]
    k = len(snap["tau"])
    assert k >= 1 and len(snap["m"]) == len(snap["stride"]) == len(snap["n"]) == k
    for key in ("avar", "lo", "hi", "edf", "alpha"):
        assert np.asarray(snap[key]).shape == (k, C), key
    assert np.asarray(snap["cov"]).shape == (k, C, C)
    assert snap["channels"] == ["x", "y", "z", *TEMPS]
    assert snap["units"] == ["m/s^2"] * 3 + ["degC"] * 2
    # τ is labelled with the fitted rate handed to the stage, not the accumulators' nominal one
    assert snap["tau"][0] == pytest.approx(snap["m"][0] / 124.9)
    # the feed's scale, which the snapshot fit takes as the rounding LSB (analyze's rule)
    assert snap["lsb_mps2"] == 1e-5
    assert AllanSnapshot.from_dict(snap).lsb_mps2 == 1e-5


def test_snapshot_request_before_the_first_record_is_a_clear_error_then_the_record() -> None:
    stage, feed = _stage()
    board = SnapshotBoard(lambda rec: {"x": {"chi2_dof": 1.0}})
    handlers = RequestHandlers(snapshots=board, status=dict, header=None,  # type: ignore[arg-type]
                               ring=Ring(10), nominal_odr_hz=125.0, rate_hz=lambda: 124.9,
                               scale_m_s2_per_count=1e-5, recent_max_s=10.0)
    try:
        with pytest.raises(AvardError, match="no Allan snapshot yet"):
            handlers.snapshot({})
        feed.temp(0, TEMPS, [21.0, 20.5])
        feed.raw(0, np.arange(3000 * 3, dtype=np.int32).reshape(3000, 3) % 7)
        rec = stage.snapshot_record()
        assert rec is not None
        board.publish(rec)
        assert board.wait_fitted(10.0)
        reply = handlers.snapshot({})
        assert reply["snapshot"] is rec["snapshot"] and reply["fit"] == {"x": {"chi2_dof": 1.0}}
    finally:
        board.stop()
