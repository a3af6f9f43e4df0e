"""Options shared by several commands, so that each is spelled and read one way everywhere.

(A module whose name starts with ``_`` is not a command: ``avard.daemon.cli`` skips it.)
"""

from __future__ import annotations

import argparse

from avard.core.errors import DataError

CHANNELS_HELP = ("channels to use, by name or number: 'x z' or 'x,z' (default: all)")


def add_channels_argument(parser: argparse.ArgumentParser) -> None:
    """``--channels`` taking both forms the docs show: ``x z`` and ``x,z``."""
    parser.add_argument("--channels", nargs="+", metavar="NAME", help=CHANNELS_HELP)


def split_channels(values: list[str] | str | None) -> list[str] | None:
    """The channel names of ``--channels`` (``['x', 'z']`` from ``x z``, ``x,z`` or
    ``x, z``); None when the option was not given."""
    if values is None:
        return None
    words = [values] if isinstance(values, str) else values
    names = [n.strip() for w in words for n in w.split(",") if n.strip()]
    if not names:
        raise DataError("--channels: no channel named; give names or numbers such as 'x z' "
                        "or '0,2'")
    return names
