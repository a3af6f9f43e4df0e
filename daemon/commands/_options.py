"""Options shared by several commands, so that each is spelled and read one way everywhere.

(A module whose name starts with ``_`` is not a command: ``avard.daemon.cli`` skips it.)
"""

from __future__ import annotations

import argparse
import math

from avard.core.analysis.options import AnalyzeOptions
from avard.core.errors import ConfigError, DataError
from avard.core.io.screen.units import temperature_units

CHANNELS_HELP = ("channels to use, by name or number: 'x z' or 'x,z' (default: all)")


def check_seconds(value: float | None, option: str, *, zero: bool = False) -> None:
    """ConfigError (one line, before any work) unless ``value`` is a finite number of seconds
    above 0 (at least 0 with ``zero``); None (an option left out) passes. A negative
    ``--interval`` had ``avard watch`` redraw at every message, ``--segment 0`` had ``avard
    record`` start a new file at every record, a negative ``--duration`` ended it at once
    with exit status 1 and no word on stderr."""
    if value is None:
        return
    if not (math.isfinite(value) and (value >= 0 if zero else value > 0)):
        raise ConfigError(f"{option} {value:g}: give a number of seconds "
                          f"{'≥ 0' if zero else 'above 0'}")


def add_channels_argument(parser: argparse.ArgumentParser) -> None:
    """``--channels`` taking both forms the docs show: ``x z`` and ``x,z``."""
    parser.add_argument("--channels", nargs="+", metavar="NAME", help=CHANNELS_HELP)


SENSOR_HELP = ("one sensor of a rig (several [[sensor]] entries): its recording in a rig's "
               "recording, or its samples on the stream; refused, naming the sensors there, "
               "when there is no such sensor")


def add_sensor_argument(parser: argparse.ArgumentParser) -> None:
    """``--sensor NAME``: which sensor of a rig a command reads."""
    parser.add_argument("--sensor", metavar="NAME", default=None, help=SENSOR_HELP)


def split_channels(values: list[str] | str | None) -> list[str] | None:
    """The channel names of ``--channels`` (``['x', 'z']`` from ``x z``, ``x,z`` or
    ``x, z``); None when the option was not given."""
    if values is None:
        return None
    words = [values] if isinstance(values, str) else values
    names = [n.strip() for w in words for n in w.split(",") if n.strip()]
    if not names:
        raise DataError("--channels: no channel named; give names or numbers such as 'x z' "
                        "or '0,2'")
    return names


def filter_corner(text: str) -> float | str | None:
    """``--filter-corner``: a corner in Hz, 'auto' or 'none'."""
    if text == "auto":
        return "auto"
    if text == "none":
        return None
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: give a corner in Hz, 'auto' or 'none'") \
            from None
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"filter corner {text} Hz must be > 0")
    return v


def add_model_arguments(parser: argparse.ArgumentParser) -> None:
    """The options that choose analyze's estimator and noise model; `avard explain` takes the
    same ones, so that its base is analyze's fit of the file run with the same options."""
    parser.add_argument("--estimator", choices=("oadev", "cascade"), default="oadev",
                        help="Allan estimator: fully overlapping (oadev, default, as Stable32 "
                             "and allantools) or the service's streaming cascade")
    parser.add_argument("--filter-corner", type=filter_corner, default="auto", metavar="HZ",
                        help="sensor low-pass corner to model on the white noise: a number in "
                             "Hz, 'auto' (ODR/4 for avard's own ADXL355 records) or 'none' "
                             "(leave out the short τ it bends; default auto)")


def add_run_argument(parser: argparse.ArgumentParser) -> None:
    """``--run RUN``: only these runs of a recording (runs at different rates are refused
    together, never averaged: this analyses them one at a time)."""
    parser.add_argument("--run", action="append", default=None, metavar="RUN",
                        help="with a recording: only this run (repeatable); runs whose rates "
                             "differ are refused together, naming them")


def add_temperature_units_argument(parser: argparse.ArgumentParser) -> None:
    """``--temperature-units auto|C|F``: the temperature logs' units, for the input screen."""
    parser.add_argument("--temperature-units", metavar="UNITS", default="auto",
                        help="the temperature logs' units: auto (default: judged from the "
                             "readings; a DS18B20 log in °F is refused for the thermal "
                             "model, with the reason), C (take every log as °C) or F "
                             "(convert every log from °F)")


def analyze_options(args: argparse.Namespace) -> AnalyzeOptions:
    """The AnalyzeOptions of analyze's and explain's shared arguments."""
    channels = split_channels(args.channels)
    return AnalyzeOptions(
        channels=None if channels is None else tuple(channels),
        filter_corner_hz=args.filter_corner, estimator=args.estimator,
        psd=bool(getattr(args, "psd", False)),
        quantiles=getattr(args, "quantiles", "exact"),
        noise_id=getattr(args, "noise_id", "avard"),
        temperature_units=temperature_units(getattr(args, "temperature_units", "auto")))
