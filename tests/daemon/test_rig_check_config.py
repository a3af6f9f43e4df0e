"""check-config on a rig (issue 28 item 1's review): one [[sensor]] entry is no rig, and
every sensor's wiring, drain rate and real-time note are said, not only the first's."""

from __future__ import annotations

from pathlib import Path

import pytest

# -- 9. check-config on a rig ------------------------------------------------------------------

def _check_config(tmp_path: Path, toml: str, capsys: pytest.CaptureFixture[str]) -> str:
    from avard.daemon import cli

    path = tmp_path / "avard.toml"
    path.write_text(toml + f'\n[recording]\ndata_dir = "{tmp_path / "rec"}"\n'
                    '[temperature]\nds18b20 = false\n')
    assert cli.main(["check-config", str(path)]) == 0
    return capsys.readouterr().out


def test_check_config_of_one_sensor_entry_says_no_rig(tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    out = _check_config(tmp_path, '[[sensor]]\nname = "left"\n', capsys)
    assert "sensors, each recorded" not in out
    assert "ADXL355 at 125 Hz ODR" in out


def test_check_config_says_every_sensors_drain_and_real_time_note(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = _check_config(tmp_path, '[[sensor]]\nname = "left"\n\n'
                        '[[sensor]]\nname = "right"\nspi_device = 1\nodr_hz = 1000.0\n\n'
                        '[[sensor]]\nname = "far"\nspi_bus = 1\nodr_hz = 1000.0\n'
                        'int1_gpio = "gpiochip0:25"\n', capsys)
    assert "3 sensors, each recorded in DATA_DIR/NAME" in out
    assert "left: /dev/spidev0.0, ADXL355 at 125 Hz ODR" in out
    # SPI0's bus is drained by a reader process (a quarter of the FIFO: 125 Hz at 1000 Hz)
    assert ("right: /dev/spidev0.1, ADXL355 at 1000 Hz ODR, ±2 g, drained at 125 Hz by its "
            "bus reader process") in out
    assert "note: at 1000 Hz the FIFO holds 32 ms" in out
    # a bus with INT1: its reader thread, at the FIFO half full, and the thread's note
    assert ("far: /dev/spidev1.0, ADXL355 at 1000 Hz ODR, ±2 g, drained at 62.5 Hz by its "
            "bus's reader thread (INT1 on the bus)") in out
    assert "note: at 1000 Hz (far)" in out
