"""The driver against a real ADXL355 on /dev/spidev0.0 (and DS18B20 on the 1-Wire bus).

Run on the Raspberry Pi only: ``AVARD_HARDWARE=1 .venv/bin/python -m pytest -m hardware
tests/daemon/test_adxl355_hardware.py``. Skipped everywhere else (see tests/conftest.py).
The sensor should lie still, Z up.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
from avard.daemon.hw.adxl355 import Adxl355
from avard.daemon.hw.timebase import TimeBase
from avard.daemon.hw.transport import open_bus

pytestmark = pytest.mark.hardware


@pytest.fixture
def dev():
    bus = open_bus("spi", bus=0, device=0, speed_hz=5_000_000)
    d = Adxl355(bus)
    d.probe()
    d.reset()
    yield d
    d.standby()
    bus.close()


def test_probe_ids(dev):
    info = dev.probe()
    assert (info.devid_ad, info.devid_mst) == (0xAD, 0x1D) and info.partid in (0xED, 0xE9)


def test_drain_one_second_at_1khz_is_continuous_and_about_one_g(dev):
    dev.configure(range_g=2, odr_hz=1000)
    dev.start()
    tb = TimeBase(1000.0, group_delay_samples=dev.group_delay_samples, min_span_s=0.5)
    got = []
    t_end = time.monotonic() + 2.0
    while time.monotonic() < t_end:
        time.sleep(0.01)  # the FIFO lasts 32 ms at 1 kHz
        d = dev.drain()
        assert not d.overrun, d.gap_reason
        got.append(d.counts)
        tb.add_drain(d)
    c = np.concatenate(got) * dev.scale_mps2
    assert 1800 < len(c) < 2200
    g = np.linalg.norm(c.mean(axis=0))
    assert 9.0 < g < 10.6  # 1 g within sensitivity tolerance and offset
    assert abs(tb.rate().ppm) < 60_000  # datasheet histogram: ±5 %


def test_chip_temperature_is_plausible(dev):
    dev.configure(range_g=2, odr_hz=125)
    dev.start()
    time.sleep(0.05)
    assert 0.0 < dev.read_temperature_c() < 70.0


def test_self_test_at_8g(dev):
    dev.configure(range_g=8, odr_hz=500)
    res = dev.self_test()
    assert res.passed, res


def test_ds18b20_on_the_bus_if_any():
    from avard.daemon.hw import ds18b20

    ids = ds18b20.discover()
    if not ids:
        pytest.skip("no DS18B20 on /sys/bus/w1/devices")
    for reading in ds18b20.Ds18b20Bank(ids).read_all():
        assert reading.ok and -20.0 < reading.value_c < 60.0 and not math.isnan(reading.value_c)
