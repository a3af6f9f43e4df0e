"""Several emulated ADXL355s on one bed (daemon/hw/simulation.emulated_rig): each on its own
emulated transport (SPI0 CE0/CE1, SPI1, I2C 0x53), drained through the real driver, sharing
the bed's motion; what ``avard separate`` then finds in them."""

from __future__ import annotations

import numpy as np
import pytest
from avard.core.analysis.separate import separate
from avard.core.errors import ConfigError
from avard.daemon.hw.rig import BusSpec, RigSpec, SensorSpec, bring_up
from avard.daemon.hw.simulation import BedSpec, emulated_rig

ODR = 125.0
SPECS = (SensorSpec("left", BusSpec("spi", 0, device=0), odr_hz=ODR),
         SensorSpec("right", BusSpec("spi", 0, device=1), odr_hz=ODR),
         SensorSpec("far", BusSpec("spi", 1, device=0), odr_hz=ODR),
         SensorSpec("i2c", BusSpec("i2c", 1, address=0x53), odr_hz=ODR))


def _run(seconds: float, bed: BedSpec) -> dict[str, np.ndarray]:
    clock, rig = emulated_rig(SPECS, "quiet-lab", bed=bed, seed=3)
    for spec, (_name, dev, _emu) in zip(SPECS, rig, strict=True):
        bring_up(dev, spec)
    got: dict[str, list[np.ndarray]] = {name: [] for name, _d, _e in rig}
    for _ in range(int(seconds / 0.2)):
        clock.advance(0.2)
        for name, dev, _emu in rig:
            d = dev.drain()
            assert not d.overrun
            got[name].append(d.counts * dev.scale_mps2)
    return {k: np.concatenate(v) for k, v in got.items()}


def test_every_transport_drains_and_the_sensors_share_the_bed() -> None:
    bed = BedSpec(white=4e-4, tilt=0.0, seed=1)      # the bed well above the sensors' noise
    data = _run(120.0, bed)
    n = min(len(v) for v in data.values())
    assert n >= 120 * ODR - 64
    z = np.array([v[:n, 2] - v[:n, 2].mean() for v in data.values()])
    corr = np.corrcoef(z)
    assert np.all(corr[np.triu_indices(4, 1)] > 0.5)   # one common input in all four


def test_separate_finds_the_bed_and_each_sensors_own_noise() -> None:
    bed = BedSpec(white=1e-4, tilt=0.0, seed=2)
    data = _run(400.0, bed)
    n = min(len(v) for v in data.values())
    names = ["left", "right", "i2c"]
    sep = separate([data[k][:n] for k in names], ODR, sensors=names, axes=["x", "y", "z"],
                   filter_corner_hz=ODR / 4)
    ax = sep.axes[2]
    k = int(np.argmin(np.abs(ax.tau - 1.0)))
    # the bed: white 1e-4 m/s/√s, so its ADEV at 1 s is 1e-4 (the sensors' filter is not on
    # it: the bed is added after the simulated sensor)
    assert np.sqrt(ax.common.var[k]) == pytest.approx(1e-4, rel=0.2)
    for i in range(3):
        fit = ax.fits[i]
        assert fit is not None
        n_fit = fit.terms["velocity_random_walk"].value
        assert n_fit == pytest.approx(1.56e-4, rel=0.15)   # quiet-lab's N


def test_two_sensors_on_one_chip_select_or_address_are_refused() -> None:
    with pytest.raises(ConfigError, match=r"both on /dev/spidev0\.1"):
        RigSpec((SPECS[1], SensorSpec("twin", BusSpec("spi", 0, device=1))))
    with pytest.raises(ConfigError, match="address 0x53"):
        RigSpec((SPECS[3], SensorSpec("twin", BusSpec("i2c", 1, address=0x53))))
    with pytest.raises(ConfigError, match="left is used twice"):
        RigSpec((SPECS[0], SensorSpec("left", BusSpec("spi", 1))))
