"""From today's one-sensor layout to a rig (issue 28 item 1's review): a recording in
data_dir itself refused until moved, run order across layouts, analyze said and not broken by
an unreadable subdirectory."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from avard.daemon.config_types import Config
from avard.daemon.hw.rig import describe_rig

from tests.daemon.test_rig_service import LEFT, RIGHT, _config

# -- 4. from today's one-sensor layout to a rig ---------------------------------------------------

def _run(config: Config, seconds: float, seed: int) -> Any:
    from avard.daemon.compose import compose_rig

    svc = compose_rig(config, describe_rig(config, simulate="quiet-lab", seed=seed, speed=None))
    svc.run(seconds)
    return svc


def test_a_one_sensor_recording_of_a_rig_sensor_is_refused_until_moved_then_restored(
        tmp_path: Path) -> None:
    """Today's layout (the sensor's recording in data_dir itself), then the same sensor in a
    rig: refused in one line that says how to move it; moved as it says, the lane restores
    (Allan state, sample index) and the rig's run comes after the moved run."""
    import shlex
    import subprocess

    from avard.core.errors import ConfigError

    single = _run(_config(tmp_path, {"name": "left"}), 12.0, seed=1)
    rig_config = _config(tmp_path, [LEFT, RIGHT])
    root = tmp_path / "rec"
    with pytest.raises(ConfigError) as err:
        _run(rig_config, 12.0, seed=2)
    said = str(err.value)
    assert "\n" not in said and "left" in said and "mkdir" in said
    assert not (root / "left").exists() and not (root / "right").exists()  # nothing started
    move = said[said.index("(mkdir") + 1:said.index("), then")]
    subprocess.run(["sh", "-c", move], check=True)
    assert not list(root.glob("*.avr"))
    rig = _run(rig_config, 12.0, seed=2)
    left = rig.lanes[0]
    # the index continues after the moved recording (its Allan state too where the channels
    # match: a simulated single sensor has simulated DS18B20 channels, a simulated rig not)
    assert left.start_index >= single.acq.next_index
    assert rig.lanes[1].start_index == 0
    from avard.core.io.recording import run_order
    assert run_order(rig.run_id)[0] == run_order(single.run_id)[0] + 1
    assert shlex.split(move)[0] == "mkdir"


def test_the_rigs_run_id_comes_after_a_one_sensor_run_in_data_dir(tmp_path: Path) -> None:
    """A one-sensor recording of a sensor not in the rig stays where it is (nothing to move),
    but run order is data order across both layouts."""
    from avard.core.io.recording import run_order

    single = _run(_config(tmp_path, {"name": "solo"}), 3.0, seed=1)
    rig = _run(_config(tmp_path, [LEFT, RIGHT]), 3.0, seed=2)
    assert run_order(rig.run_id)[0] == run_order(single.run_id)[0] + 1


def test_analyze_says_when_a_rigs_sensors_sit_beside_a_recording(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    from avard.core.io.source import sensor_path

    _run(_config(tmp_path, {"name": "solo"}), 3.0, seed=1)
    _run(_config(tmp_path, [LEFT, RIGHT]), 3.0, seed=2)
    root = tmp_path / "rec"
    with caplog.at_level("WARNING"):
        assert sensor_path(root, None) == root
    assert "left, right" in caplog.text and "--sensor" in caplog.text


# -- 5. an unreadable subdirectory beside a plain recording --------------------------------------

def _lost_and_found_unreadable(monkeypatch: pytest.MonkeyPatch) -> None:
    """lost+found at a mount's root is root-only (the tests may run as root, so say it)."""
    import errno

    real_iterdir = Path.iterdir

    def iterdir(self: Path) -> Any:
        if self.name == "lost+found":
            raise PermissionError(errno.EACCES, "Permission denied", str(self))
        return real_iterdir(self)

    monkeypatch.setattr(Path, "iterdir", iterdir)


def test_an_unreadable_subdirectory_does_not_break_a_plain_recording(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """lost+found at a mount's root is root-only: the service's user reading the recording
    there must not fail on it (r7)."""
    from avard.core.io.source import open_record, rig_sensors, sensor_path

    single = _run(_config(tmp_path, {"name": "solo"}), 3.0, seed=1)
    root = tmp_path / "rec"
    (root / "lost+found").mkdir()
    (root / "left").mkdir()
    _lost_and_found_unreadable(monkeypatch)
    assert sensor_path(root, None) == root
    assert rig_sensors(root) == ()
    info = open_record(root).info
    assert info.recording is not None
    assert info.recording.runs[0].n_samples == single.acq.samples


def test_a_one_sensor_run_after_a_rigs_comes_after_it_in_run_order(tmp_path: Path) -> None:
    """Back from a rig to one sensor in data_dir itself: its run is the next, not the first
    again beside the rig's (r2's third step)."""
    from avard.core.io.recording import run_order

    rig = _run(_config(tmp_path, [LEFT, RIGHT]), 3.0, seed=1)
    single = _run(_config(tmp_path, {"name": "solo"}), 3.0, seed=2)
    assert run_order(single.run_id)[0] == run_order(rig.run_id)[0] + 1


def test_the_next_run_id_skips_a_subdirectory_it_cannot_read(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from avard.daemon.service.recorder import new_run_id

    (tmp_path / "lost+found").mkdir()
    (tmp_path / "left").mkdir()
    (tmp_path / "left" / "n00000004-20260101T000000Z-abcdef_00000000_x.avr").write_bytes(b"")
    _lost_and_found_unreadable(monkeypatch)
    assert new_run_id(tmp_path, 1.7e9).startswith("n00000005-")
