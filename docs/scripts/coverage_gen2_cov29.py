"""coverage_gen2_run.py with ``signal_edf.resolved_ramp_interval`` in place of analyze's
``with_signal_edf`` (cov29's measurement; analyze itself does not print these bounds):
beside a ramp the time domain resolved, the bounds from the estimate's error with the
ramp's cross term at the slope's measured variance times the model's ratio
(``drift.model_slope_var``, ``drift.CROSS_SCALE``).

    OMP_NUM_THREADS=1 nice .venv/bin/python docs/scripts/coverage_gen2_cov29.py run \
        --hours 1,60,12 --mixes drift,both --records 200 --out DIR
    .venv/bin/python docs/scripts/coverage_gen2_run.py table --hours 1,12,60 \
        --mixes drift,both --out DIR --detail

(The run reads the same records as ``coverage_gen2_run.py run`` with the same seed.)
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from avard.core.analysis import signal_edf as se  # noqa: E402

_ORIG = se.with_signal_edf
for _mod in list(sys.modules.values()):
    if _mod is not None and _mod is not se and getattr(_mod, "with_signal_edf", None) is _ORIG:
        _mod.with_signal_edf = se.resolved_ramp_interval
# analyze's engine imports the name at its own import: load it, then point it at the rule
from avard.core.analysis import engine  # noqa: E402

engine.with_signal_edf = se.resolved_ramp_interval  # type: ignore[attr-defined]

from docs.scripts import coverage_gen2_run as run  # noqa: E402

if __name__ == "__main__":
    sys.exit(run.main(sys.argv[1:]))
