"""Check the sensor hardware before running the service.

Opens the sensor through the rig factory (daemon/hw/rig.py: the bus of ``[sensor]``, SPI or I2C;
or with ``$AVARD_BACKEND=simulate:PRESET`` the simulated rig), then by the rig's one start-up
sequence probes the ADXL355 (explaining a wrong answer), resets it, optionally runs the
self-test (at ±8 g, where gravity plus the deflection cannot clip) and configures it; then
acquires for ``--seconds`` and reports the real output rate fitted against CLOCK_MONOTONIC (Hz
and ppm off nominal, 1σ), the mean acceleration per axis (m/s², ± standard error of the mean),
the chip temperature (°C, uncalibrated) and every DS18B20 on the 1-Wire bus. ``--emulate`` does
the same against the register-level emulator holding 1 g on Z (no 1-Wire bus: the DS18B20s are
then skipped, and said to be, as with a simulated rig). The last lines say what was checked and
what was skipped. Exit status 0 when everything looked right, 1 when a check failed, 2 when the
hardware could not be used at all.
"""

from __future__ import annotations

import argparse
import math
import sys
from typing import TYPE_CHECKING, Any

import numpy as np
from avard.core.errors import ConfigError

if TYPE_CHECKING:
    from avard.daemon.hw.adxl355 import DeviceInfo

NAME = "probe"
HELP = "check the ADXL355 (IDs, self-test, real ODR, 1 g) and the DS18B20 sensors"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config", metavar="FILE", help="TOML configuration ([sensor] bus "
                        "settings, odr_hz, range_g); default: the built-in defaults")
    parser.add_argument("--sensor", metavar="NAME", default=None,
                        help="with several [[sensor]] entries: the one to probe")
    parser.add_argument("--seconds", type=float, default=20.0,
                        help="acquisition time for the rate fit, s (default 20: about ±25 ppm "
                             "at 125 Hz; the uncertainty falls as seconds^-1.5)")
    parser.add_argument("--self-test", dest="self_test", action="store_true", default=True,
                        help="run the electrostatic self-test at ±8 g (the default)")
    parser.add_argument("--no-self-test", dest="self_test", action="store_false",
                        help="skip the self-test (e.g. when the sensor cannot be kept still)")
    parser.add_argument("--no-ds18b20", action="store_true", help="skip the 1-Wire sensors")
    parser.add_argument("--emulate", action="store_true", help="no hardware: use the "
                        "register-level emulator (1 g on Z)")
    parser.add_argument("--ppm", type=float, default=2500.0,
                        help="with --emulate: the emulated oscillator error, ppm (default "
                             "2500)")


def run(args: argparse.Namespace) -> int:
    from avard.daemon.config_types import load
    from avard.daemon.hw.rig import bring_up, open_sensor
    from avard.daemon.hw.timebase import TimeBase

    if not 0.5 <= args.seconds <= 3600:
        raise ConfigError(f"--seconds {args.seconds}: use 0.5 to 3600 s")
    if not abs(args.ppm) <= 1e5:   # the datasheet's oscillator is within a few 1000 ppm
        raise ConfigError(f"--ppm {args.ppm:g}: an emulated oscillator error must be within "
                          "±100000 ppm (±10 %)")
    config = load(args.config).one_sensor(args.sensor)
    if len(config.rig_sensors) > 1:
        raise ConfigError(f"{args.config}: {len(config.rig_sensors)} sensors; probe one at a "
                          f"time with --sensor NAME "
                          f"({', '.join(x.name for x in config.rig_sensors)})")
    s = config.sensor
    out = sys.stdout
    ok = True
    checked: list[str] = []
    skipped: list[str] = []
    # the backend of daemon/hw/rig.py: --emulate is the still emulated sensor (1 g on Z, --ppm),
    # else $AVARD_BACKEND's simulated rig, else the hardware
    opened = open_sensor(config, still_odr_error_ppm=args.ppm if args.emulate else None)
    dev, clock = opened.driver, opened.clock

    def found(info: DeviceInfo) -> None:
        checked.append("IDs")
        out.write(f"{info.name} found: DEVID_AD 0x{info.devid_ad:02X}, DEVID_MST "
                  f"0x{info.devid_mst:02X}, PARTID 0x{info.partid:02X}, REVID {info.revid}\n")

    try:
        up = bring_up(dev, s, self_test=args.self_test, found=found)
        odr, rng = s.odr_hz, s.range_g
        if up.self_test is not None:
            st = up.self_test
            g = 9.80665
            deltas = ", ".join(f"{a} {d:.3f} g ({d * g:.2f} m/s²)"
                               for a, d in zip("XYZ", st.delta_g, strict=True))
            out.write(f"self-test {'passed' if st.passed else 'FAILED'}: {deltas}\n")
            ok &= st.passed
            checked.append("self-test")
        else:
            skipped.append("self-test (--no-self-test)")
        tb = TimeBase(odr, group_delay_samples=dev.group_delay_samples,
                      min_span_s=min(1.0, args.seconds / 2))
        poll_s = min(0.25 * 32 / odr, 0.1)  # four polls per FIFO fill
        # Polls at a fixed period alias against the ODR: the newest sample's age at each
        # drain then drifts slowly (a sawtooth), not at random, and biases the rate fit by
        # several of its own σ (the emulator's clock is exact, so this is worst there).
        # Dithered intervals make that age independent from drain to drain.
        dither = np.random.default_rng(355)
        t_end = clock.monotonic() + args.seconds
        blocks, gaps = [], 0
        while clock.monotonic() < t_end:
            clock.sleep(poll_s * dither.uniform(0.5, 1.5))
            d = dev.drain()
            gaps += int(d.overrun)
            tb.add_drain(d)
            if d.n_sets:
                blocks.append(d.counts)
        temp_c = dev.read_temperature_c()
        dev.standby()
        a = np.concatenate(blocks) * dev.scale_mps2 if blocks else np.empty((0, 3))
        r = tb.rate()
        out.write(f"{len(a)} samples in {args.seconds:g} s at nominal {odr:g} Hz, "
                  f"±{rng} g; gaps: {gaps}\n")
        out.write(f"real output rate {r.odr_hz:.4f} ± {r.odr_u_hz:.4f} Hz "
                  f"({r.ppm:+.0f} ± {r.ppm_u:.0f} ppm off nominal, 1σ)\n")
        checked.append("output rate")
        if not math.isfinite(r.ppm_u) or r.ppm_u > RATE_U_PPM:
            out.write(f"  {args.seconds:g} s is too short to measure the rate to ±"
                      f"{RATE_U_PPM:g} ppm; {_seconds_for(args.seconds, r.ppm_u)}\n")
        if len(a) > 1:
            mean = a.mean(axis=0)
            sem = a.std(axis=0, ddof=1) / math.sqrt(len(a))
            out.write("mean acceleration (m/s², ± standard error): " + ", ".join(
                f"{ax} {m:+.5f} ± {e:.5f}" for ax, m, e in zip("XYZ", mean, sem, strict=True))
                + f"; |a| = {np.linalg.norm(mean):.4f} m/s²\n")
            checked.append("1 g")
            if not 0.9 * 9.80665 < np.linalg.norm(mean) < 1.1 * 9.80665:
                out.write("  |a| is not 1 g: the sensor is moving, or its sensitivity or "
                          "wiring is wrong\n")
                ok = False
        else:
            out.write("no samples arrived\n")
            ok = False
        out.write(f"chip temperature {temp_c:.2f} °C (uncalibrated intercept "
                  f"{dev.temp_intercept_lsb:g} LSB)\n")
        checked.append("chip temperature")
        ok &= gaps == 0
    finally:
        dev.close()
    if args.emulate:
        skipped.append("DS18B20s (--emulate has no 1-Wire bus)")
    elif opened.emulated:
        skipped.append(f"DS18B20s (the simulated rig {opened.simulate} has no real 1-Wire bus)")
    elif args.no_ds18b20:
        skipped.append("DS18B20s (--no-ds18b20)")
    else:
        ok &= _ds18b20(out)
        checked.append("DS18B20s")
    out.write(f"checked: {', '.join(checked)}\n")
    if skipped:
        out.write(f"skipped: {'; '.join(skipped)}\n")
    out.write("all checks passed\n" if ok else "some checks FAILED\n")
    return 0 if ok else 1


#: A rate measured less precisely than this (1σ, ppm) is said to be too short to tell.
RATE_U_PPM = 50.0


def _seconds_for(seconds: float, u_ppm: float) -> str:
    """The advice for a too-uncertain rate: the duration that reaches RATE_U_PPM, from the
    fit's scaling (slope uncertainty ∝ span^-1.5 for evenly spread drain stamps)."""
    if not math.isfinite(u_ppm):
        return "run longer (--seconds)"
    need = seconds * (u_ppm / RATE_U_PPM) ** (2.0 / 3.0)
    return f"run --seconds {math.ceil(need / 5) * 5:g} or more"


def _ds18b20(out: Any) -> bool:
    from avard.daemon.hw import ds18b20

    ids = ds18b20.discover()
    if not ids:
        out.write("no DS18B20 on the 1-Wire bus\n")
        return True
    good = True
    for rd in ds18b20.Ds18b20Bank(ids).read_all():
        if rd.ok:
            out.write(f"DS18B20 28-{rd.sensor_id}: {rd.value_c:.4f} °C ({rd.read_s:.2f} s)\n")
        else:
            out.write(f"DS18B20 28-{rd.sensor_id}: {rd.status} ({rd.detail})\n")
            good = False
    return good
