"""The demo's output as the README shows it: generated from a real run, compared by tests.

``python -m tests.support.demo_block`` (from the checkout, with the venv's python) runs
``avard demo`` exactly as ``make demo`` does (no arguments, ``--out demo-out``, 6 simulated
hours) and writes its stdout into README.md between the ``demo-block`` markers; it also runs
the short demo of :data:`SHORT_ARGS` and stores its stdout in :data:`SHORT_BLOCK`.

tests/daemon/test_demo.py compares a short run with :data:`SHORT_BLOCK` on every test run (a
change of the demo's output fails there first, and this script updates both) and, in the slow
set, a run with the README's parameters with the README's block itself. stdout is the same on
every run with one seed: the wall time goes to stderr.
"""

from __future__ import annotations

import re
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
SHORT_BLOCK = ROOT / "tests" / "daemon" / "demo_short.txt"
#: what ``make demo`` runs: ``avard demo`` with its defaults
README_ARGS: tuple[str, ...] = ()
SHORT_ARGS: tuple[str, ...] = ("--hours", "0.05", "--no-plot")
_BLOCK = re.compile(r"(<!-- demo-block:[^\n]*-->\n```\n)(.*?)(```\n)", re.S)


def demo_stdout(args: tuple[str, ...], cwd: Path) -> str:
    """stdout of ``avard demo ARGS`` run in ``cwd`` (so ``--out`` is ``demo-out`` there)."""
    p = subprocess.run([sys.executable, "-m", "avard.daemon.cli", "demo", *args], cwd=cwd,
                       capture_output=True, text=True, timeout=3600)
    if p.returncode != 0:
        raise RuntimeError(f"avard demo {' '.join(args)} failed:\n{p.stderr[-3000:]}")
    return p.stdout


def readme_block(text: str | None = None) -> str:
    m = _BLOCK.search(README.read_text() if text is None else text)
    if m is None:
        raise LookupError("README.md has no demo-block")
    return m.group(2)


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        SHORT_BLOCK.write_text(demo_stdout(SHORT_ARGS, Path(tmp)))
        out = demo_stdout(README_ARGS, Path(tmp))
    text = README.read_text()
    readme_block(text)  # the markers are there
    README.write_text(_BLOCK.sub(lambda m: m.group(1) + out + m.group(3), text, count=1))
    print(f"updated {README.name} and {SHORT_BLOCK.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
