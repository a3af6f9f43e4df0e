"""DS18B20 readers through w1thermsensor itself over a fake sysfs tree."""

from __future__ import annotations

import logging
import math
import time
from pathlib import Path

import pytest
from avard.core.errors import ConfigError
from avard.daemon.hw import ds18b20 as D
from avard.daemon.hw.emulator import VirtualClock
from avard.daemon.hw.w1_sysfs import crc8_maxim, scratchpad, w1_slave_text

from .fake_w1 import fake_w1_tree


def test_crc8_and_scratchpad_match_a_real_sensor_dump():
    # a line captured from a Raspberry Pi w1_slave at 23.125 °C
    real = "72 01 4b 46 7f ff 0e 10 57 : crc=57 YES"
    assert w1_slave_text(scratchpad(23.125)).splitlines()[0] == real
    assert crc8_maxim(bytes.fromhex("72014b467fff0e1057")) == 0  # CRC over all 9 bytes is 0
    assert scratchpad(-10.125)[:2] == bytes([0x5E, 0xFF])
    with pytest.raises(ValueError):
        scratchpad(130.0)


def test_w1thermsensor_itself_reads_the_fake_tree(tmp_path):
    tree = fake_w1_tree(tmp_path, plate=24.5625)
    cls = D.sensor_class(tree.base)
    w1 = D.import_w1thermsensor()
    s = cls(w1.Sensor.DS18B20, tree.ids["plate"].split("-")[1])
    assert s.get_temperature() == 24.5625
    assert cls.BASE_DIRECTORY == tree.base
    assert w1.W1ThermSensor.BASE_DIRECTORY == Path("/sys/bus/w1/devices")  # untouched


def test_discover_finds_only_ds18b20_and_tolerates_no_bus(tmp_path, caplog):
    tree = fake_w1_tree(tmp_path, a=20.0, b=21.0)
    assert D.discover(tree.base) == ["0316a2797cff", "0417b3808d00"]
    with caplog.at_level(logging.WARNING):
        assert D.discover(tmp_path / "nowhere") == []
    assert "w1-gpio" in caplog.text


def test_ids_are_normalised_and_checked():
    assert D.normalise_id("28-0316A2797CFF") == "0316a2797cff"
    with pytest.raises(ConfigError, match="not a DS18B20"):
        D.normalise_id("10-0316a2797cff")
    with pytest.raises(ConfigError, match="1-Wire id"):
        D.normalise_id("28-xyz")


def test_faults_give_nan_with_a_status_and_are_logged_once(tmp_path, caplog):
    tree = fake_w1_tree(tmp_path, plate=24.0)
    sid = tree.ids["plate"]
    clock = VirtualClock()
    r = D.SensorReader("plate", sid, base_directory=tree.base, clock=clock)
    first = r.read()
    assert first.ok and first.value_c == 24.0 and first.t_mono == clock.monotonic()
    cases = [
        (tree.set_crc_failure, D.CRC),
        (tree.set_bad_crc_but_yes, D.CRC),
        (tree.set_reset_value, D.RESET_VALUE),
        (tree.set_all_zero, D.NOT_READY),
        (tree.remove, D.MISSING),
    ]
    with caplog.at_level(logging.WARNING, logger="avard.daemon.hw.ds18b20"):
        for make_fault, status in cases:
            if status == D.MISSING:
                tree.set_temperature(sid, 30.0)
            make_fault(sid)
            for _ in range(3):
                rd = r.read()
                assert rd.status == status and math.isnan(rd.value_c), status
            if status == D.MISSING:
                tree.restore(sid)
            else:
                tree.set_temperature(sid, 24.0)
            assert r.read().value_c == (30.0 if status == D.MISSING else 24.0)
    warnings = [rec for rec in caplog.records if rec.levelno == logging.WARNING]
    assert len(warnings) == len(cases)  # one per state change, not one per read
    assert r.counts[D.CRC] == 6 and r.counts[D.OK] == 1 + len(cases)


def test_a_configured_sensor_absent_at_start_reads_nan_until_it_appears(tmp_path):
    tree = fake_w1_tree(tmp_path)
    r = D.SensorReader("ambient", "28-0417b3808d00", base_directory=tree.base)
    assert r.read().status == D.MISSING
    tree.add("0417b3808d00", -5.5)
    rd = r.read()
    assert rd.ok and rd.value_c == -5.5


def test_bank_threads_deliver_stamped_readings_to_a_queue(tmp_path):
    tree = fake_w1_tree(tmp_path, plate=24.0, ambient=21.0)
    bank = D.Ds18b20Bank({"plate": tree.ids["plate"], "ambient": tree.ids["ambient"]},
                         interval_s=0.01, base_directory=tree.base)
    assert bank.names == ["plate", "ambient"]
    with bank:
        deadline = time.monotonic() + 60.0  # a hang bound: the loops end on their condition
        got: list[D.TemperatureReading] = []
        while time.monotonic() < deadline and {g.name for g in got if g.ok} != set(bank.names):
            got += bank.drain()
            time.sleep(0.005)
        tree.remove(tree.ids["ambient"])
        while time.monotonic() < deadline and not any(
                g.name == "ambient" and g.status == D.MISSING for g in got):
            got += bank.drain()
            time.sleep(0.005)
    assert any(g.name == "plate" and g.value_c == 24.0 for g in got)
    assert any(g.name == "ambient" and g.value_c == 21.0 for g in got)
    assert any(g.name == "ambient" and g.status == D.MISSING for g in got)
    for name in bank.names:  # per sensor, stamps increase
        ts = [g.t_mono for g in got if g.name == name]
        assert ts == sorted(ts)
    assert all(not t.is_alive() for t in bank._threads)


def test_bank_discovers_and_survives_a_failing_sink(tmp_path, caplog):
    tree = fake_w1_tree(tmp_path, plate=24.0)
    seen = []

    def sink(reading):
        seen.append(reading)
        if len(seen) == 1:
            raise RuntimeError("consumer bug")

    bank = D.Ds18b20Bank(None, interval_s=0.005, sink=sink, base_directory=tree.base)
    assert bank.names == ["0316a2797cff"]
    with caplog.at_level(logging.ERROR), bank:
        deadline = time.monotonic() + 60.0  # a hang bound: the loops end on their condition
        while len(seen) < 3 and time.monotonic() < deadline:
            time.sleep(0.005)
    assert len(seen) >= 3 and "consumer bug" in caplog.text


def test_bank_rejects_a_bad_interval():
    with pytest.raises(ConfigError):
        D.Ds18b20Bank({}, interval_s=0)
