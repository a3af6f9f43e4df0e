"""The whole pipeline on an emulated sensor, in a couple of minutes: ``make demo``.

1. Runs the acquisition service (``avard run --simulate quiet-lab``) on its virtual clock for
   ``--hours`` simulated hours (default 6) as fast as the CPU allows, recording into
   ``OUT/recording`` and publishing on loopback ZeroMQ sockets with ephemeral ports.
2. A real subscriber (SUB socket in this process) receives the stream meanwhile and checks that
   every raw sample arrived exactly once (sequence numbers and sample indices).
3. Reads the recording back, checks that its offline Allan variance equals the service's own
   streamed snapshot, fits the IEEE noise terms (with 68 % intervals) to each axis, and writes
   ``OUT/adev.png`` and ``OUT/report.md``.
"""

from __future__ import annotations

import argparse
import logging
import shutil
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
from avard.core.errors import AvardError, OutputError
from avard.core.io.outputs import check_output_dir, require_plot_extra
from avard.core.sim.presets import make_config
from avard.daemon.config import load_config
from avard.daemon.config_types import Config

NAME = "demo"
HELP = "run the service on the emulated ADXL355 for hours of simulated time, then analyse"

log = logging.getLogger(__name__)

PRESET = "quiet-lab"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default="demo-out", metavar="DIR",
                        help="output directory (default ./demo-out; its recording/ is replaced)")
    parser.add_argument("--hours", type=float, default=6.0,
                        help="simulated hours (default 6)")
    parser.add_argument("--preset", default=PRESET, help="simulator preset (default quiet-lab)")
    parser.add_argument("--seed", type=int, default=2026, help="simulator seed")
    parser.add_argument("--no-plot", action="store_true", help="skip the PNG plot")


class _Listener:
    """A subscriber thread that counts every raw sample and checks index continuity."""

    def __init__(self, endpoint: str, request_endpoint: str) -> None:
        from avard.daemon.net.subscriber import Subscriber

        self.sub = Subscriber(endpoint, request_endpoint=request_endpoint).connect(join=False)
        self.indices_ok = True
        self.samples = 0
        self.first: int | None = None
        self.next: int | None = None
        self.avar_messages = 0
        self.last_avar: dict[str, Any] | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="demo-subscriber", daemon=True)

    def start(self, publisher: Any) -> None:
        """Join ``publisher`` (before acquisition), then read in a thread."""
        from avard.daemon.net.handshake import wait_until_subscribed

        for topic, rec in wait_until_subscribed(publisher, self.sub):
            self._take(topic, rec)
        self._thread.start()

    def _take(self, topic: str, rec: dict[str, Any]) -> None:
        if topic == "raw":
            if self.next is not None and rec["i0"] != self.next:
                self.indices_ok = False
            if self.first is None:
                self.first = rec["i0"]
            self.next = rec["i0"] + rec["n"]
            self.samples += rec["n"]
        elif rec["kind"] == "avar":
            self.avar_messages += 1
            self.last_avar = rec

    def _run(self) -> None:
        while not self._stop.is_set():
            msg = self.sub.recv(timeout_s=0.2)
            if msg is not None:
                self._take(msg.topic, msg.record)

    def stop(self) -> None:
        # Drain what is still queued (the publisher is closed; nothing new arrives).
        self._stop.set()
        self._thread.join(5)
        while (msg := self.sub.recv(timeout_s=0.5)) is not None:
            self._take(msg.topic, msg.record)
        self.sub.close()


def _agreement(rel: float) -> str:
    """The recording-vs-stream check as the same words on every run: below 1e-12 the
    difference is float rounding, whose last digits depend on how the reader's blocks fell."""
    return ("equal to float rounding (max relative difference < 1e-12)" if rel < 1e-12
            else f"max relative difference {rel:.1e}")


def _fmt(v: float | None) -> str:
    return "—" if v is None else f"{v:.3e}"


def run(args: argparse.Namespace) -> int:
    from avard.core.io.recording import load_recording, replay_allan
    from avard.core.model.fit import fit_noise
    from avard.daemon.commands.run import build

    if args.hours <= 0:
        raise AvardError(f"--hours {args.hours}: must be positive")
    check_output_dir(args.out, what=f"--out {args.out}", create=True)
    if not args.no_plot:
        try:  # said at the start, not after the run; the demo itself needs no figure
            require_plot_extra("the demo's figure")
        except OutputError as exc:
            log.warning("%s; the demo runs without adev.png", exc)
            args.no_plot = True
    out = Path(args.out).resolve()
    rec_dir = out / "recording"
    if rec_dir.exists():
        shutil.rmtree(rec_dir)
    out.mkdir(parents=True, exist_ok=True)
    cfg = load_config(None, **{
        "recording.data_dir": str(rec_dir),
        "publish.endpoint": "tcp://127.0.0.1:0", "publish.request_endpoint": "tcp://127.0.0.1:0",
        "publish.hwm": 1_000_000, "publish.status_interval_s": 1.0,
        "sensor.poll_hz": 1.0,                 # raised to 3·ODR/32 by the service
        "allan.snapshot_interval_s": 60.0, "allan.checkpoint_interval_s": 600.0,
        "allan.restore": False, "service.status_log_interval_s": 10.0,
    })
    ns = argparse.Namespace(simulate=args.preset, speed=0.0, seed=args.seed)
    svc = build(ns, Config.from_dict(cfg))
    listener: dict[str, _Listener] = {}

    def before_acquisition() -> None:
        lst = _Listener(svc.publisher.endpoint, svc.request_server.endpoint)
        lst.start(svc.publisher)
        listener["l"] = lst

    seconds = args.hours * 3600.0
    say = sys.stdout.write
    say(f"avard demo: {args.hours:g} simulated hours of an emulated ADXL355 ({args.preset}, "
        f"{cfg['sensor']['odr_hz']:g} Hz) through the service, as fast as this CPU allows\n")
    wall0 = time.monotonic()
    svc.run(seconds, before_acquisition=before_acquisition)
    wall = time.monotonic() - wall0
    lst = listener["l"]
    lst.stop()
    st = svc.final_status
    # The one figure that depends on this machine goes to stderr, so that what stdout says
    # is the same on every run with one seed (the README shows it verbatim).
    sys.stderr.write(f"avard demo: the service took {wall:.0f} s of wall time on this CPU "
                     f"({seconds / wall:.0f}× real time)\n")
    say(f"  service: {st['samples']} samples, {st['overruns']} overruns, "
        f"recording {st['disk']['bytes'] / 1e6:.1f} MB in {st['disk']['segments']} "
        f"segment{'' if st['disk']['segments'] == 1 else 's'}\n")
    say(f"  subscriber: {lst.samples} samples, index continuity "
        f"{'ok' if lst.indices_ok else 'BROKEN'}, {lst.sub.stats.messages_lost} messages "
        f"lost, {lst.avar_messages} Allan snapshots\n")

    # Offline: the recording's Allan variance equals the service's streamed one.
    replay = replay_allan(rec_dir)
    a_stream = svc.allan.snapshot().avar
    a_off = replay.snapshot().avar
    ok = a_stream.shape == a_off.shape
    rel = float(np.nanmax(np.abs(a_off - a_stream) / np.where(a_stream == 0, 1, a_stream))) \
        if ok else float("inf")
    say(f"  recording vs streamed Allan variance: {_agreement(rel)}\n")

    record = load_recording(rec_dir)
    result = replay.result()
    odr = float(cfg["sensor"]["odr_hz"])
    fits = {}
    truth = make_config(args.preset).to_dict()
    lsb = record.meta.get("lsb_mps2")   # the rounding after the chip filter
    lines = ["", "IEEE noise terms per axis (68 % intervals, SI units; the simulator's true "
             "value after each):", ""]
    for c, axis in enumerate(("x", "y", "z")):
        try:
            fits[axis] = fit_noise(result.channel(c), filter_corner_hz=odr / 4,
                                   rounding_lsb=lsb)
        except AvardError as exc:
            lines.append(f"  {axis}: fit failed: {exc}")
            continue
        f = fits[axis]
        lines.append(f"  axis {axis} (τ {f.tau_min_s:.3g}–{f.tau_max_s:.3g} s, "
                     f"χ²/dof {f.chi2_dof:.2f}):")
        for name, t in f.terms.items():
            true = _fmt(float(truth[name][c])) if name in truth else "?"
            if t.present:
                lines.append(f"    {name:22s} {_fmt(t.value)} [{_fmt(t.lo)}, {_fmt(t.hi)}] "
                             f"{t.unit}   (simulated {true})")
            else:
                lines.append(f"    {name:22s} not supported by the data   (simulated {true})")
    say("\n".join(lines) + "\n")
    plot = None if args.no_plot else _plot(out / "adev.png", result, fits)
    _report(out / "report.md", args, st, lst, wall, seconds, rel, lines, record, plot)
    # named as given (not resolved), so the line is the same on every machine
    given = Path(args.out)
    say(f"\n  wrote {given / 'report.md'}" + (f" and {given / plot.name}" if plot else "")
        + "\n")
    good = ok and rel < 1e-9 and lst.indices_ok and st["overruns"] == 0
    return 0 if good else 1


def _plot(path: Path, result: Any, fits: dict[str, Any]) -> Path | None:
    from avard.core.plot import pyplot, save_figure

    try:
        plt = pyplot()
    except AvardError as exc:
        log.warning("%s: no plot", exc)
        return None
    fig, ax = plt.subplots(figsize=(7, 5))
    for c, axis in enumerate(("x", "y", "z")):
        ch = result.channel(c)
        ax.errorbar(ch.tau, np.sqrt(ch.var), yerr=[np.sqrt(ch.var) - np.sqrt(ch.lo),
                                                   np.sqrt(ch.hi) - np.sqrt(ch.var)],
                    fmt="o", ms=3, color=f"C{c}", label=f"{axis} measured")
        if axis in fits:
            ax.plot(ch.tau, np.sqrt(fits[axis].model_avar(ch.tau)), "-", lw=1,
                    color=f"C{c}", label=f"{axis} fit")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("averaging time τ (s)")
    ax.set_ylabel("Allan deviation (m/s²)")
    ax.set_title("avard demo: emulated ADXL355, streamed Allan deviation and fit")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    return save_figure(fig, path, dpi=120)


def _report(path: Path, args: argparse.Namespace, st: dict[str, Any], lst: _Listener,
            wall: float, seconds: float, rel: float, lines: list[str], record: Any,
            plot: Path | None) -> None:
    text = [
        "# avard demo report", "",
        f"- simulated: {args.hours:g} h of preset `{args.preset}` (seed {args.seed}), "
        f"{record.rate_hz:.4f} Hz fitted rate",
        f"- service: {st['samples']} samples, {st['overruns']} overruns, "
        f"{st['bus_errors']} bus errors, wall time {wall:.0f} s ({seconds / wall:.0f}× real "
        "time)",
        f"- recording: {st['disk']['bytes']} bytes in {st['disk']['segments']} segments, "
        f"{len(record.meta['gaps'])} gap records, {len(record.meta['problems'])} damaged frames",
        f"- subscriber: {lst.samples} samples received, index continuity "
        f"{'ok' if lst.indices_ok else 'broken'}, {lst.sub.stats.messages_lost} messages lost",
        f"- recording vs streamed Allan variance: max relative difference {rel:.1e}",
        "", "```", *lines, "```", "",
    ]
    if plot:
        text.append(f"![Allan deviation]({plot.name})")
    path.write_text("\n".join(text) + "\n")
