"""core/outputs: output paths refused before any work, with the reason and the fix."""

from __future__ import annotations

from pathlib import Path

import pytest
from avard.core.errors import OutputError
from avard.core.io.outputs import check_output_dir, check_output_file, free_bytes


def test_a_good_file_path_passes_and_leaves_nothing_behind(tmp_path: Path) -> None:
    assert check_output_file(tmp_path / "a.png", what="--plot", suffixes=(".png",)) \
        == tmp_path / "a.png"
    assert list(tmp_path.iterdir()) == []     # the write probe removed its file


@pytest.mark.parametrize(("name", "message"), [
    ("a.jpgg", "unknown suffix '.jpgg'; give a file ending in .png, .pdf"),
    ("missing/a.png", "folder {tmp}/missing does not exist; create it first"),
    ("plain.txt/a.png", "is a file, not a folder"),
    ("folder.png", "is a folder; give a file name in it"),
])
def test_bad_file_paths_are_refused_with_the_reason(tmp_path: Path, name: str,
                                                    message: str) -> None:
    (tmp_path / "plain.txt").write_text("x")
    (tmp_path / "folder.png").mkdir()
    with pytest.raises(OutputError, match=r"^--plot x: ") as exc:
        check_output_file(tmp_path / name, what="--plot x", suffixes=(".png", ".pdf"))
    assert message.format(tmp=tmp_path) in str(exc.value)


def test_folders_exist_or_can_be_made(tmp_path: Path) -> None:
    assert check_output_dir(tmp_path, what="--out") == tmp_path
    new = tmp_path / "a" / "b"
    assert check_output_dir(new, what="--out", create=True) == new
    assert not (tmp_path / "a").exists()                  # checked, not created
    with pytest.raises(OutputError, match="does not exist"):
        check_output_dir(new, what="--out")
    (tmp_path / "f").write_text("x")
    with pytest.raises(OutputError, match="is a file; give a folder"):
        check_output_dir(tmp_path / "f", what="--out")
    with pytest.raises(OutputError, match="is a file, so folder"):
        check_output_dir(tmp_path / "f" / "sub", what="--out", create=True)


def test_free_bytes_of_a_path_not_yet_made(tmp_path: Path) -> None:
    import shutil

    # the nearest existing folder's file system (others write to it meanwhile: 1 GB slack)
    free = free_bytes(tmp_path / "not" / "yet")
    assert free > 0 and abs(free - shutil.disk_usage(tmp_path).free) < 1e9
