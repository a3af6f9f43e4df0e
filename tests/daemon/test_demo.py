"""`avard demo` end to end on a short run: service, subscriber, recording, fit, plot, report."""

from __future__ import annotations

from pathlib import Path

import pytest
from avard.daemon.cli import main

from tests.support.demo_block import README_ARGS, SHORT_ARGS, SHORT_BLOCK, demo_stdout, readme_block


def test_demo_short_run_writes_report_and_plot(tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "demo"
    assert main(["demo", "--hours", "0.05", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "index continuity ok, 0 messages lost" in text
    assert "max relative difference" in text
    assert "velocity_random_walk" in text and "m/s/sqrt(s)" in text
    # each term is shown next to the simulator's true value, and N comes back within 2 %
    from avard.core.sim.presets import make_config

    n_true = make_config("quiet-lab").velocity_random_walk[0]
    n_line = next(ln for ln in text.splitlines() if ln.strip().startswith("velocity_random_walk"))
    assert f"(simulated {n_true:.3e})" in n_line
    assert abs(float(n_line.split()[1]) / n_true - 1) < 0.02, n_line
    report = (out / "report.md").read_text()
    assert "recording vs streamed Allan variance" in report
    assert (out / "adev.png").stat().st_size > 10_000
    assert len(list((out / "recording").glob("*.avr"))) >= 1
    # Running again replaces the demo's own recording instead of appending to it.
    assert main(["demo", "--hours", "0.01", "--out", str(out), "--no-plot"]) == 0
    runs = {p.name.split("_")[0] for p in (out / "recording").glob("*.avr")}
    assert len(runs) == 1


def test_demo_refuses_nonpositive_hours(tmp_path: Path,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["demo", "--hours", "0", "--out", str(tmp_path)]) == 2
    assert "--hours" in capsys.readouterr().err


def test_the_demo_with_its_seed_prints_the_same_numbers_every_run(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The service used to stop when its supervisor next looked at the fast virtual clock,
    so the sample count (and every fitted number) changed from run to run with one seed; the
    recording's size and the snapshot count are the same on every run too (the wall time is
    on stderr)."""
    texts = []
    for i in range(2):
        assert main(["demo", "--hours", "0.05", "--out", str(tmp_path / f"d{i}"),
                     "--no-plot"]) == 0
        captured = capsys.readouterr()
        assert "wall time" in captured.err and "wall" not in captured.out
        # no log lines beside the results unless -v (they went to stderr, mixed with them)
        assert "INFO" not in captured.err
        texts.append(captured.out.replace(str(tmp_path / f"d{i}"), "OUT"))
    assert texts[0] == texts[1]
    lines = texts[0].splitlines()
    n = int(lines[1].split()[1])
    # quiet-lab's real ODR (125 Hz, −800 ppm); the samples after the last drain (polled at
    # 3·ODR/32, so fewer than 11) stay in the FIFO
    assert 0 <= round(0.05 * 3600 * 124.9) - n <= 32 / 3 + 1
    # every sample and every snapshot (one per 60 s of service time) reached the subscriber
    assert f"subscriber: {n} samples, index continuity ok, 0 messages lost, 3 Allan " \
           "snapshots" in lines[2]


def test_a_short_demo_prints_exactly_the_stored_block(tmp_path: Path) -> None:
    """The stored block and README.md's are written by one script (tests/support/demo_block.py)
    from real runs: when the demo's output changes, this fails, and the script updates both."""
    assert demo_stdout(SHORT_ARGS, tmp_path) == SHORT_BLOCK.read_text(), (
        "the demo's output changed: run `.venv/bin/python -m tests.support.demo_block` and "
        "commit README.md and tests/daemon/demo_short.txt")


@pytest.mark.slow
def test_make_demo_prints_exactly_the_readme_block(tmp_path: Path) -> None:
    assert demo_stdout(README_ARGS, tmp_path) == readme_block()


def test_the_readme_shows_the_demo_block_with_what_make_demo_runs() -> None:
    block = readme_block()
    assert block.startswith("avard demo: 6 simulated hours")
    assert "\n  wrote demo-out/report.md" in block
    makefile = (Path(__file__).parents[2] / "Makefile").read_text()
    assert "\t$(VENV)/bin/avard demo\n" in makefile  # README_ARGS: no arguments
