"""The reader waiting on INT1 (FIFO watermark) instead of a timer, on the emulated pin."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from avard.core.errors import ConfigError
from avard.core.io.recording import RecordingReader
from avard.daemon.compose import simulated_service
from avard.daemon.config import load_config
from avard.daemon.hw.adxl355 import Adxl355
from avard.daemon.hw.emulator import EmulatedAdxl355, FakeSpiDev, VirtualClock, counter_source
from avard.daemon.hw.interrupt import EmulatedInterruptPin, GpiodPin, parse_spec
from avard.daemon.hw.pacing import watermark_sets, watermark_settings
from avard.daemon.hw.transport import SpiBus


def _rig(use_int1: bool) -> tuple[Adxl355, EmulatedAdxl355, VirtualClock]:
    clock = VirtualClock()
    emu = EmulatedAdxl355(counter_source(), clock)
    dev = Adxl355(SpiBus(FakeSpiDev(emu)), clock=clock)
    dev.probe()
    dev.reset()
    dev.configure(range_g=2, odr_hz=125.0, **watermark_settings(use_int1))
    dev.start()
    return dev, emu, clock


def test_pin_rises_at_the_watermark_and_falls_after_a_drain() -> None:
    dev, emu, clock = _rig(True)
    pin = EmulatedInterruptPin(emu, clock)
    wm = watermark_sets()
    t0 = clock.monotonic()
    assert pin.wait(10.0)
    # asserted exactly when the FIFO holds the watermark's sets
    assert clock.monotonic() - t0 == pytest.approx(wm / 125.0, abs=1.5 / 125.0)
    assert emu.fifo_entries >= 3 * wm and emu.int_level(1)
    dev.drain()
    assert not emu.int_level(1)
    # INT_MAP lost (the part reset behind the driver's back): the pin never rises and the
    # wait falls back to its timeout
    _dev2, emu2, clock2 = _rig(True)
    emu2.regs[0x2A] = 0
    pin2 = EmulatedInterruptPin(emu2, clock2)
    t0 = clock2.monotonic()
    assert not pin2.wait(0.5)
    assert clock2.monotonic() - t0 == pytest.approx(0.5)


def test_service_on_the_pin_drains_once_per_watermark_and_loses_nothing(tmp_path: Path) -> None:
    cfg = load_config(None, **{"recording.data_dir": str(tmp_path), "publish.enabled": False,
                               "sensor.int1_gpio": "emulated", "sensor.poll_hz": 1.0})
    svc, _sims, _emu = simulated_service(cfg, "quiet-lab", seed=2)
    pin = svc.interrupt
    assert isinstance(pin, EmulatedInterruptPin)
    svc.run(60.0)
    st = svc.final_status
    assert st["overruns"] == 0 and st["gaps"] == 0
    # one wake per watermark: 125 Hz / 16 sets, not the timer's rate or more
    assert pin.waits == pytest.approx(st["sim_time_s"] * 125.0 / watermark_sets(), rel=0.05)
    assert pin.asserted >= 0.95 * pin.waits
    raw = [r for r in RecordingReader(tmp_path) if r["kind"] == "raw"]
    idx = np.concatenate([r["i0"] + np.arange(r["n"]) for r in raw])
    np.testing.assert_array_equal(idx, np.arange(idx[0], idx[0] + st["samples"]))


def test_gpio_spec_and_missing_binding_are_one_clear_line() -> None:
    assert parse_spec("gpiochip0:25") == ("gpiochip0", 25)
    with pytest.raises(ConfigError, match="CHIP:LINE"):
        parse_spec("25")
    try:
        import gpiod  # type: ignore[import-not-found]  # noqa: F401
    except ImportError:
        with pytest.raises(ConfigError, match="libgpiod"):
            GpiodPin("gpiochip0:25")
