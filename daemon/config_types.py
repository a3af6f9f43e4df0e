"""The checked configuration as typed, frozen dataclasses: one per ``[section]`` of the schema.

daemon/config.py stays the one source of truth for what a key may hold (type, default, unit,
range, choices) and checks a TOML file into a nested dict; :meth:`Config.from_dict` turns that
checked dict into these objects, so code reads ``config.sensor.odr_hz`` (a float, known to
mypy) instead of ``cfg["sensor"]["odr_hz"]`` (Any). The classes are written out rather than
generated from the schema so the type checker sees their fields;
tests/daemon/test_config_types.py holds them equal to the schema: every schema key is a field
with the same default and the matching type, and every field is a schema key.

Types follow what validation yields: a number key (int or float in TOML) is a ``float``, a
list of strings is a ``tuple[str, ...]`` (frozen all the way down). :meth:`Config.as_dict`
gives the validated dict back (lists again), which the recording header stores.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any


@dataclass(frozen=True)
class SensorConfig:
    """``[sensor]``: how the ADXL355 is wired and run."""

    bus: str = "spi"
    spi_bus: int = 0
    spi_device: int = 0
    spi_speed_hz: int = 5_000_000
    i2c_bus: int = 1
    i2c_address: int = 0x1D
    range_g: int = 2
    odr_hz: float = 125.0
    poll_hz: float = 4.0
    int1_gpio: str = ""
    temp_intercept_lsb: float = 1885.0

    @property
    def bus_number(self) -> int:
        """The bus number of the wiring in use (/dev/spidevB.D's B, or /dev/i2c-N's N)."""
        return self.spi_bus if self.bus == "spi" else self.i2c_bus


@dataclass(frozen=True)
class TemperatureConfig:
    """``[temperature]``: the DS18B20s and the chip's own sensor."""

    ds18b20: bool = True
    ids: tuple[str, ...] = ()
    required: bool = False
    interval_s: float = 1.0
    chip_interval_s: float = 1.0


@dataclass(frozen=True)
class AllanConfig:
    """``[allan]``: the streaming accumulators, snapshots and checkpoints."""

    overlap: int = 8
    snapshot_interval_s: float = 10.0
    checkpoint_interval_s: float = 60.0
    restore: bool = True


@dataclass(frozen=True)
class RecordingConfig:
    """``[recording]``: the segment files."""

    enabled: bool = True
    data_dir: str = "/var/lib/avard"
    segment_s: float = 3600.0
    fsync_interval_s: float = 5.0
    block_s: float = 1.0
    retention_days: float = 0.0
    retention_max_bytes: int = 0
    min_free_bytes: int = 64 * 1024 * 1024

    @property
    def path(self) -> Path:
        return Path(self.data_dir)


@dataclass(frozen=True)
class PublishConfig:
    """``[publish]``: the ZeroMQ PUB and request sockets."""

    enabled: bool = True
    endpoint: str = "tcp://127.0.0.1:5555"
    request_endpoint: str = "tcp://127.0.0.1:5556"
    allow_remote: bool = False
    hwm: int = 10000
    status_interval_s: float = 5.0
    recent_max_s: float = 10.0


@dataclass(frozen=True)
class CurveConfig:
    """``[curve]``: CURVE encryption and authentication of both sockets."""

    enabled: bool = False
    server_secret_key_file: str = ""
    authorized_keys_dir: str = ""


@dataclass(frozen=True)
class ServiceConfig:
    """``[service]``: the ring buffer and the status log."""

    ring_s: float = 30.0
    status_log_interval_s: float = 60.0


@dataclass(frozen=True)
class Config:
    """The whole checked configuration, one typed section per ``[section]``."""

    sensor: SensorConfig = field(default_factory=SensorConfig)
    temperature: TemperatureConfig = field(default_factory=TemperatureConfig)
    allan: AllanConfig = field(default_factory=AllanConfig)
    recording: RecordingConfig = field(default_factory=RecordingConfig)
    publish: PublishConfig = field(default_factory=PublishConfig)
    curve: CurveConfig = field(default_factory=CurveConfig)
    service: ServiceConfig = field(default_factory=ServiceConfig)

    @classmethod
    def from_dict(cls, cfg: Mapping[str, Mapping[str, Any]]) -> Config:
        """The typed form of a dict checked by ``config.validate_config``/``load_config``
        (every section and key present; an unchecked dict is not this function's input)."""
        sections: dict[str, Any] = {}
        for f in dataclasses.fields(cls):
            section_cls = SECTIONS[f.name]
            table = cfg[f.name]
            sections[f.name] = section_cls(**{
                k.name: tuple(table[k.name]) if isinstance(table[k.name], list) else table[k.name]
                for k in dataclasses.fields(section_cls)})
        return cls(**sections)

    def as_dict(self) -> dict[str, dict[str, Any]]:
        """The validated nested dict this was built from (tuples as lists, as TOML has them):
        what a recording header stores as its ``config``."""
        return {f.name: {k: list(v) if isinstance(v, tuple) else v
                         for k, v in dataclasses.asdict(getattr(self, f.name)).items()}
                for f in dataclasses.fields(self)}


#: The dataclass of each ``[section]``, in schema order.
SECTIONS: dict[str, type] = {
    "sensor": SensorConfig, "temperature": TemperatureConfig, "allan": AllanConfig,
    "recording": RecordingConfig, "publish": PublishConfig, "curve": CurveConfig,
    "service": ServiceConfig,
}


def as_config(cfg: Config | Mapping[str, Mapping[str, Any]]) -> Config:
    """``cfg`` as a :class:`Config`: for entry points that still take the checked dict
    (tests and benchmarks build the service from ``load_config``'s output)."""
    return cfg if isinstance(cfg, Config) else Config.from_dict(cfg)


def load(path: str | Path | None, **overrides: Any) -> Config:
    """``config.load_config`` (the one validation), typed."""
    from avard.daemon.config import load_config

    return Config.from_dict(load_config(path, **overrides))
