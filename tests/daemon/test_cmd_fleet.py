"""`avard fleet`: twelve simulated sensors on a Dask LocalCluster, two outliers by
construction (issue #29)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from avard.core.analysis.engine import analyze, analyze_records
from avard.core.io.source import open_record
from avard.daemon.cli import main

pytest.importorskip("distributed")

RATE = 100.0
N = 1 << 16
#: sensor index → (N multiplier, K multiplier): 3 has a white level 2.5× the batch's,
#: 8 a rate random walk 6× the batch's
OUTLIERS = {3: (2.5, 1.0), 8: (1.0, 6.0)}


def _sensor(path: Path, i: int) -> None:
    """One sensor, written apart from the simulator: white noise (N) and a random walk of
    the rate (K), levels within ±10 % across the batch, on three axes, 1 g on z."""
    rng = np.random.default_rng(1000 + i)
    n_mult, k_mult = OUTLIERS.get(i, (1.0, 1.0))
    n_level = 1e-4 * (1 + 0.1 * rng.uniform(-1, 1)) * n_mult   # m/s/√s
    k_level = 2e-5 * (1 + 0.1 * rng.uniform(-1, 1)) * k_mult   # m/s²/√s
    white = rng.standard_normal((N, 3)) * n_level * np.sqrt(RATE)
    walk = np.cumsum(rng.standard_normal((N, 3)), axis=0) * k_level / np.sqrt(RATE)
    np.savez(path, accel=white + walk + np.array([0.0, 0.0, 9.81]), rate_hz=RATE,
             sensor=f"unit{i:02d}")


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    d = tmp_path_factory.mktemp("fleet")
    paths = []
    for i in range(12):
        p = d / f"unit{i:02d}.npz"
        _sensor(p, i)
        paths.append(p)
    return paths


def test_fleet_on_a_local_cluster_equals_analyze_and_flags_the_two_outliers(
        fleet: list[Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    csv, png = tmp_path / "fleet.csv", tmp_path / "fleet.png"
    args = ["fleet", *map(str, fleet), "--workers", "2", "--json", "--csv", str(csv)]
    plot = pytest.importorskip("matplotlib", reason="the plot extra") is not None
    rc = main([*args, "--plot", str(png)] if plot else args)
    assert rc == 0
    d = json.loads(capsys.readouterr().out)
    flagged = {(o["sensor"], o["term"]) for o in d["outliers"]}
    assert {s for s, _t in flagged} == {"unit03", "unit08"}
    assert ("unit03", "velocity_random_walk") in flagged
    assert ("unit08", "rate_random_walk") in flagged
    # every sensor's terms are avard analyze's of its file alone
    rows = {(r["sensor"], r["channel"]): r for r in d["sensors"]}
    for p in fleet:
        an = analyze(open_record(p))
        for name, ch in an.channels.items():
            row = rows[(p.stem, name)]
            for term, e in ch.fit.terms.items():
                got = row["terms"][term]
                assert got["present"] == e.present, (p.stem, name, term)
                if e.present:
                    assert got["value"] == pytest.approx(e.value, rel=1e-9)
                    assert got["lo"] == pytest.approx(e.lo, rel=1e-9)
    assert csv.read_text().startswith("sensor,channel,term,value")
    assert png.stat().st_size > 10_000


def test_by_sensor_pools_a_sensors_records(fleet: list[Path], tmp_path: Path) -> None:
    """--by sensor: two records naming one sensor are pooled as segments of one record."""
    a, b = tmp_path / "a.npz", tmp_path / "b.npz"
    for p, seed in ((a, 1), (b, 2)):
        rng = np.random.default_rng(seed)
        np.savez(p, accel=rng.normal(0, 1e-3, (N, 3)), rate_hz=RATE, sensor="same")
    out = subprocess.run([sys.executable, "-m", "avard.daemon.cli", "fleet", str(a), str(b),
                          str(fleet[0]), str(fleet[1]), str(fleet[2]), "--by", "sensor",
                          "--workers", "1", "--json"],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    d = json.loads(out.stdout)
    pooled = next(r for r in d["sensors"] if r["sensor"] == "same" and r["channel"] == "x")
    ref = analyze_records([open_record(a), open_record(b)]).channels["x"].fit.terms[
        "velocity_random_walk"]
    assert pooled["hours"] == pytest.approx(2 * N / RATE / 3600)
    assert pooled["terms"]["velocity_random_walk"]["value"] == pytest.approx(ref.value,
                                                                            rel=1e-9)


@pytest.mark.parametrize("args, message", [
    (["missing.npz"], "no such file"),
    (["{a}", "--scheduler", "tcp://127.0.0.1:1"], "no Dask scheduler"),
    (["{a}", "--scheduler", "tcp://127.0.0.1:99999"], "not a scheduler address"),
    (["{a}", "--scheduler", "tcp://127.0.0.1"], "not a scheduler address"),
    (["{a}", "--workers", "0"], "--workers 0"),
    (["{a}", "{nosensor}", "--by", "sensor"], "names no sensor"),
])
def test_bad_input_is_one_line_and_exit_2(fleet: list[Path], tmp_path: Path, args: list[str],
                                          message: str) -> None:
    nosensor = tmp_path / "nosensor.npz"
    np.savez(nosensor, accel=np.zeros((4096, 3)), rate_hz=RATE)
    argv = [x.format(a=fleet[0], nosensor=nosensor) for x in args]
    out = subprocess.run([sys.executable, "-m", "avard.daemon.cli", "fleet", *argv],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 2
    assert message in out.stderr and "Traceback" not in out.stderr


def test_avard_run_loads_nothing_of_dask() -> None:
    probe = ("import sys; from avard.daemon.cli import build_parser; build_parser('run'); "
             "import avard.daemon.commands.run; "
             "print(sorted(m for m in sys.modules if m.split('.')[0] in ('dask', "
             "'distributed')))")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                         check=True, timeout=120)
    assert out.stdout.strip() == "[]"


@pytest.mark.parametrize("how", ["same path", "another spelling"])
def test_one_record_named_twice_is_refused_before_any_work(
        fleet: list[Path], monkeypatch, capsys, how: str) -> None:
    """It was two sensors of the population (counted twice in its median and spread)."""
    from avard.daemon.commands import fleet as fleet_cmd

    monkeypatch.setattr(fleet_cmd, "_client", lambda args: pytest.fail("a cluster started"))
    a = str(fleet[0])
    b = a if how == "same path" else str(fleet[0].parent / "." / fleet[0].name)
    assert main(["fleet", a, str(fleet[1]), b]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "given twice" in err, err


def test_a_broken_file_among_the_records_is_named_before_the_cluster_starts(
        fleet: list[Path], tmp_path: Path, monkeypatch, capsys) -> None:
    from avard.daemon.commands import fleet as fleet_cmd

    monkeypatch.setattr(fleet_cmd, "_client", lambda args: pytest.fail("a cluster started"))
    broken = tmp_path / "unit99.npz"
    broken.write_bytes(fleet[0].read_bytes()[:1000])
    assert main(["fleet", *map(str, fleet[:3]), str(broken)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "unit99.npz" in err and "truncated" in err, err


def test_the_local_clusters_log_lines_stay_off_stderr(fleet: list[Path]) -> None:
    """The scheduler runs in avard's process, its loggers at INFO by Dask's config: some
    thirty lines (scheduler start, workers, comms) reached stderr through avard's handler,
    around a result or an error. Another local cluster held Dask's default HTTP port 8787
    (another test's fleet, beside this one under ``-n 2``): Dask warned on stderr that the
    port was taken. Held here on purpose, so the case is met every run."""
    import socket

    holder = socket.socket()
    holder.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        holder.bind(("", 8787))
        holder.listen()
    except OSError:
        pass                        # held already, by something else: the same case
    try:
        r = subprocess.run([sys.executable, "-m", "avard.daemon.cli", "fleet",
                            *map(str, fleet[:2]), "--workers", "1"],
                           capture_output=True, text=True, timeout=300)
    finally:
        holder.close()
    assert r.returncode == 0, r.stderr
    assert r.stderr == "" and r.stdout.startswith("Units SI"), r.stderr


class _Started(Exception):
    """The cluster would start: every check before it passed."""


def test_records_that_need_rate_are_read_with_it_before_the_cluster_starts(
        tmp_path: Path, monkeypatch, capsys) -> None:
    """The files are opened before the cluster starts, with ``--rate`` as the workers open
    them: an .npz without ``rate_hz`` was refused there although the rate was given."""
    from avard.daemon.commands import fleet as fleet_cmd

    rng = np.random.default_rng(0)
    paths = []
    for k in "ab":
        p = tmp_path / f"norate_{k}.npz"
        np.savez(p, accel=rng.normal(size=(2000, 3)) * 1e-3)
        paths.append(str(p))

    def start(args):
        raise _Started

    monkeypatch.setattr(fleet_cmd, "_client", start)
    with pytest.raises(_Started):
        main(["fleet", *paths, "--rate", "100"])
    # without the rate they are refused before it, in one line
    assert main(["fleet", *paths]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--rate" in err, err
