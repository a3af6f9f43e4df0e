"""``/metrics``: the run in the Prometheus text exposition format (version 0.0.4).

So a lab that already runs Prometheus and Grafana can scrape ``avard web`` like any other
exporter. SI base units in every metric name (seconds, hertz, celsius, bytes, m/s²).
Counters are the service's own counts (they restart with the service's run) or this
server's (they restart with it); Prometheus' ``rate()``/``increase()`` handle both resets.
"""

from __future__ import annotations

import math
import time
from typing import Any

from avard.core.allan.streaming import AllanSnapshot
from avard.daemon.web.state import RunState

CONTENT_TYPE = "text/plain; version=0.0.4; charset=utf-8"
ACCEL_AXES = ("x", "y", "z")


def _label(value: Any) -> str:
    """A label value with \\, " and newline escaped as the format requires."""
    return str(value).replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n")


class _Writer:
    def __init__(self) -> None:
        self.lines: list[str] = []

    def metric(self, name: str, kind: str, help_text: str,
               samples: list[tuple[dict[str, Any], Any]]) -> None:
        samples = [(lab, float(v)) for lab, v in samples
                   if isinstance(v, int | float) and math.isfinite(v)]
        if not samples:
            return
        self.lines.append(f"# HELP {name} {help_text}")
        self.lines.append(f"# TYPE {name} {kind}")
        for labels, value in samples:
            lab = ",".join(f'{k}="{_label(v)}"' for k, v in labels.items())
            self.lines.append(f"{name}{{{lab}}} {value!r}" if lab else f"{name} {value!r}")

    def text(self) -> str:
        return "\n".join(self.lines) + "\n"


def metrics_text(state: RunState) -> str:
    """The exposition text (call with ``state.lock`` held)."""
    st, stats = state.status, state.stats
    run = {"run": st.get("run") or (state.runs[-1] if state.runs else "")}
    w = _Writer()
    w.metric("avard_samples_total", "counter",
             "Samples acquired by the service in its current run.", [(run, st.get("samples"))])
    w.metric("avard_web_samples_received_total", "counter",
             "Samples received by this avard web server.", [({}, stats.samples_received)])
    w.metric("avard_web_samples_lost_total", "counter",
             "Samples lost between the service and this server (transport).",
             [({}, stats.samples_lost)])
    w.metric("avard_web_messages_lost_total", "counter",
             "Messages lost between the service and this server (sequence holes).",
             [({}, stats.messages_lost)])
    reasons = sorted(state.gaps_by_reason)
    w.metric("avard_gaps_total", "counter", "Gap records seen by this server, by reason.",
             [({"reason": r}, state.gaps_by_reason[r]) for r in reasons])
    w.metric("avard_gap_samples_total", "counter",
             "Samples missing in gaps seen by this server, by reason.",
             [({"reason": r}, state.gap_samples_by_reason[r]) for r in reasons])
    w.metric("avard_overruns_total", "counter", "FIFO overruns in the service's current run.",
             [(run, st.get("overruns"))])
    w.metric("avard_bus_errors_total", "counter",
             "SPI/I2C bus errors in the service's current run.", [(run, st.get("bus_errors"))])
    w.metric("avard_rate_hertz", "gauge", "The service's fitted output data rate, Hz.",
             [({}, st.get("rate_hz"))])
    ppm = state.rate_ppm
    w.metric("avard_rate_offset_ppm", "gauge",
             "Fitted output data rate relative to nominal, parts per million.",
             [({}, ppm)] if ppm is not None else [])
    w.metric("avard_temperature_celsius", "gauge", "Latest temperature reading, degrees C.",
             [({"sensor": k}, v) for k, v in sorted(state.latest_temps.items())
              if v is not None])
    disk = st.get("disk") if isinstance(st.get("disk"), dict) else {}
    free = disk.get("free_bytes") if isinstance(disk, dict) else None
    w.metric("avard_disk_free_bytes", "gauge", "Free space where the service records, bytes.",
             [({}, free)] if isinstance(free, int | float) and free >= 0 else [])
    w.metric("avard_subscribers", "gauge", "Subscribers of the service's PUB socket.",
             [({}, st.get("subscribers"))])
    w.metric("avard_service_uptime_seconds", "gauge",
             "Time since the service's current run started, s.", [({}, st.get("sim_time_s"))])
    w.metric("avard_web_uptime_seconds", "gauge", "Time since this server started, s.",
             [({}, time.time() - state.started)])
    snap = state.snapshot
    if snap is not None:
        w.metric("avard_allan_samples", "gauge", "Samples in the latest Allan snapshot.",
                 [({}, snap.n_samples)])
        # one unit per metric name: accelerations and temperatures apart
        ci = f"{100 * snap.data.ci:.1f} %"
        for base, accel, unit, what in (
                ("avard_adev_meters_per_second_squared", True, "m/s^2", "axis"),
                ("avard_temperature_adev_celsius", False, "degC", "sensor")):
            for suffix, key, help_text in (
                    ("", "avar", f"Allan deviation at tau, {unit}."),
                    ("_lower", "lo", f"Lower end of the {ci} ADEV interval at tau, {unit}."),
                    ("_upper", "hi", f"Upper end of the {ci} ADEV interval at tau, {unit}.")):
                w.metric(base + suffix, "gauge", help_text,
                         _adev_samples(snap.data, key, accel=accel, label=what))
    return w.text()


def _adev_samples(d: AllanSnapshot, key: str, *, accel: bool,
                  label: str) -> list[tuple[dict[str, Any], float]]:
    """√(value) at every τ of the acceleration axes (``accel``) or of the other channels."""
    tau = d.tau
    values = getattr(d, key)
    names = list(d.names)
    out: list[tuple[dict[str, Any], float]] = []
    if values.ndim != 2 or values.shape[0] != len(tau):
        return out
    for c, name in enumerate(names[: values.shape[1]]):
        if (name in ACCEL_AXES) != accel:
            continue
        for k, t in enumerate(tau):
            v = values[k, c]
            if math.isfinite(v) and v >= 0:
                out.append(({label: name, "tau_seconds": f"{t:.6g}"}, math.sqrt(v)))
    return out
