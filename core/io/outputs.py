"""Output paths checked before the work that fills them starts.

Every command that writes a file or a folder asks here first, so that a missing folder, a
folder it may not write, an unknown suffix or a missing ``plot`` extra is one clear line in the
first second, not a failure after an hour of analysis or simulation. Writability is tested by
creating (and at once removing) a hidden file in the folder: that is the one test that holds
for permissions, read-only mounts, ACLs and a process without CAP_DAC_OVERRIDE alike.
"""

from __future__ import annotations

import errno
import math
import os
import shutil
import tempfile
from collections.abc import Iterable, Sequence
from pathlib import Path

from avard.core.errors import OutputError, describe_os_error

__all__ = [
    "check_output_dir",
    "check_output_file",
    "check_outputs_apart",
    "check_plot_output",
    "free_bytes",
    "repeated_path",
    "require_plot_extra",
    "same_file",
]

#: Figure formats the Agg-based figures can always write (matplotlib's own list is larger,
#: but needs matplotlib imported; these are the ones the docs promise).
PLOT_SUFFIXES = (".png", ".pdf", ".svg")


def _probe_write(folder: Path, what: str) -> None:
    """Create and remove a hidden file in ``folder``; an OutputError saying why not."""
    try:
        fd, tmp = tempfile.mkstemp(prefix=".avard-write-check-", dir=folder)
    except OSError as exc:
        exc.filename = None  # the probe file's random name would only confuse
        raise OutputError(f"{what}: cannot write into folder {folder}: "
                          f"{describe_os_error(exc)}") from exc
    os.close(fd)
    os.unlink(tmp)


def _existing_ancestor(path: Path) -> Path:
    p = path.absolute()
    while not p.exists() and p != p.parent:
        p = p.parent
    return p


def check_output_file(path: str | os.PathLike[str], *, what: str,
                      suffixes: Iterable[str] | None = None) -> Path:
    """Check that ``path`` can be written as a file: a known suffix, an existing folder this
    process may write into, not a folder itself, and (when it exists) writable. ``what``
    names the option in messages (``"--plot lab.png"``)."""
    p = Path(path)
    allowed = tuple(s.lower() for s in suffixes) if suffixes is not None else None
    if allowed is not None and p.suffix.lower() not in allowed:
        raise OutputError(f"{what}: unknown suffix {p.suffix or '(none)'!r}; give a file "
                          f"ending in {', '.join(allowed)}")
    if p.is_dir():
        raise OutputError(f"{what}: {p} is a folder; give a file name in it (e.g. "
                          f"{p / ('out' + (allowed[0] if allowed else ''))})")
    folder = p.parent
    if not folder.exists():
        raise OutputError(f"{what}: folder {folder} does not exist; create it first "
                          f"(mkdir -p {folder})")
    if not folder.is_dir():
        raise OutputError(f"{what}: {folder} is a file, not a folder; check the path")
    if p.exists():
        try:
            with open(p, "r+b"):  # opens for writing without changing a byte
                pass
        except OSError as exc:
            raise OutputError(f"{what}: {describe_os_error(exc)}") from exc
    else:
        _probe_write(folder, what)
    return p


def same_file(a: str | os.PathLike[str], b: str | os.PathLike[str]) -> bool:
    """Whether two paths name one existing file (another spelling, a link): False where
    either is missing or unreadable, whose own read or write then says so."""
    try:
        return os.path.exists(a) and os.path.exists(b) and os.path.samefile(a, b)
    except OSError:
        return False


def repeated_path(paths: Sequence[str | os.PathLike[str]]
                  ) -> tuple[str | os.PathLike[str], str | os.PathLike[str]] | None:
    """The first two of ``paths`` that name one file (``same_file``), or None: one record
    given twice is no second sensor."""
    for i, a in enumerate(paths):
        for b in paths[i + 1:]:
            if same_file(a, b):
                return a, b
    return None


def check_outputs_apart(outputs: Iterable[tuple[str, str | os.PathLike[str]]],
                        inputs: Iterable[str | os.PathLike[str]]) -> None:
    """No output names a file read as input, and no two outputs name one file (``outputs``:
    (option as typed, path)). ``avard analyze data.csv --export csv data.csv`` replaced the
    record with its ADEV table, exit status 0; two exports to one path kept the last."""
    ins = [Path(i) for i in inputs]
    seen: list[tuple[str, Path]] = []
    for what, path in outputs:
        p = Path(path)
        for i in ins:
            if same_file(p, i) or p.absolute() == i.absolute():
                raise OutputError(f"{what}: {p} is the record read ({i}); writing it would "
                                  "replace the data: write the output to another file")
        for other, q in seen:
            if same_file(p, q) or p.absolute() == q.absolute():
                raise OutputError(f"{other} and {what} name one file; give each output its "
                                  "own file")
        seen.append((what, p))


def check_output_dir(path: str | os.PathLike[str], *, what: str, create: bool = False) -> Path:
    """Check that ``path`` is (or, with ``create``, can become) a folder this process may write
    into. Nothing is created here: the nearest existing folder is what is tested."""
    p = Path(path)
    if p.exists():
        if not p.is_dir():
            raise OutputError(f"{what}: {p} is a file; give a folder (it holds several "
                              "files), e.g. " + str(p.with_suffix("")))
        _probe_write(p, what)
        return p
    if not create:
        raise OutputError(f"{what}: folder {p} does not exist; create it first "
                          f"(mkdir -p {p})")
    base = _existing_ancestor(p)
    if not base.is_dir():
        raise OutputError(f"{what}: {base} is a file, so folder {p} cannot be made; check "
                          "the path")
    _probe_write(base, what)
    return p


def require_plot_extra(what: str) -> None:
    """An OutputError when matplotlib (the ``plot`` extra) cannot be imported."""
    try:
        import matplotlib  # noqa: F401
    except ImportError as exc:
        raise OutputError(f"{what} needs matplotlib, which is not installed: "
                          "pip install 'avard[plot]' (or leave the option out)") from exc


def check_plot_output(path: str | os.PathLike[str], *, what: str) -> Path:
    """A figure path: a known figure suffix, a writable folder and matplotlib importable."""
    p = check_output_file(path, what=what, suffixes=PLOT_SUFFIXES)
    require_plot_extra(what)
    return p


def free_bytes(path: str | os.PathLike[str]) -> int:
    """Bytes free to this user on the file system that holds ``path`` (or its nearest
    existing folder)."""
    base = _existing_ancestor(Path(path))
    try:
        return shutil.disk_usage(base).free
    except OSError as exc:  # pragma: no cover - a folder that vanished under us
        if exc.errno == errno.ENOENT:
            return 0
        raise


def finite_for_json(x: object) -> object:
    """``x`` (dicts, lists, numbers) with every non-finite float as None: what a ``--json``
    output prints (strict JSON has no NaN or infinity)."""
    if isinstance(x, dict):
        return {k: finite_for_json(v) for k, v in x.items()}
    if isinstance(x, list):
        return [finite_for_json(v) for v in x]
    if isinstance(x, float):
        return x if math.isfinite(x) else None
    return x
