"""Every command of the README's table, run as an unprivileged user against input it may not
read and output it may not write: one line naming the file, exit status 2, no traceback.

CI runs the tests as root, for whom mode bits do not apply; the commands are therefore run
under ``setpriv --inh-caps=-all --bounding-set=-all`` (uid 0 without CAP_DAC_OVERRIDE and
CAP_DAC_READ_SEARCH: the owner's mode bits then hold for root too), or directly when the tests
already run as an ordinary user.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

SETPRIV = shutil.which("setpriv")
LOG_LINE = re.compile(r"^(DEBUG|INFO|WARNING) [\w.]+: ")


def _unprivileged() -> list[str]:
    if os.geteuid() != 0:
        return []
    if SETPRIV is None:
        pytest.skip("running as root and setpriv (util-linux) is missing: cannot drop privileges")
    return [SETPRIV, "--inh-caps=-all", "--bounding-set=-all", "--"]


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("cli_errors")
    rng = np.random.default_rng(1)
    ok = d / "ok.npz"
    np.savez(ok, accel=rng.normal(0, 1e-3, (4000, 3)), rate_hz=100.0)
    locked = d / "locked.npz"
    shutil.copy(ok, locked)
    locked_dir = d / "recording"           # like /var/lib/avard/... of another group
    locked_dir.mkdir()
    (locked_dir / "run_0000.avr").write_bytes(b"")
    locked_csv = d / "locked.csv"
    locked_csv.write_text("t,x\n0,1\n0.01,2\n")
    locked_toml = d / "locked.toml"
    locked_toml.write_text("[sensor]\n")
    locked_key = d / "locked.key"
    locked_key.write_text("not a key\n")
    ro = d / "nowrite"
    ro.mkdir()
    for p in (locked, locked_csv, locked_toml, locked_key):
        p.chmod(0)
    locked_dir.chmod(0)
    ro.chmod(0o555)
    yield {"ok": ok, "locked": locked, "locked_csv": locked_csv, "locked_dir": locked_dir,
           "locked_toml": locked_toml, "locked_key": locked_key, "nowrite": ro}
    locked_dir.chmod(0o755)
    ro.chmod(0o755)


# (argv with {placeholders}, the name the error line must contain, output case: stdout empty)
CASES = [
    (["analyze", "{locked}"], "locked.npz", False),
    (["analyze", "{locked_dir}"], "recording", False),
    (["analyze", "{locked_csv}"], "locked.csv", False),
    (["explain", "{locked_dir}"], "recording", False),
    (["analyze", "{ok}", "--plot", "{nowrite}/adev.png"], "nowrite", True),
    (["analyze", "{ok}", "--export", "csv", "{nowrite}/adev.csv"], "nowrite", True),
    (["analyze", "{ok}", "--export", "kalibr", "{nowrite}/imu.yaml"], "nowrite", True),
    (["explain", "{locked}"], "locked.npz", False),
    (["explain", "{ok}", "--report", "{nowrite}/report"], "nowrite", True),
    (["simulate", "--hours", "0.01", "--seed", "1", "--out", "{nowrite}/x.npz"], "nowrite", True),
    (["keys", "--out", "{nowrite}/keys"], "nowrite", True),
    (["demo", "--out", "{nowrite}/demo", "--hours", "0.01"], "nowrite", True),
    (["record", "tcp://127.0.0.1:9", "--out", "{nowrite}/rec", "--wait", "1"], "nowrite", True),
    (["run", "--config", "{locked_toml}"], "locked.toml", False),
    (["run", "--simulate", "quiet-lab", "--speed", "0", "--duration", "1", "--data-dir",
      "{nowrite}/rec"], "nowrite", True),
    (["check-config", "{locked_toml}"], "locked.toml", False),
    (["probe", "--emulate", "--config", "{locked_toml}"], "locked.toml", False),
    (["watch", "tcp://127.0.0.1:9", "--server-key", "{locked_key}", "--client-key",
      "{locked_key}"], "locked.key", False),
]


@pytest.mark.parametrize(("argv", "names", "output_case"), CASES,
                         ids=[" ".join(c[0][:2]) + f" #{i}" for i, c in enumerate(CASES)])
def test_unreadable_input_and_unwritable_output_end_in_one_line(
        files: dict[str, Path], argv: list[str], names: str, output_case: bool) -> None:
    args = [a.format(**files) for a in argv]
    r = subprocess.run([*_unprivileged(), sys.executable, "-m", "avard.daemon.cli", *args],
                       capture_output=True, text=True, timeout=120, check=False,
                       stdin=subprocess.DEVNULL)
    assert "Traceback" not in r.stderr, r.stderr
    assert r.returncode == 2, (r.returncode, r.stderr)
    errors = [ln for ln in r.stderr.splitlines() if ln.strip() and not LOG_LINE.match(ln)]
    assert len(errors) == 1, r.stderr
    line = errors[0]
    assert line.startswith(f"avard {argv[0]}: error: "), line
    assert names in line.split(": error: ", 1)[1], line
    if output_case:  # the output was refused before any work was done or printed
        assert r.stdout == "", r.stdout


@pytest.mark.parametrize("argv", [
    ["analyze", "{ok}", "--plot", "{tmp}/adev.png"],
    ["explain", "{ok}", "--report", "{tmp}/report"],
])
def test_a_missing_plot_extra_is_said_before_the_work(files: dict[str, Path], tmp_path: Path,
                                                      argv: list[str]) -> None:
    """As on a Pi installed by systemd/install.sh, which leaves the plot extra out."""
    args = [a.format(tmp=tmp_path, **files) for a in argv]
    code = ("import sys; sys.modules['matplotlib'] = None; from avard.daemon.cli import main; "
            f"sys.exit(main({args!r}))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       timeout=120, check=False)
    assert r.returncode == 2, r.stderr
    assert "needs matplotlib" in r.stderr and "avard[plot]" in r.stderr
    assert "Traceback" not in r.stderr and r.stdout == ""
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(("suffix", "option"), [(".jpgg", "--plot"), (".txt", "--plot")])
def test_an_unknown_figure_suffix_is_refused_before_the_work(
        files: dict[str, Path], tmp_path: Path, suffix: str, option: str) -> None:
    r = subprocess.run([sys.executable, "-m", "avard.daemon.cli", "analyze", str(files["ok"]),
                        option, str(tmp_path / f"adev{suffix}")], capture_output=True,
                       text=True, timeout=120, check=False)
    assert r.returncode == 2 and r.stdout == ""
    assert f"unknown suffix '{suffix}'" in r.stderr and ".png" in r.stderr


def test_the_demo_without_the_plot_extra_says_so_first_and_runs(tmp_path: Path) -> None:
    args = ["demo", "--out", str(tmp_path / "demo"), "--hours", "0.01"]
    code = ("import sys; sys.modules['matplotlib'] = None; from avard.daemon.cli import main; "
            f"sys.exit(main({args!r}))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       timeout=300, check=False)
    assert r.returncode == 0, r.stderr
    first = r.stderr.splitlines()[0]
    assert "needs matplotlib" in first and "runs without adev.png" in first
    assert (tmp_path / "demo" / "report.md").exists()
    assert not (tmp_path / "demo" / "adev.png").exists()
