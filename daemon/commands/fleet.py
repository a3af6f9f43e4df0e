"""Analyse many sensors' records together on Dask and compare them as a population.

Examples:

    avard fleet pi*/lab.npz                          # a LocalCluster on this machine
    avard fleet a.npz b.npz c.npz --json > fleet.json
    avard fleet runs/*.npz --by sensor --csv fleet.csv --plot fleet.png
    avard fleet /data/*.npz --scheduler tcp://10.0.0.5:8786   # an existing Dask cluster

One record per sensor (the file's name), or --by sensor: records whose 'sensor' field names
the same sensor are pooled (as segments of one record: no Allan difference spans two). Each
.npz record is cut by time into chunks, one Dask task per chunk, and the chunks are added
up exactly (the result is `avard analyze`'s); recordings and CSV files are one task each.
The table gives per sensor and axis N, B, K with 68 % intervals, χ²/dof, hours and losses,
the population's median and robust spread, and the outliers with the reason (rule in
docs/fleet.md). Needs the fleet extra (Dask's distributed). The records' paths must be
readable by the Dask workers (the same path on every machine of a cluster).
"""

from __future__ import annotations

import argparse
import json
import logging
import socket
import sys
from collections.abc import Callable, Sequence
from concurrent.futures import Executor, ThreadPoolExecutor
from pathlib import Path
from typing import TYPE_CHECKING, Any

from avard.core.errors import DataError
from avard.core.io.outputs import (
    check_output_file,
    check_outputs_apart,
    check_plot_output,
    repeated_path,
)
from avard.daemon.commands._options import add_channels_argument, split_channels

if TYPE_CHECKING:
    from avard.core.analysis.results import Analysis

NAME = "fleet"
HELP = "analyse many sensors' records on Dask and flag the outliers of the population"

#: Samples per Dask task when an .npz record is cut into chunks: large enough that a task's
#: start and its re-read prefix cost little beside its OADEV, small enough to spread a 60 h
#: record over a few workers.
CHUNK_SAMPLES = 1 << 22


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.add_argument("paths", nargs="+", metavar="PATH",
                        help=".npz, .csv or recordings, one per sensor (or --by sensor)")
    parser.add_argument("--by", choices=("file", "sensor"), default="file",
                        help="one sensor per file (default), or pool the .npz records whose "
                             "'sensor' field names the same sensor")
    parser.add_argument("--sensor", action="append", metavar="NAME", default=None,
                        help="a rig's recording stands for its sensors' recordings; "
                             "--sensor NAME (repeated) takes only these of them")
    parser.add_argument("--scheduler", metavar="ADDRESS",
                        help="a running Dask scheduler (tcp://HOST:8786); default: a "
                             "LocalCluster on this machine")
    parser.add_argument("--workers", type=int, default=None, metavar="N",
                        help="LocalCluster worker processes (default: the cores, at most 4)")
    parser.add_argument("--rate", type=float, default=None, metavar="HZ",
                        help="sample rate in Hz for CSV files without a t column")
    add_channels_argument(parser)
    parser.add_argument("--json", action="store_true", help="print JSON instead of the table")
    parser.add_argument("--csv", metavar="FILE.csv", help="write the population table as csv")
    parser.add_argument("--plot", metavar="FILE.png",
                        help="the population's ADEV curves with their median and spread "
                             "(needs the plot extra)")


def _refuse_a_record_twice(paths: Sequence[str]) -> None:
    """The same record named twice (``avard fleet *.npz lab.npz``) was two sensors of the
    population: counted twice in its median and spread, with exit status 0."""
    twice = repeated_path(paths)
    if twice is not None:
        a, b = twice
        raise DataError(f"{a} and {b} are the same record, given twice; name each sensor's "
                        "record once")


def _check_files(paths: Sequence[str], rate: float | None) -> None:
    """Every .npz and CSV opened (their metadata only) before the cluster starts: a broken
    one among many ended the run only once the workers had started, under their log lines.
    A recording is checked by its own first read on a worker (opening it here would scan
    every segment once more)."""
    from avard.core.io.readers import record_kind
    from avard.core.io.source import open_record

    for p in paths:
        _path, kind = record_kind(p)
        if kind != "recording":
            _ = open_record(p, rate_hz=rate).info


def _groups(paths: Sequence[str], by: str, rate: float | None = None) -> dict[str, list[str]]:
    """Sensor name → its records, checked to exist before any work."""
    for p in paths:
        if not Path(p).exists():
            raise DataError(f"{p}: no such file or folder; give the records' paths")
    _refuse_a_record_twice(paths)
    if by == "file":
        _check_files(paths, rate)
        names: dict[str, list[str]] = {}
        for p in paths:
            stem = Path(p).stem or Path(p).name
            name = stem if stem not in names else str(p)
            names[name] = [str(p)]
        return names
    from avard.core.io.source import RecordFormat, open_record

    out: dict[str, list[str]] = {}
    formats: dict[str, RecordFormat] = {}
    for p in paths:
        info = open_record(p, rate_hz=rate).info
        sensor = info.sensor_name
        if not sensor:
            raise DataError(f"{p} names no sensor (no 'sensor' field); use --by file")
        out.setdefault(str(sensor), []).append(str(p))
        formats[str(p)] = info.format
    for sensor, group in out.items():
        if len(group) > 1 and any(formats[p] is not RecordFormat.NPZ for p in group):
            raise DataError(f"{group[0]}: --by sensor pools .npz records only, and "
                            f"{len(group)} records name the sensor {sensor}; give them "
                            "with --by file")
    return out


def _reachable(address: str) -> None:
    """Raise OSError at once where nothing listens at a tcp:// scheduler address (Dask's
    Client retries a refused connection until its timeout, so a typo would cost 5 s), and
    ValueError where its port is malformed."""
    from urllib.parse import urlsplit

    parts = urlsplit(address if "://" in address else f"tcp://{address}")
    if parts.scheme != "tcp" or not parts.hostname or parts.port is None:
        return                                 # other transports: Dask's own check
    with socket.create_connection((parts.hostname, parts.port), timeout=5.0):
        pass


def _client(args: argparse.Namespace) -> Any:
    try:
        from distributed import Client, LocalCluster
    except ImportError as exc:
        raise DataError("avard fleet needs Dask's distributed: pip install 'avard[fleet]' "
                        "(from a checkout: .venv/bin/pip install -e '.[fleet]')") from exc
    if args.scheduler:
        try:
            _reachable(args.scheduler)
            return Client(args.scheduler, timeout="5s")
        except ValueError as exc:              # a malformed address (port, missing parts)
            raise DataError(f"--scheduler {args.scheduler}: not a scheduler address ({exc}); "
                            "give one as tcp://HOST:PORT") from exc
        except (OSError, TimeoutError) as exc:
            raise DataError(f"--scheduler {args.scheduler}: no Dask scheduler answers there "
                            f"({exc}); start one (dask scheduler) or leave --scheduler out "
                            "for a local cluster") from exc
    from avard.core.analysis.parallel import MAX_WORKERS, default_workers

    n = args.workers or max(1, min(MAX_WORKERS, default_workers()))
    # Dask's INFO lines (workers starting, connections) would bury the table on a terminal;
    # silence_logs quiets the workers' processes only: the scheduler runs in this one, and
    # its loggers (at INFO by Dask's config) reached stderr through avard's root handler
    if not getattr(args, "verbose", 0):
        logging.getLogger("distributed").setLevel(logging.WARNING)
    # no dashboard; the scheduler's HTTP routes still start, on 8787 by default, and a
    # second local cluster (another fleet run, a notebook) made Dask warn on stderr that
    # the port was taken: a free port of the system's choosing instead
    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                           dashboard_address=None, silence_logs=logging.WARNING,
                           scheduler_kwargs={"dashboard_address": ":0"})
    return Client(cluster)


def _analyse_group(paths: list[str], args: argparse.Namespace, executor: Executor) -> Analysis:
    from avard.core.analysis.engine import analyze, analyze_records
    from avard.core.analysis.options import AnalyzeOptions
    from avard.core.io.source import RecordFormat, open_record

    channels = split_channels(args.channels)
    options = AnalyzeOptions(channels=None if channels is None else tuple(channels))
    sources = [open_record(p, rate_hz=args.rate) for p in paths]
    if all(s.info.format is RecordFormat.NPZ for s in sources):
        n = max(int(s.info.n_samples or 0) for s in sources)
        chunks = max(1, min(16, n // CHUNK_SAMPLES))
        return analyze_records(sources, options, chunks=chunks, executor=executor)
    (source,) = sources
    # a CSV or a recording: one task, analyze as it is
    return executor.submit(analyze, source, options).result()


def analyse_fleet(groups: dict[str, list[str]], args: argparse.Namespace, executor: Executor,
                  progress: Callable[[int, int], None] | None = None
                  ) -> dict[str, Analysis]:
    """Every sensor's analysis, the sensors side by side (their chunks all in flight)."""
    out: dict[str, Analysis] = {}
    with ThreadPoolExecutor(max_workers=min(8, len(groups))) as pool:
        futures = {name: pool.submit(_analyse_group, paths, args, executor)
                   for name, paths in groups.items()}
        for i, (name, fut) in enumerate(futures.items(), 1):
            out[name] = fut.result()
            if progress is not None:
                progress(i, len(futures))
    return out


def _progress() -> Callable[[int, int], None] | None:
    if not sys.stderr.isatty():
        return None

    def show(done: int, total: int) -> None:
        sys.stderr.write(f"\rfleet: {done}/{total} sensors analysed")
        if done >= total:
            sys.stderr.write("\n")
        sys.stderr.flush()

    return show


def run(args: argparse.Namespace) -> int:
    from avard.core.analysis.population import format_population, population, population_csv

    if args.csv:
        check_output_file(args.csv, what=f"--csv {args.csv}", suffixes=(".csv",))
    if args.plot:
        check_plot_output(args.plot, what=f"--plot {args.plot}")
    check_outputs_apart([*([(f"--csv {args.csv}", args.csv)] if args.csv else []),
                         *([(f"--plot {args.plot}", args.plot)] if args.plot else [])],
                        args.paths)
    if args.workers is not None and args.workers < 1:
        raise DataError(f"--workers {args.workers}: give a whole number of processes >= 1")
    if args.rate is not None and not args.rate > 0:
        raise DataError(f"--rate {args.rate}: a sample rate must be a positive number of Hz")
    from avard.daemon.commands.separate import rig_records

    # a rig's recording stands for its sensors' recordings (--sensor NAME: only those)
    groups = _groups(rig_records(args.paths, args.sensor), args.by, args.rate)
    client = _client(args)
    try:
        analyses = analyse_fleet(groups, args, client.get_executor(), _progress())
    finally:
        cluster = getattr(client, "cluster", None)
        client.close()
        if cluster is not None and not args.scheduler:
            cluster.close()
    pop = population(analyses)
    if args.json:
        sys.stdout.write(json.dumps(pop.to_dict(), indent=1, allow_nan=False) + "\n")
    else:
        sys.stdout.write(format_population(pop) + "\n")
    if args.csv:
        Path(args.csv).write_text(population_csv(pop))
    if args.plot:
        from avard.core.plot import plot_population

        plot_population(analyses, pop, args.plot)
    return 0
