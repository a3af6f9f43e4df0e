"""The register map as data: addresses, reset values, rates, ranges, temperature formula."""

from __future__ import annotations

import pytest
from avard.core.errors import ConfigError
from avard.daemon.hw import registers as R


def test_addresses_and_resets_match_the_datasheet_table():
    expect = {"DEVID_AD": (0x00, 0xAD), "DEVID_MST": (0x01, 0x1D), "PARTID": (0x02, 0xED),
              "STATUS": (0x04, 0x00), "FIFO_ENTRIES": (0x05, 0), "TEMP2": (0x06, 0),
              "XDATA3": (0x08, 0), "FIFO_DATA": (0x11, 0), "OFFSET_X_H": (0x1E, 0),
              "ACT_COUNT": (0x27, 1), "FILTER": (0x28, 0), "FIFO_SAMPLES": (0x29, 0x60),
              "RANGE": (0x2C, 0x81), "POWER_CTL": (0x2D, 0x01), "SELF_TEST": (0x2E, 0),
              "RESET": (0x2F, 0)}
    for name, (addr, reset) in expect.items():
        reg = R.REGISTERS[name]
        assert (reg.address, reg.reset) == (addr, reset), name
    assert len(R.BY_ADDRESS) == len(R.REGISTERS)  # no two names share an address
    assert all(r.address < R.N_REGISTERS for r in R.REGISTERS.values())


def test_config_registers_are_exactly_0x1e_to_0x2c():
    cfg = sorted(r.address for r in R.REGISTERS.values() if r.config)
    assert cfg == list(range(0x1E, 0x2D))


def test_fields_get_and_put():
    f = R.REGISTERS["RANGE"].fields["RANGE"]
    assert f.get(0x81) == 1
    assert f.put(0x81, 3) == 0x83  # I2C_HS and the other bits kept
    with pytest.raises(ValueError):
        f.put(0, 4)
    assert R.REGISTERS["STATUS"].fields["NVM_BUSY"].put(0, 1) == R.STATUS_NVM_BUSY


@pytest.mark.parametrize("odr,code", [(4000, 0), (1000, 2), (125, 5), (7.813, 9), (3.906, 10)])
def test_rate_for_accepts_the_table(odr, code):
    assert R.rate_for(odr).code == code


def test_rate_for_refuses_100_hz_with_the_nearest_rates():
    with pytest.raises(ConfigError) as exc:
        R.rate_for(100)
    msg = str(exc.value)
    assert "100 Hz" in msg and "125 Hz" in msg and "62.5 Hz" in msg
    with pytest.raises(ConfigError, match="4000 Hz"):
        R.rate_for(8000)


def test_ranges_and_sensitivity():
    assert [R.range_code(g) for g in (2, 4, 8)] == [1, 2, 3]
    with pytest.raises(ConfigError, match="±16 g"):
        R.range_code(16)
    assert R.counts_to_mps2(2) == pytest.approx(9.80665 / 256000)
    assert R.counts_to_mps2(8) == pytest.approx(4 * R.counts_to_mps2(2))


def test_temperature_formula_and_inverse():
    assert R.temperature_from_raw(1885) == 25.0
    assert R.temperature_from_raw(1852, R.TEMP_INTERCEPT_REV0) == 25.0
    assert R.temperature_from_raw(1885 - 90.5) == pytest.approx(35.0)
    for t in (-20.0, 0.0, 25.0, 61.3):
        assert abs(R.temperature_from_raw(R.raw_from_temperature(t)) - t) <= 0.5 / 9.05 + 1e-12
    assert R.raw_from_temperature(1e6) == 0 and R.raw_from_temperature(-1e6) == 0xFFF


def test_importing_the_hardware_layer_touches_no_hardware():
    """No spidev, smbus2 or w1thermsensor import (w1thermsensor would run modprobe) until a
    bus or sensor is actually opened."""
    import os
    import subprocess
    import sys

    code = ("import sys\n"
            "import avard.daemon.hw.registers, avard.daemon.hw.transport, avard.daemon.hw.adxl355\n"
            "import avard.daemon.hw.timebase, avard.daemon.hw.emulator\n"
            "import avard.daemon.hw.ds18b20\n"
            "import avard.daemon.hw.w1_sysfs, avard.daemon.hw.thread_priority\n"
            "import avard.daemon.commands.probe\n"
            "print(sorted(m for m in ('spidev', 'smbus2', 'w1thermsensor') if m in sys.modules))")
    env = {k: v for k, v in os.environ.items() if k != "W1THERMSENSOR_NO_KERNEL_MODULE"}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         check=True, timeout=60)
    assert out.stdout.strip() == "[]"
