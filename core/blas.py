"""One BLAS thread around avard's own computations, for programs that use the Python API.

Why: numpy's OpenBLAS starts a pool of one thread per core when numpy loads, and hands a dot
product of more than a few ten thousand elements to it. avard's sums of products are such
vectors (running-sum differences, lag-1 products of the noise identification) and C×C
matrices, for which the pool brings nothing on an idle machine and costs dearly on a busy one
(its workers busy-wait): on a loaded machine and on a Pi's four slow cores the default pool
made a four-statistic run 8.5–33 s instead of ~1 s (issue 12). The ``avard`` CLI and the
service set OPENBLAS_NUM_THREADS=1 before numpy loads; a program that imports avard.core has
loaded numpy already, so the library entry points hold the calling thread to one BLAS thread
with :func:`one_blas_thread` and give the setting back afterwards.

How, without a dependency (threadpoolctl does the same for many libraries): every OpenBLAS
loaded in the process (numpy's, scipy's) is found in /proc/self/maps and called through
ctypes. ``openblas_set_num_threads_local`` (OpenBLAS ≥ 0.3.27, numpy ≥ 2 wheels) sets the
count for the calling thread only, so the program's other threads keep their pool. An older
OpenBLAS has only the process-wide setting: it is set to one while any avard computation
runs and restored when the last one ends, which other threads see meanwhile. Other BLAS
libraries (MKL, Accelerate) and systems without /proc are left alone: ``active_backends()``
says what is held.
"""

from __future__ import annotations

import ctypes
import functools
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

__all__ = ["BlasLibrary", "active_backends", "one_blas_thread", "single_blas_thread"]

F = TypeVar("F", bound=Callable[..., Any])

# the global setters and getters under the names OpenBLAS builds export them
_GLOBAL_NAMES = [(f"{p}openblas_set_num_threads{s}", f"{p}openblas_get_num_threads{s}")
                 for p in ("", "scipy_") for s in ("", "64_", "_64")]


@dataclass(frozen=True)
class BlasLibrary:
    """One loaded OpenBLAS: its file, its pool size and its thread-count setter (``local``:
    for the calling thread only)."""

    path: str
    local: bool
    set_threads: Callable[[int], Any]
    get_threads: Callable[[], int]


_lock = threading.Lock()
_found: tuple[int, list[BlasLibrary]] | None = None  # (modules imported then, libraries)
_state = threading.local()  # depth of nested held avard computations in this thread
_global_users = 0  # threads inside an avard computation holding a process-wide setting
_global_saved: dict[str, int] = {}


def _open(path: str) -> BlasLibrary | None:
    try:
        lib = ctypes.CDLL(path)  # already mapped: this only takes a handle
    except OSError:
        return None
    for set_name, get_name in _GLOBAL_NAMES:
        setter, getter = getattr(lib, set_name, None), getattr(lib, get_name, None)
        if setter is None or getter is None:
            continue
        getter.argtypes, getter.restype = [], ctypes.c_int
        local = getattr(lib, "openblas_set_num_threads_local", None)
        if local is not None:
            local.argtypes, local.restype = [ctypes.c_int], ctypes.c_int
            return BlasLibrary(path, True, local, getter)
        setter.argtypes, setter.restype = [ctypes.c_int], None
        return BlasLibrary(path, False, setter, getter)
    return None


def active_backends() -> list[BlasLibrary]:
    """The OpenBLAS libraries loaded in this process that ``one_blas_thread`` holds, looked
    up again after an import (scipy brings its own; a shared library comes with a module)."""
    global _found
    imported = len(sys.modules)
    if _found is not None and _found[0] == imported:
        return _found[1]
    try:
        lines = Path("/proc/self/maps").read_text().splitlines()
    except OSError:
        lines = []
    with _lock:
        paths = sorted({ln.split(maxsplit=5)[5] for ln in lines
                        if "openblas" in ln.rsplit("/", 1)[-1].lower()
                        and len(ln.split(maxsplit=5)) == 6})
        libs = [lib for lib in map(_open, paths) if lib is not None]
        _found = (imported, libs)
        return libs


def _pooled() -> list[BlasLibrary]:
    """The libraries that would use more than one thread here (none under the CLI and the
    service, which start numpy with OPENBLAS_NUM_THREADS=1: then nothing is set at all)."""
    if getattr(_state, "depth", 0):
        return []  # an enclosing avard computation holds them already
    return [lib for lib in active_backends() if lib.get_threads() > 1]


def _hold(libs: list[BlasLibrary]) -> list[tuple[BlasLibrary, int]]:
    global _global_users
    saved = [(lib, int(lib.set_threads(1))) for lib in libs if lib.local]
    shared = [lib for lib in libs if not lib.local]
    if shared:
        with _lock:
            if _global_users == 0:
                for lib in shared:
                    _global_saved[lib.path] = int(lib.get_threads())
                    lib.set_threads(1)
            _global_users += 1
    _state.depth = 1
    return saved


def _release(libs: list[BlasLibrary], saved: list[tuple[BlasLibrary, int]]) -> None:
    global _global_users
    _state.depth = 0
    for lib, n in saved:
        lib.set_threads(n)
    if any(not lib.local for lib in libs):
        with _lock:
            _global_users -= 1
            if _global_users == 0:
                for lib in libs:
                    if not lib.local:
                        lib.set_threads(_global_saved.pop(lib.path, 1))


@contextmanager
def single_blas_thread() -> Iterator[None]:
    """Run the block with one BLAS thread in the calling thread; nested uses are free."""
    libs = _pooled()
    if not libs:
        yield
        return
    saved = _hold(libs)
    try:
        yield
    finally:
        _release(libs, saved)


def one_blas_thread(fn: F) -> F:
    """Decorator form of :func:`single_blas_thread` for avard's entry points (the same, without
    a generator's cost on the service's per-block calls)."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        libs = _pooled()
        if not libs:
            return fn(*args, **kwargs)
        saved = _hold(libs)
        try:
            return fn(*args, **kwargs)
        finally:
            _release(libs, saved)

    return wrapper  # type: ignore[return-value]
