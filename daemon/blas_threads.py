"""Hold numpy's BLAS/OpenMP to one thread in the service (import before numpy).

The service's numpy work is on small blocks in threads of its own; a BLAS pool of one thread
per core would only spin (OpenBLAS busy-waits) and take cores from the reader on a 4-core Pi.
The variables are read once, when numpy loads its BLAS, so this module must be imported
before numpy is: ``avard run`` imports it first (``LOADED_BEFORE_NUMPY`` records whether it
was in time; tests/daemon/test_cmd_run.py checks it).
"""

from __future__ import annotations

import os
import sys

_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS",
         "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS")

LOADED_BEFORE_NUMPY = "numpy" not in sys.modules
for _name in _VARS:
    os.environ.setdefault(_name, "1")   # an administrator's explicit setting wins
