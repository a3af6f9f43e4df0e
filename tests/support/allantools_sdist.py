"""The public Stable32 reference data sets, from allantools' source distribution.

allantools' test suite keeps raw records with Stable32's own output for each (a Cs 5071A
clock, a GPS 1PPS record, an OCXO, simulated pink FM noise, a Keysight 53230A counter floor).
They are LGPL and 4 MB, so they are not copied into avard: the pinned sdist is fetched once
with pip (the package index CI installs from), its sha256 checked, its ``tests/`` folder
extracted, and the result cached under ``$AVARD_TEST_CACHE`` (default
``~/.cache/avard-tests``) for later runs.
"""

from __future__ import annotations

import fcntl
import hashlib
import os
import shutil
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

NAME = "allantools"
VERSION = "2024.6"
ARCHIVE = f"{NAME}-{VERSION}.tar.gz"
SHA256 = "c4380c74de834ac869aefc899038e784ef1dd396370be89d6836abffbe484289"
FETCH_TIMEOUT_S = 300


class Unavailable(Exception):
    """The archive could not be had here (no index, no network): a reason to skip."""


class Corrupt(Exception):
    """The archive is not the pinned one: never a reason to skip."""


def cache_dir() -> Path:
    env = os.environ.get("AVARD_TEST_CACHE")
    return Path(env) if env else Path.home() / ".cache" / "avard-tests"


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with path.open("rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _fetch(into: Path) -> Path:
    """pip download the pinned sdist into ``into`` (a fresh directory)."""
    cmd = [sys.executable, "-m", "pip", "download", f"{NAME}=={VERSION}", "--no-binary",
           ":all:", "--no-deps", "--disable-pip-version-check", "-q", "-d", str(into)]
    try:
        out = subprocess.run(cmd, capture_output=True, text=True, timeout=FETCH_TIMEOUT_S)
    except (OSError, subprocess.TimeoutExpired) as e:
        raise Unavailable(f"pip download {NAME}=={VERSION} failed: {e}") from e
    archive = into / ARCHIVE
    if out.returncode != 0 or not archive.is_file():
        last = (out.stderr.strip().splitlines() or ["no message"])[-1]
        raise Unavailable(f"pip download {NAME}=={VERSION} failed: {last}")
    return archive


def reference_tests() -> Path:
    """The extracted ``tests/`` folder of the pinned allantools sdist, fetched if needed.

    Raises ``Unavailable`` when it cannot be fetched and ``Corrupt`` when the archive's
    sha256 is not the pinned one."""
    root = cache_dir()
    done = root / f"{NAME}-{VERSION}" / "tests"
    if done.is_dir():
        return done
    root.mkdir(parents=True, exist_ok=True)
    # one fetch at a time: parallel test workers (pytest -n 2) share the cache
    with (root / f".{NAME}-{VERSION}.lock").open("w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not done.is_dir():
            _fetch_and_extract(root)
    return done


def _fetch_and_extract(root: Path) -> None:
    """Fetch (unless kept) and check the archive, then extract its tests/ into ``root``."""
    archive = root / ARCHIVE
    if not archive.is_file():
        with tempfile.TemporaryDirectory(dir=root) as tmp:
            got = _fetch(Path(tmp))
            if _sha256(got) != SHA256:  # checked before it is kept
                raise Corrupt(f"{got.name} has sha256 {_sha256(got)}, not the pinned {SHA256}")
            os.replace(got, archive)
    if _sha256(archive) != SHA256:
        raise Corrupt(f"{archive} has sha256 {_sha256(archive)}, not the pinned {SHA256}: "
                      "delete it to fetch it again")
    # extract beside, then rename: a run killed half-way never leaves a partial folder
    with tempfile.TemporaryDirectory(dir=root) as tmp, tarfile.open(archive) as tar:
        prefix = f"{NAME}-{VERSION}/tests/"
        members = [m for m in tar.getmembers() if m.name.startswith(prefix)]
        tar.extractall(tmp, members=members, filter="data")
        final = root / f"{NAME}-{VERSION}"
        shutil.rmtree(final, ignore_errors=True)  # a folder without tests/: left half-made
        os.replace(Path(tmp) / f"{NAME}-{VERSION}", final)


def reference_tests_or_skip() -> Path:
    """``reference_tests()`` for a test: skipped with the reason where the archive cannot be
    fetched, failed under CI (``CI=true``), failed always when it is not the pinned one."""
    import pytest

    try:
        return reference_tests()
    except Corrupt as e:
        pytest.fail(str(e))
    except Unavailable as e:
        if os.environ.get("CI") == "true":
            pytest.fail(f"CI must run the Stable32 data-set tests: {e}")
        pytest.skip(str(e))
