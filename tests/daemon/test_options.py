"""One form of --channels for every command: ``x z`` and ``x,z`` both work everywhere."""

from __future__ import annotations

import pytest
from avard.core.errors import DataError
from avard.daemon.cli import build_parser
from avard.daemon.commands._options import split_channels


@pytest.mark.parametrize("words", [["x", "z"], ["x,z"], ["x,", "z"], ["x, z"]])
def test_both_spellings_give_the_same_channels(words: list[str]) -> None:
    assert split_channels(words) == ["x", "z"]


def test_no_channel_named_is_refused() -> None:
    assert split_channels(None) is None
    with pytest.raises(DataError, match="no channel"):
        split_channels([","])


@pytest.mark.parametrize("command", ["analyze", "explain"])
@pytest.mark.parametrize("form", [["x", "z"], ["x,z"]])
def test_every_command_with_channels_parses_both_forms(command: str, form: list[str]) -> None:
    args = build_parser(command).parse_args([command, "data.npz", "--channels", *form])
    assert split_channels(args.channels) == ["x", "z"]
