"""daemon/config_types.py against the schema of daemon/config.py: one source of truth."""

from __future__ import annotations

import dataclasses
import typing
from pathlib import Path

import pytest
from avard.daemon import config_types
from avard.daemon.config import SCHEMA, default_config, load_config, validate_config
from avard.daemon.config_types import SECTIONS, Config, as_config

#: The Python type validation yields for each schema key type.
_TYPE_OF = {int: int, str: str, bool: bool, (int, float): float, list: tuple[str, ...]}


def test_every_schema_key_is_a_field_with_its_default_and_type_and_vice_versa() -> None:
    assert list(SECTIONS) == list(SCHEMA)
    # every section, then the [[sensor]] entries (each checked with [sensor]'s keys)
    assert [f.name for f in dataclasses.fields(Config)] == [*SCHEMA, "sensors"]
    for sec, keys in SCHEMA.items():
        cls = SECTIONS[sec]
        assert dataclasses.is_dataclass(cls) and cls.__dataclass_params__.frozen  # type: ignore[attr-defined]
        hints = typing.get_type_hints(cls, vars(config_types))
        fields = {f.name: f for f in dataclasses.fields(cls)}
        assert list(fields) == list(keys), sec        # same keys, same order, none extra
        for name, key in keys.items():
            assert hints[name] == _TYPE_OF[key.type], f"{sec}.{name}"
            default = fields[name].default
            want = tuple(key.default) if isinstance(key.default, list) else key.default
            if _TYPE_OF[key.type] is float:
                want = float(want)                 # as validation stores a number
            assert default == want and type(default) is type(want), f"{sec}.{name}"


def test_numbers_given_as_integers_come_out_as_floats() -> None:
    """A TOML ``odr_hz = 1000`` is validated to a float; the typed field holds that float."""
    c = Config.from_dict(validate_config({"sensor": {"odr_hz": 1000, "poll_hz": 10}}))
    assert c.sensor.odr_hz == 1000.0 and type(c.sensor.odr_hz) is float
    assert type(c.sensor.poll_hz) is float and type(c.sensor.range_g) is int


def test_defaults_agree_and_the_dict_round_trips(tmp_path: Path) -> None:
    assert Config.from_dict(default_config()) == Config()
    assert Config().as_dict() == default_config()
    cfg = load_config(None, **{"recording.data_dir": str(tmp_path), "temperature.ids":
                               ["28-0316a2797cff"], "sensor.odr_hz": 1000,
                               "publish.enabled": False})
    c = Config.from_dict(cfg)
    assert c.recording.data_dir == str(tmp_path.resolve()) and not c.publish.enabled
    assert c.temperature.ids == ("28-0316a2797cff",)
    assert c.as_dict() == cfg                     # what the header stores is unchanged
    assert as_config(cfg) == c and as_config(c) is c
    assert config_types.load(None, **{"recording.data_dir": str(tmp_path),
                                      "temperature.ids": ["28-0316a2797cff"],
                                      "sensor.odr_hz": 1000, "publish.enabled": False}) == c


def test_sections_are_frozen() -> None:
    c = Config()
    with pytest.raises(dataclasses.FrozenInstanceError):
        c.sensor.odr_hz = 4000.0  # type: ignore[misc]
    with pytest.raises(dataclasses.FrozenInstanceError):
        c.sensor = c.sensor       # type: ignore[misc]
    assert hash(c) == hash(Config())   # frozen all the way down: ids is a tuple
