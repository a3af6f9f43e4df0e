"""Several emulated ADXL355s on one bed (daemon/hw/simulation.emulated_rig): each on its own
emulated transport (SPI0 CE0/CE1, SPI1, I2C 0x53), drained through the real driver, sharing
the bed's motion; what ``avard separate`` then finds in them."""

from __future__ import annotations

import dataclasses

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


def test_the_live_separation_finds_the_beds_common_mode_at_short_tau() -> None:
    """The sensors start measuring as the rig brings them up, some ms apart (not a whole
    number of samples): the bed is a function of time (BedMotion), so aligned by their
    fitted time bases they feel the same bed, and the live separation's common mode is the
    bed's ADEV down to the shortest τ. (Shared by sample count, as the emulator once did,
    the sensors paired one sample off and the common mode at τ0 came out near zero.)"""
    from avard.core.allan.deviations import oavar
    from avard.daemon.hw.simulation import BedMotion
    from avard.daemon.hw.timebase import TimeBase
    from avard.daemon.service.separation_stage import (
        Aligner,
        SensorBlock,
        SensorClock,
        SeparationStage,
    )

    bed = BedSpec(white=4e-4, tilt=0.0, seed=5)
    specs = SPECS[:3]
    clock, rig = emulated_rig(specs, "quiet-lab", bed=bed, seed=3)
    for spec, (_name, dev, _emu) in zip(specs, rig, strict=True):
        bring_up(dev, spec)
    starts = [emu.sampled_at(0, 1)[0] for _n, _d, emu in rig]
    phases = [((t - starts[0]) * ODR) % 1.0 for t in starts[1:]]
    assert all(0.2 < p < 0.8 for p in phases), phases      # a fraction of a sample apart
    names = [n for n, _d, _e in rig]
    aligner, stage = Aligner(names), SeparationStage(names, ODR)
    timebases = [TimeBase(ODR) for _ in rig]
    for _ in range(int(300.0 / 0.2)):
        clock.advance(0.2)
        for (name, dev, _e), tb in zip(rig, timebases, strict=True):
            d = dev.drain()
            tb.update(d.index0 + len(d.counts) - 1, d.t_mono)
            aligner.push(SensorBlock(name, d.index0, d.counts * dev.scale_mps2),
                         SensorClock.of(tb, d.index0))
        while (blk := aligner.pop()) is not None:
            stage.feed(blk)
    live = stage.separation()
    assert live is not None and aligner.slips == dict.fromkeys(names, 0)
    # The truth: what the bed alone gives the estimator at the sensors' own instants (the
    # aligner pairs each tick with the nearest sample, up to half a sample away, and the bed
    # at 3 ms apart is not quite the same bed): another draw of the same motion, long, read
    # at those offsets, separated with no sensor noise.
    lags = [(p - round(p)) / ODR for p in
            [(t - starts[0]) * ODR for t in starts]]
    truth_bed = BedMotion(dataclasses.replace(bed, seed=9), 3, ODR, 0.0)
    t = 1.0 + np.arange(300_000) / ODR
    ys = [truth_bed.at(s, t + lag) for s, lag in enumerate(lags)]
    truth = separate(ys, ODR, sensors=names, axes=["x", "y", "z"], fit=False,
                     overlap=8).axes[2].common
    own = oavar(ys[0][:, 2], ODR)
    common = live.axes[2].common
    for k in range(3):                                      # τ = 8, 16, 32 ms
        assert not common.upper_limit[k]
        # within three half-widths of the 68 % interval (one realisation: a 68 % interval
        # misses a third of the time)
        half = (common.hi[k] - common.lo[k]) / 2
        assert abs(common.var[k] - truth.var[k]) <= 3 * half, (k, common.var[k], truth.var[k])
        # and that is the bed's own ADEV but for the misalignment
        assert truth.var[k] == pytest.approx(own.var[k].item(), rel=0.2)
