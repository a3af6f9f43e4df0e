"""The composition root: a described rig → its hardware side → the service over it.

This is the one place where daemon/hw (drivers, emulator, the rig) and daemon/service (the
pipeline) meet: :func:`compose` builds the :class:`~avard.daemon.hw.rig.Rig` a
:class:`~avard.daemon.hw.rig.RigSpec` describes, hands the :class:`Service` that rig, and wires
what flows back (the rig's own temperature feed into the service's reading handler). ``avard
run`` and ``avard demo`` come through here, and so do the tests and benchmarks that run the
simulated service (:func:`simulated_service`). hw imports nothing from service (a test holds
the import graph to that).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from typing import Any, cast

from avard.core.errors import ConfigError
from avard.daemon.config_types import Config, as_config
from avard.daemon.hw.emulator import EmulatedAdxl355
from avard.daemon.hw.rig import Rig, RigSpec, build_lanes, build_rig, describe_rig
from avard.daemon.hw.simulation import SimulatedSensors
from avard.daemon.service.rig_service import RigService
from avard.daemon.service.supervisor import Service, ServiceHooks, Supervised


def compose(config: Config, spec: RigSpec | Rig, *, run_id: str | None = None,
            notifier: Any = None, hooks: ServiceHooks | None = None,
            after_tick: Callable[[float], None] | None = None) -> Service:
    """The service over the rig ``spec`` describes (or over a rig already built).
    ``after_tick`` (a test's or benchmark's hook) runs after the rig's own tick. A rig of
    several sensors is :func:`compose_rig`'s."""
    if isinstance(spec, RigSpec) and len(spec.sensors) > 1:
        raise ConfigError(f"{len(spec.sensors)} sensors: compose_rig builds their service")
    rig = spec if isinstance(spec, Rig) else build_rig(spec)
    if after_tick is not None:
        rig = dataclasses.replace(rig, on_tick=_chain(rig.on_tick, after_tick))
    feed = rig.temperature_feed
    if feed is not None:
        # its files (the simulated 1-Wire tree) in the directory the service owns when it
        # records (its lock covers them), removed when it stops: a killed process then leaves
        # nothing in /tmp, and the next start in that directory replaces what it left.
        # Without recording nothing locks that directory, and another service may record
        # there and own its tree: a private temporary folder then (removed at the stop).
        feed.workdir = config.recording.path if config.recording.enabled else None
        rig = dataclasses.replace(rig, closers=(*rig.closers, feed.close))
    svc = Service(config, rig, run_id=run_id, notifier=notifier, hooks=hooks)
    if feed is not None:
        feed.deliver = svc.temperature_reading
    return svc


def compose_rig(config: Config, spec: RigSpec, *, run_id: str | None = None,
                notifier: Any = None, hooks: ServiceHooks | None = None) -> Supervised:
    """The service of ``spec``: a :class:`Service` for one sensor (as :func:`compose`), a
    :class:`RigService` of one lane per sensor for several (docs/architecture.md)."""
    if len(spec.sensors) == 1:
        return compose(config, spec, run_id=run_id, notifier=notifier, hooks=hooks)
    return RigService(config, build_lanes(spec), run_id=run_id, notifier=notifier,
                      hooks=hooks)


def _chain(first: Callable[[float], None] | None,
           then: Callable[[float], None]) -> Callable[[float], None]:
    if first is None:
        return then

    def tick(t_mono: float) -> None:
        first(t_mono)
        then(t_mono)

    return tick


def simulated_service(cfg: Config | Mapping[str, Mapping[str, Any]], preset: str, *,
                      seed: int | None = None, odr_error_ppm: float | None = None,
                      speed: float | None = None,
                      after_tick: Callable[[float], None] | None = None,
                      run_id: str | None = None, notifier: Any = None,
                      hooks: ServiceHooks | None = None
                      ) -> tuple[Service, SimulatedSensors, EmulatedAdxl355]:
    """The service over the simulated rig of ``preset`` (:func:`compose`), with the simulator
    and the emulator for a test to reach into. ``speed``: the virtual clock at most that many
    times real time (None: as fast as it can). The driver and the virtual clock are
    ``svc.sensor`` and ``svc.clock``."""
    config = as_config(cfg)
    spec = describe_rig(config, simulate=preset, seed=seed, odr_error_ppm=odr_error_ppm,
                        speed=speed)
    svc = compose(config, spec, run_id=run_id, notifier=notifier, hooks=hooks,
                  after_tick=after_tick)
    parts = svc.rig.parts
    return (svc, cast(SimulatedSensors, parts["sims"]),
            cast(EmulatedAdxl355, parts["emulator"]))
