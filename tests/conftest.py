"""Shared test configuration: markers for slow statistical runs and real hardware, and the
root logger put back after every test."""

from __future__ import annotations

import logging
import os
from collections.abc import Iterator
from pathlib import Path

import pytest

# w1thermsensor runs modprobe on import unless told not to; tests never load kernel modules.
os.environ.setdefault("W1THERMSENSOR_NO_KERNEL_MODULE", "1")

# One BLAS thread per test process, as the service runs (daemon/blas_threads.py), set before
# numpy loads its BLAS. The suite runs one process per core (`pytest -n 2`): a BLAS pool per
# process on top would only oversubscribe the cores, and OpenBLAS busy-waits, so the tests'
# own numpy work (long dot products in the studies' estimators) spent several times its CPU
# spinning. Children that check the BLAS setting strip these variables themselves
# (test_blas.py, test_cmd_run.py, test_cmd_analyze.py); an explicit setting wins.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
IMUDATA = SHARED / "data" / "imudata"


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--runslow", action="store_true", help="run tests marked slow")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    skip_slow = pytest.mark.skip(reason="slow: run with --runslow")
    hw = os.environ.get("AVARD_HARDWARE") == "1" and Path("/dev/spidev0.0").exists()
    skip_hw = pytest.mark.skip(reason="hardware: set AVARD_HARDWARE=1 with a real /dev/spidev0.0")
    for item in items:
        if "slow" in item.keywords and not config.getoption("--runslow"):
            item.add_marker(skip_slow)
        if "hardware" in item.keywords and not hw:
            item.add_marker(skip_hw)


@pytest.fixture(scope="session")
def imudata_dir() -> Path:
    """The real ADIS16405 runs in ../shared/data/imudata (never copied into the repo)."""
    if not (IMUDATA / "adis16405_run1.npz").exists():
        pytest.skip(f"real data not present at {IMUDATA}")
    return IMUDATA


def _pytests_own(handler: logging.Handler) -> bool:
    """pytest's log capture handlers, which it adds and removes around each phase itself."""
    return type(handler).__module__.startswith("_pytest")


@pytest.fixture(autouse=True)
def _root_logger_restored() -> Iterator[None]:
    """The root logger's handlers and level as they were before the test.

    A test that calls ``main()`` in-process (or any code that configures logging) left its
    handler on the root logger, bound to that test's captured stderr; pytest closes that
    capture, and every later test's log line became a 'Logging error' in its own stderr
    (a test that read its stderr failed, or not, by the order the tests ran in). pytest's
    own capture handlers are left to pytest: it swaps them at every phase."""
    root = logging.getLogger()
    handlers = [h for h in root.handlers if not _pytests_own(h)]
    level = root.level
    yield
    root.handlers[:] = handlers + [h for h in root.handlers if _pytests_own(h)]
    root.setLevel(level)
