"""DS18B20 faults under the running service: w1thermsensor itself over a fake sysfs tree.

CRC failures (the kernel's "NO" and a bad scratchpad with "YES"), the 85 °C power-on value, a
sensor removed and re-inserted: each failed read is recorded as a missing value (never as a
made-up temperature), each drop-out and return as an event, the other sensor and the
accelerometer carry on, and the sensor's readings come back when it does.
"""

from __future__ import annotations

import math

from avard.daemon.hw.ds18b20 import Ds18b20Bank

from .fake_w1 import fake_w1_tree
from .test_faults_bus import (
    assert_index_jumps_match_gaps,
    assert_subscriber_saw_everything,
    run_rig,
)

PLATE_C, AMBIENT_C = 24.5, 21.0
# (start time in simulated s, what happens to the plate sensor); each phase lasts 4 s
PHASES = [(8.0, "crc"), (12.0, "ok"), (16.0, "bad_crc_yes"), (20.0, "reset85"),
          (24.0, "removed"), (28.0, "ok")]
END_S = 32.0


#: simulated seconds between two reading rounds of the bank
READ_EVERY_S = 0.6


class _BankOnTheDataClock(Ds18b20Bank):
    """The bank's own read and sink, its rounds paced by the simulation instead of by real
    time: the bank's threads read on the wall clock, and on a loaded machine a starved thread
    left a phase of a few real tenths of a second without a reading (the suite's -n 2 beside
    a busy neighbour). Each round is taken from the reader's drain hook at a simulated time,
    so which phase a reading falls in depends on the data clock alone."""

    def start(self) -> None:  # no threads: rounds come from round_at
        pass

    def stop(self, timeout_s: float = 2.0) -> None:
        pass

    def round_at(self) -> None:
        for reading in self.read_all():
            self.sink(reading)


def test_crc_85c_and_removal_are_missing_values_and_events_then_readings_return(tmp_path):
    tree = fake_w1_tree(tmp_path, plate=PLATE_C, ambient=AMBIENT_C)
    plate = tree.ids["plate"]
    bank = _BankOnTheDataClock({"plate": plate, "ambient": tree.ids["ambient"]},
                               base_directory=tree.base)
    rounds = [0]

    def inject(ctx: dict, t: float) -> None:
        if t >= rounds[0] * READ_EVERY_S:
            rounds[0] = int(t // READ_EVERY_S) + 1
            bank.round_at()
        for start, what in PHASES:
            if t > start and ctx["once"](f"{start}"):
                if what == "ok":
                    if not (tree.base / tree.full_id(plate)).exists():
                        tree.restore(plate)  # re-inserted
                    tree.set_temperature(plate, PLATE_C)
                elif what == "crc":
                    tree.set_crc_failure(plate)
                elif what == "bad_crc_yes":
                    tree.set_bad_crc_but_yes(plate)
                elif what == "reset85":
                    tree.set_reset_value(plate)
                elif what == "removed":
                    tree.remove(plate)

    rig = run_rig(tmp_path, END_S, inject=inject, bank=bank)
    recs = rig.records()
    t0 = rig.svc.t_start
    temps = [r for r in recs if r["kind"] == "temp" and r.get("source") == "ds18b20"]

    def values(name: str, lo: float, hi: float) -> list[float | None]:
        return [r["values_c"][0] for r in temps if r["names"] == [name]
                and lo + 0.8 < r["t_mono"] - t0 < hi - 0.3]

    for (start, what), (end, _) in zip(PHASES, [*PHASES[1:], (END_S, "")], strict=True):
        got = values("plate", start, end)
        assert got, f"no plate readings in phase {what}"
        if what == "ok":
            assert all(v == PLATE_C for v in got), (what, got)
        else:
            # never 85.0, never a stale or invented value: missing
            assert all(v is None for v in got), (what, got)
    # The other sensor never missed a beat.
    amb = values("ambient", 0.0, END_S)
    assert amb and all(v == AMBIENT_C for v in amb)
    assert not any(v is not None and math.isclose(v, 85.0) for r in temps for v in r["values_c"])
    # Every drop-out and every return is an event naming the sensor and what went wrong.
    events = [r for r in recs if r["kind"] == "event" and r["name"] in ("sensor_lost",
                                                                        "sensor_back")]
    names = [e["name"] for e in events]
    assert names[:2] == ["sensor_lost", "sensor_back"]
    assert names[-1] == "sensor_back" and names.count("sensor_back") == 2
    statuses = {e["detail"]["status"] for e in events if e["name"] == "sensor_lost"}
    assert statuses and all(e["detail"]["sensor"] == "plate" for e in events)
    # The accelerometer carried on: no gap, every sample recorded and published.
    assert [g for g in assert_index_jumps_match_gaps(recs) if g["n"]] == []
    assert_subscriber_saw_everything(rig)
