"""The configuration, declared once: one frozen dataclass per ``[section]``, each field carrying
its :class:`Key` (unit, range or choices, documentation) as metadata.

Both faces of the configuration come from these classes: :func:`schema` reads the keys off the
fields (their type from the annotation, their default from the field) and daemon/config.py's
``SCHEMA``, which checks a TOML file into a nested dict, is that schema;
:meth:`Config.from_dict` turns the checked dict into these typed objects, so code reads
``config.sensor.odr_hz`` (a float, known to mypy) instead of ``cfg["sensor"]["odr_hz"]`` (Any).
A key is added, renamed or given a new range in one place: here.

Types follow what validation yields: a number key (int or float in TOML) is a ``float``, a
list of strings is a ``tuple[str, ...]`` (frozen all the way down). :meth:`Config.as_dict`
gives the validated dict back (lists again), which the recording header stores.
"""

from __future__ import annotations

import dataclasses
import typing
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar, cast

_T = TypeVar("_T")

#: Output data rates of the ADXL355 (Hz, datasheet FILTER register table).
ODR_CHOICES = (4000.0, 2000.0, 1000.0, 500.0, 250.0, 125.0, 62.5, 31.25, 15.625, 7.8125, 3.90625)


@dataclass(frozen=True)
class Key:
    """One configuration key: its type, default, unit and what is allowed."""

    type: type | tuple[type, ...]
    default: Any
    unit: str = ""
    lo: float | None = None
    hi: float | None = None
    choices: tuple[Any, ...] | None = None
    doc: str = ""
    path: bool = False       # a directory the service writes: restricted to allowed roots

    def allowed(self) -> str:
        if self.choices is not None:
            return "one of " + ", ".join(repr(c) for c in self.choices)
        parts = [self._type_name()]
        if self.lo is not None and self.hi is not None:
            parts.append(f"from {self.lo:g} to {self.hi:g}")
        elif self.lo is not None:
            parts.append(f"at least {self.lo:g}")
        if self.unit:
            parts.append(self.unit)
        return " ".join(parts)

    def _type_name(self) -> str:
        types = self.type if isinstance(self.type, tuple) else (self.type,)
        names = {bool: "a boolean", int: "an integer", float: "a number", str: "a string",
                 list: "a list of strings"}
        return " or ".join(dict.fromkeys(names.get(t, t.__name__) for t in types))


@dataclass(frozen=True)
class _Spec:
    """What a field says about its key beyond type and default (see :func:`setting`)."""

    unit: str = ""
    lo: float | None = None
    hi: float | None = None
    choices: tuple[Any, ...] | None = None
    doc: str = ""
    path: bool = False


def setting(default: _T, unit: str = "", lo: float | None = None, hi: float | None = None, *,
            choices: tuple[Any, ...] | None = None, doc: str = "", path: bool = False) -> _T:
    """A config field: its default, and what the schema checks (unit, range, choices)."""
    spec = _Spec(unit, lo, hi, choices, doc, path)
    return cast(_T, field(default=default, metadata={"key": spec}))


@dataclass(frozen=True)
class SensorConfig:
    """``[sensor]``: how the ADXL355 is wired and run."""

    name: str = setting("adxl355", doc="the sensor's name: stored in the recording header, "
                        "and avard separate's label for it")
    bus: str = setting("spi", choices=("spi", "i2c"), doc="how the ADXL355 is wired")
    spi_bus: int = setting(0, lo=0, hi=7, doc="/dev/spidevB.D: B")
    spi_device: int = setting(0, lo=0, hi=7, doc="/dev/spidevB.D: D (chip select)")
    spi_speed_hz: int = setting(5_000_000, "Hz", 100_000, 10_000_000, doc="SPI clock")
    i2c_bus: int = setting(1, lo=0, hi=31, doc="/dev/i2c-N")
    i2c_address: int = setting(0x1D, choices=(0x1D, 0x53), doc="ASEL low 0x1D, high 0x53")
    range_g: int = setting(2, "g", choices=(2, 4, 8), doc="full scale ±range_g")
    odr_hz: float = setting(125.0, "Hz", choices=ODR_CHOICES, doc="output data rate")
    poll_hz: float = setting(4.0, "Hz", 1.0, 2000.0,
                             doc="least FIFO drain rate; raised to drain the FIFO half full")
    int1_gpio: str = setting("", doc="GPIO of the INT1 pin as CHIP:LINE (e.g. gpiochip0:25): "
                             "wait on the FIFO watermark instead of a timer; empty: timer")
    temp_intercept_lsb: float = setting(
        1885.0, "LSB", 1700.0, 2100.0,
        doc="TEMP reading at 25 °C: 1852 (Rev. 0) or 1885 (later)")
    sync: str = setting("none", choices=("none", "external"),
                        doc="several sensors: 'external' when their SYNC/CLK pins share one "
                        "sample clock (recorded; the time bases are fitted either way)")

    @property
    def bus_number(self) -> int:
        """The bus number of the wiring in use (/dev/spidevB.D's B, or /dev/i2c-N's N)."""
        return self.spi_bus if self.bus == "spi" else self.i2c_bus


@dataclass(frozen=True)
class TemperatureConfig:
    """``[temperature]``: the DS18B20s and the chip's own sensor."""

    ds18b20: bool = setting(True, doc="read DS18B20 sensors on the 1-Wire bus")
    ids: tuple[str, ...] = setting((), doc="DS18B20 IDs to use ('28-...'); empty: all found")
    required: bool = setting(False, doc="refuse to start when a listed DS18B20 is missing")
    interval_s: float = setting(1.0, "s", 0.75, 3600.0, doc="DS18B20 read interval")
    chip_interval_s: float = setting(1.0, "s", 0.01, 3600.0,
                                     doc="ADXL355 on-chip temperature read interval")


@dataclass(frozen=True)
class AllanConfig:
    """``[allan]``: the streaming accumulators, snapshots and checkpoints."""

    overlap: int = setting(8, choices=(1, 2, 4, 8, 16, 32, 64),
                           doc="differences kept per octave (stride m/overlap): a power of two")
    snapshot_interval_s: float = setting(10.0, "s", 0.1, 86400.0,
                                         doc="publish and record an Allan snapshot this often")
    checkpoint_interval_s: float = setting(60.0, "s", 1.0, 86400.0,
                                           doc="save the accumulators for restart this often")
    restore: bool = setting(True, doc="restore the accumulators from the last checkpoint")


@dataclass(frozen=True)
class RecordingConfig:
    """``[recording]``: the segment files."""

    enabled: bool = setting(True, doc="write the recording")
    data_dir: str = setting("/var/lib/avard", path=True, doc="segment files go here")
    segment_s: float = setting(3600.0, "s", 10.0, 86400.0, doc="start a new segment this often")
    fsync_interval_s: float = setting(5.0, "s", 0.05, 3600.0,
                                      doc="fsync this often: a power cut loses at most this much")
    block_s: float = setting(1.0, "s", 0.01, 10.0, doc="raw samples per record, in seconds")
    retention_days: float = setting(0.0, "days", 0.0, 36500.0,
                                    doc="delete segments older than this; 0 keeps all")
    retention_max_bytes: int = setting(0, "bytes", 0, None,
                                       doc="delete oldest segments above this total; 0 = no "
                                       "limit")
    min_free_bytes: int = setting(64 * 1024 * 1024, "bytes", 0, None,
                                  doc="pause writing (disk full) below this much free space")

    @property
    def path(self) -> Path:
        return Path(self.data_dir)


@dataclass(frozen=True)
class PublishConfig:
    """``[publish]``: the ZeroMQ PUB and request sockets."""

    enabled: bool = setting(True, doc="publish over ZeroMQ")
    endpoint: str = setting("tcp://127.0.0.1:5555", doc="PUB socket (raw, temp, avar, ...)")
    request_endpoint: str = setting("tcp://127.0.0.1:5556",
                                    doc="request socket (snapshot, status, recent)")
    allow_remote: bool = setting(False, doc="needed to bind anything but loopback")
    hwm: int = setting(10000, "messages", 10, 10_000_000, doc="PUB send high-water mark")
    status_interval_s: float = setting(5.0, "s", 0.1, 3600.0, doc="publish status this often")
    recent_max_s: float = setting(10.0, "s", 0.0, 600.0, doc="longest 'recent' reply")


@dataclass(frozen=True)
class CurveConfig:
    """``[curve]``: CURVE encryption and authentication of both sockets."""

    enabled: bool = setting(False, doc="CURVE-encrypt and authenticate both sockets")
    server_secret_key_file: str = setting("", doc="server secret key (from `avard keys`)")
    authorized_keys_dir: str = setting("", doc="directory of authorised client public keys")


@dataclass(frozen=True)
class ServiceConfig:
    """``[service]``: the ring buffer and the status log."""

    ring_s: float = setting(30.0, "s", 1.0, 3600.0, doc="ring buffer length in seconds")
    status_log_interval_s: float = setting(60.0, "s", 1.0, 86400.0,
                                           doc="log a status line this often")


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
    #: every ``[[sensor]]`` entry in order (``sensor`` is the first); () for a ``[sensor]`` table
    sensors: tuple[SensorConfig, ...] = ()

    @property
    def rig_sensors(self) -> tuple[SensorConfig, ...]:
        """The sensors of the rig: the ``[[sensor]]`` entries, or the one ``[sensor]``."""
        return self.sensors or (self.sensor,)

    def one_sensor(self, name: str | None) -> Config:
        """This config with only the sensor ``name`` (None: as it is), for what reads one
        sensor (``avard probe --sensor NAME``); ConfigError naming the sensors otherwise."""
        if name is None:
            return self
        for s in self.rig_sensors:
            if s.name == name:
                return dataclasses.replace(self, sensor=s, sensors=())
        from avard.core.errors import ConfigError

        raise ConfigError(f"--sensor {name}: no such sensor in the config; its sensors are "
                          f"{', '.join(s.name for s in self.rig_sensors)}")

    @classmethod
    def from_dict(cls, cfg: Mapping[str, Any]) -> Config:
        """The typed form of a dict checked by ``config.validate_config``/``load_config``
        (every section and key present; an unchecked dict is not this function's input)."""
        sections: dict[str, Any] = {name: _section(section_cls, cfg[name])
                                    for name, section_cls in SECTIONS.items()}
        sections["sensors"] = tuple(_section(SensorConfig, t) for t in cfg.get("sensors", ()))
        return cls(**sections)

    def as_dict(self) -> dict[str, Any]:
        """The validated nested dict this was built from (tuples as lists, as TOML has them):
        what a recording header stores as its ``config``."""
        out: dict[str, Any] = {name: _table(getattr(self, name)) for name in SECTIONS}
        if self.sensors:
            out["sensors"] = [_table(s) for s in self.sensors]
        return out


def _section(section_cls: type[_T], table: Mapping[str, Any]) -> _T:
    return section_cls(**{
        k.name: tuple(table[k.name]) if isinstance(table[k.name], list) else table[k.name]
        for k in dataclasses.fields(section_cls)})  # type: ignore[arg-type]


def _table(section: Any) -> dict[str, Any]:
    return {k: list(v) if isinstance(v, tuple) else v
            for k, v in dataclasses.asdict(section).items()}


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


#: The schema key type of each field annotation: a number accepts TOML's int and float.
_KEY_TYPES: dict[Any, type | tuple[type, ...]] = {
    int: int, str: str, bool: bool, float: (int, float), tuple[str, ...]: list}


def schema() -> dict[str, dict[str, Key]]:
    """``{section: {key: Key}}`` read off the dataclasses: what daemon/config.py checks."""
    out: dict[str, dict[str, Key]] = {}
    for sec, cls in SECTIONS.items():
        hints = typing.get_type_hints(cls)
        keys: dict[str, Key] = {}
        for f in dataclasses.fields(cls):
            spec: _Spec = f.metadata["key"]
            default = list(f.default) if isinstance(f.default, tuple) else f.default
            keys[f.name] = Key(_KEY_TYPES[hints[f.name]], default, spec.unit, spec.lo, spec.hi,
                               spec.choices, spec.doc, spec.path)
        out[sec] = keys
    return out
