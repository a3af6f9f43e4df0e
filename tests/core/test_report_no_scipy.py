"""`avard analyze` of a file never imports scipy, an ADXL355 record with its chip filter
modelled included (issue #12, speed: scipy.special cost 0.1–0.2 CPU-s of every analyze and
scipy.signal 0.5 s and ~70 MB, seconds on a Raspberry Pi)."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np

# Run in a fresh interpreter: the test process has scipy loaded by other tests.
PROBE = """
import json, sys
import avard.core.analysis.engine as r
from avard.core.analysis.formats import format_table
from avard.core.io.source import open_record
an = r.analyze(open_record(sys.argv[1]))
table = format_table(an)
print(json.dumps({
    "scipy": sorted(m for m in sys.modules if m == "scipy" or m.startswith("scipy.")),
    "lines": {k: ch.lines for k, ch in an.channels.items()},
    "threshold_solver": "avard.core.allan.beta" in sys.modules,
    "table": table,
}))
"""


def test_analyze_and_its_table_do_not_import_scipy(tmp_path: Path) -> None:
    rng = np.random.default_rng(5)
    n, rate = 1 << 15, 50.0
    accel = 2e-4 * rng.standard_normal((n, 2)) + np.cumsum(2e-6 * rng.standard_normal((n, 2)),
                                                           axis=0)
    accel[:, 1] += 1e-3 * np.sin(2 * np.pi * 3.1 * np.arange(n) / rate)   # a line to find
    path = tmp_path / "rec.npz"
    np.savez(path, accel=accel, rate_hz=rate, axes=np.array(["x", "y"]))
    out = subprocess.run([sys.executable, "-c", PROBE, str(path)], capture_output=True,
                         text=True, check=True, timeout=300)
    got = json.loads(out.stdout)
    assert got["scipy"] == []
    # the line finder ran (its threshold solved here) and found the 3.1 Hz line; the
    # table was written, with its fit lines (where the χ² p-value is computed)
    assert got["threshold_solver"]
    assert [round(ln["frequency_hz"], 1) for ln in got["lines"]["y"]] == [3.1]
    dofs = [int(d) for d in re.findall(r"χ²/dof = [0-9.]+ \(dof (\d+)\)", got["table"])]
    assert len(dofs) == 2 and min(dofs) > 0


def test_analyze_of_an_adxl355_record_with_its_filter_does_not_import_scipy(
        tmp_path: Path) -> None:
    """avard's own records (simulated here, as `avard simulate` writes them) have their
    chip filter and LSB modelled: the filter's Butterworth, impulse response and gain come
    from numpy, not scipy.signal."""
    rec = tmp_path / "lab.npz"
    subprocess.run([sys.executable, "-m", "avard.daemon.cli", "simulate", "--preset",
                    "quiet-lab", "--hours", "0.25", "--seed", "2", "--out", str(rec)],
                   capture_output=True, text=True, check=True, timeout=300)
    out = subprocess.run([sys.executable, "-c", PROBE, str(rec)], capture_output=True,
                         text=True, check=True, timeout=300)
    got = json.loads(out.stdout)
    assert got["scipy"] == []
    assert "sensor low-pass modelled at" in got["table"]  # the chip filter was modelled
