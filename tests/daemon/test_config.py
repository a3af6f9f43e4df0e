"""The config schema: defaults, the shipped file, refusals that name key, value and allowed."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import pytest
from avard.core.errors import ConfigError
from avard.daemon.cli import main
from avard.daemon.config import (
    SCHEMA,
    default_config,
    effective_poll_hz,
    load_config,
    validate_config,
)

SHIPPED = Path(__file__).resolve().parents[2] / "config" / "avard.toml"


def test_shipped_file_equals_defaults_and_comments_every_key() -> None:
    assert load_config(SHIPPED) == default_config()
    text = SHIPPED.read_text()
    raw = tomllib.loads(text)
    assert set(raw) == set(SCHEMA)
    lines = text.splitlines()
    for sec, keys in SCHEMA.items():
        assert set(raw[sec]) == set(keys), sec
        for name in keys:
            at = next(i for i, ln in enumerate(lines) if re.match(rf"{name}\s*=", ln))
            comment = []
            j = at - 1
            while j >= 0 and lines[j].startswith("#"):
                comment.insert(0, lines[j])
                j -= 1
            joined = " ".join(comment)
            assert "Default" in joined, f"{sec}.{name} comment lacks its default"
            if keys[name].unit and keys[name].unit != "g":
                assert keys[name].unit.split()[0] in joined, f"{sec}.{name} lacks its unit"


@pytest.mark.parametrize("raw, pattern", [
    ({"sensor": {"odr_hz": 100}}, r"sensor\.odr_hz = 100.*out of range.*125\.0"),
    ({"sensor": {"odr": 125}}, r"sensor\.odr: unknown key"),
    ({"sensr": {}}, r"\[sensr\]: unknown section"),
    ({"sensor": {"range_g": "2"}}, r"sensor\.range_g = '2': wrong type"),
    ({"recording": {"enabled": 1}}, r"recording\.enabled = 1: wrong type.*boolean"),
    ({"allan": {"overlap": True}}, r"allan\.overlap = True: wrong type"),
    ({"recording": {"fsync_interval_s": 0}}, r"fsync_interval_s = 0.*from 0\.05 to 3600 s"),
    ({"recording": {"data_dir": "/etc/avard"}}, r"data_dir = '/etc/avard': not under"),
    ({"publish": {"endpoint": "tcp://0.0.0.0:5555"}}, r"allow_remote = true"),
    ({"publish": {"endpoint": "udp://x"}}, r"ZeroMQ endpoint"),
    ({"temperature": {"ids": [1, 2]}}, r"temperature\.ids = \[1, 2\]"),
    ({"sensor": {"name": "left plate"}}, r"sensor\.name = 'left plate': use 1 to 32"),
])
def test_bad_values_are_refused_with_key_value_and_allowed(raw: dict, pattern: str) -> None:
    with pytest.raises(ConfigError, match=pattern):
        validate_config(raw)


def test_all_problems_are_reported_at_once() -> None:
    with pytest.raises(ConfigError) as err:
        validate_config({"sensor": {"odr_hz": 1, "bogus": 1}, "allan": {"overlap": 0}})
    msg = str(err.value)
    assert "sensor.odr_hz" in msg and "sensor.bogus" in msg and "allan.overlap" in msg


def test_remote_bind_allowed_when_explicit_and_overrides_apply(tmp_path: Path) -> None:
    cfg = validate_config({"publish": {"endpoint": "tcp://0.0.0.0:6000", "allow_remote": True}})
    assert cfg["publish"]["endpoint"] == "tcp://0.0.0.0:6000"
    cfg = load_config(None, **{"recording.data_dir": str(tmp_path)})
    assert cfg["recording"]["data_dir"] == str(tmp_path.resolve())
    assert cfg["sensor"]["odr_hz"] == 125.0


def test_poll_rate_rises_with_odr() -> None:
    cfg = validate_config({"sensor": {"odr_hz": 4000, "poll_hz": 10}})
    assert effective_poll_hz(cfg) == pytest.approx(250.0)      # FIFO half full: 16 / 4000 s
    assert effective_poll_hz(default_config()) == pytest.approx(125.0 / 16)


def test_check_config_command(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # the shipped config records into /var/lib/avard, which systemd makes: by hand (as `avard
    # run` would) with the data folder somewhere this user may write
    assert main(["check-config", str(SHIPPED), "--data-dir", str(tmp_path / "rec")]) == 0
    assert "valid" in capsys.readouterr().out
    bad = tmp_path / "bad.toml"
    bad.write_text("[sensor]\nodr_hz = 100\n")
    assert main(["check-config", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "sensor.odr_hz = 100" in err and "allowed" in err
    broken = tmp_path / "broken.toml"
    broken.write_text("[sensor\n")
    assert main(["check-config", str(broken)]) == 2
    assert "not valid TOML" in capsys.readouterr().err


def test_temperature_intercept_is_configurable_and_bounded() -> None:
    cfg = validate_config({"sensor": {"temp_intercept_lsb": 1852}})
    assert cfg["sensor"]["temp_intercept_lsb"] == 1852
    with pytest.raises(ConfigError, match="temp_intercept_lsb"):
        validate_config({"sensor": {"temp_intercept_lsb": 9000}})
