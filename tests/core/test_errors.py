"""describe_os_error: one line naming the file, what happened and what to do."""

from __future__ import annotations

import errno
import os
from pathlib import Path

import pytest
from avard.core.errors import AvardError, OutputError, describe_os_error
from avard.core.sim import sim_io
from avard.core.sim.presets import make_config


@pytest.mark.parametrize(("code", "advice"), [
    (errno.EACCES, "group avard"), (errno.ENOENT, "check the path"),
    (errno.ENOSPC, "free some space"), (errno.EROFS, "read-only"),
    (errno.EISDIR, "not a folder"), (errno.EIO, "dmesg"), (errno.ELOOP, "permissions"),
])
def test_each_error_names_the_file_and_what_to_do(code: int, advice: str) -> None:
    text = describe_os_error(OSError(code, os.strerror(code), "/data/run.npz"))
    assert text.startswith(f"/data/run.npz: {os.strerror(code)}; ")
    assert advice in text and "\n" not in text


def test_without_a_file_name_it_still_says_what_to_do() -> None:
    text = describe_os_error(OSError(errno.ENOSPC, os.strerror(errno.ENOSPC)))
    assert text == f"{os.strerror(errno.ENOSPC)}; free some space on that disk, or write " \
                   "somewhere else"


def test_output_error_is_an_avard_error() -> None:
    assert issubclass(OutputError, AvardError)


def test_a_full_disk_while_simulating_names_the_output_and_leaves_nothing(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    real = sim_io.iter_record_blocks

    def full_after_one_block(*args, **kwargs):
        blocks = real(*args, **kwargs)
        yield next(blocks)
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(sim_io, "iter_record_blocks", full_after_one_block)
    out = tmp_path / "r.npz"
    with pytest.raises(OutputError, match=rf"writing {out}: No space left.*free some space"):
        sim_io.write_npz(out, make_config("quiet-lab"), 0.01, seed=1, chunk=1000)
    assert list(tmp_path.iterdir()) == []
