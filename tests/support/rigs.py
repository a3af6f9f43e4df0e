"""A :class:`~avard.daemon.hw.rig.Rig` from parts a test built itself (a driver whose drain
it wraps, a DS18B20 bank over a fake sysfs tree), for ``daemon.compose.compose``."""

from __future__ import annotations

from typing import Any

from avard.daemon.config_types import Config
from avard.daemon.hw.rig import ClockSpec, Rig, RigSpec, SensorSpec


def rig_from_parts(config: Config, dev: Any, clock: Any, *, simulate: str | None = None,
                   speed: float | None = None, sims: Any = None, bank: Any = None) -> Rig:
    """The rig of ``dev`` on ``clock``; ``sims`` (a SimulatedSensors) adds its DS18B20 feed
    and ticks, ``bank`` a Ds18b20Bank."""
    spec = RigSpec((SensorSpec.from_config(config.sensor),),
                   ClockSpec("virtual" if simulate else "system", simulate, speed=speed),
                   config.temperature)
    return Rig(spec, dev, clock, {"device": "ADXL355 (test)"}, temperature_bank=bank,
               extra_temperature_names=tuple(sims.names) if sims is not None else (),
               on_tick=sims.on_tick if sims is not None else None, temperature_feed=sims)
