"""Simulated records on disk (.npz streamed in bounded memory) and the DS18B20 readings."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
from avard.core.errors import DataError
from avard.core.sim.presets import make_config
from avard.core.sim.sim_io import write_npz
from avard.core.sim.simulate import SensorSimulator, simulate_record
from avard.core.sim.thermal import DS18B20_STEP_C, ds18b20_aligned, ds18b20_readings


def test_npz_written_in_chunks_equals_in_memory_record(tmp_path) -> None:
    cfg = make_config("quiet-lab")
    path = tmp_path / "rec.npz"
    n = write_npz(path, cfg, 0.02, seed=4, chunk=1000)        # 8992 samples, 9 chunks
    mem = simulate_record(cfg, 0.02, seed=4)
    with np.load(path, allow_pickle=False) as d:
        assert n == d["accel"].shape[0] == mem["accel"].shape[0]
        assert np.array_equal(d["accel"], mem["accel"])
        assert np.array_equal(d["temperature_c"], mem["temperature_c"], equal_nan=True)
        assert float(d["rate_hz"]) == pytest.approx(125.0 * (1 - 800e-6))
        assert list(d["axes"]) == ["x", "y", "z"]
        assert list(d["temperature_names"]) == ["plate", "ambient"]
        assert json.loads(str(d["sim_config"]))["preset"] == "quiet-lab"
        # accel is what the chip reports: whole LSBs
        counts = d["accel"] / float(d["lsb_mps2"])
        assert np.allclose(counts, np.rint(counts), rtol=0, atol=1e-6)
    assert [p.name for p in tmp_path.iterdir()] == ["rec.npz"]     # no temporary files left
    assert os.stat(path).st_mode & 0o044                            # readable like any file


def test_npz_accel_equals_the_streamed_counts(tmp_path) -> None:
    cfg = make_config("adxl355-datasheet")
    write_npz(tmp_path / "a.npz", cfg, 0.005, seed=9)
    counts = SensorSimulator(cfg, seed=9).next(2250).counts
    with np.load(tmp_path / "a.npz") as d:
        assert np.array_equal(d["accel"], counts * cfg.lsb_mps2)


def test_npz_bad_output_is_a_clear_error(tmp_path) -> None:
    cfg = make_config("quiet-lab")
    with pytest.raises(DataError, match=r"\.npz"):
        write_npz(tmp_path / "rec.csv", cfg, 0.01, seed=1)
    with pytest.raises(DataError, match="does not exist"):
        write_npz(tmp_path / "nowhere" / "rec.npz", cfg, 0.01, seed=1)
    with pytest.raises(DataError, match="less than one sample"):
        write_npz(tmp_path / "rec.npz", cfg, 1e-9, seed=1)
    assert list(tmp_path.iterdir()) == []


def test_ds18b20_one_reading_per_conversion_in_sixteenths() -> None:
    rate = 125.0
    temp = np.column_stack([20.0 + np.linspace(0, 1, 2000), np.full(2000, 21.03)])
    t, vals = ds18b20_readings(temp, rate, 0.75)
    assert np.allclose(np.diff(t), 0.75, atol=1 / rate)
    assert len(t) == int(2000 / rate / 0.75)
    assert np.array_equal(vals / DS18B20_STEP_C, np.rint(vals / DS18B20_STEP_C))
    assert np.all(np.abs(vals - temp[np.rint(t * rate).astype(int)]) <= DS18B20_STEP_C / 2)
    assert np.all(vals[:, 1] == 21.0)                           # 21.03 reads as 21.0000
    # the aligned layout splits into chunks exactly like the whole
    whole = ds18b20_aligned(temp, rate, 0.75, offset_c=np.array([0.5, 0.0]))
    parts = np.concatenate([ds18b20_aligned(temp[i:i + 333], rate, 0.75, index0=i,
                                            offset_c=np.array([0.5, 0.0]))
                            for i in range(0, 2000, 333)])
    assert np.array_equal(whole, parts, equal_nan=True)
    assert np.count_nonzero(np.isfinite(whole[:, 0])) == len(t)
    assert np.allclose(whole[np.isfinite(whole[:, 0]), 0], vals[:, 0] + 0.5)


def test_temperatures_at_a_few_samples_equal_the_full_arrays() -> None:
    sim = SensorSimulator(make_config("quiet-lab", hvac_period_s=60.0), seed=3)
    sim.next(777)
    c = sim.next(5000)
    rel = np.array([0, 1, 93, 2048, 4999])
    full = np.column_stack([c.temp_c, c.chip_temp_c])
    assert np.allclose(c.temperatures_at(rel), full[rel], rtol=0, atol=1e-12)
    # and the npz layout built from them matches the array path
    aligned = ds18b20_aligned(c.temp_c, 124.9, 0.75, index0=c.index0)
    assert np.count_nonzero(np.isfinite(aligned[:, 0])) > 0
