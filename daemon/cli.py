"""The ``avard`` command line: finds the subcommands in ``avard.daemon.commands``.

Errors the user can fix (``AvardError``) become one clear line on stderr and exit status 2;
anything else is a bug and keeps its traceback.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import pkgutil
import sys
from collections.abc import Sequence

from avard.core.errors import AvardError

from . import __version__, commands
from .logfmt import formatter_for

log = logging.getLogger("avard")


def _module_names() -> list[str]:
    return sorted(
        i.name for i in pkgutil.iter_modules(commands.__path__) if not i.name.startswith("_")
    )


def _command_modules(only: str | None = None) -> list:
    """Import the command modules, or only the one ``only`` names (as typed, "check-config").

    Importing one command instead of all keeps ``avard run`` from paying for scipy and
    matplotlib imports that only the analysis commands need (seconds on a Raspberry Pi).
    """
    names = _module_names()
    if only is not None and only.replace("-", "_") in names:
        names = [only.replace("-", "_")]
    mods = []
    for name in names:
        mod = importlib.import_module(f"{commands.__name__}.{name}")
        if hasattr(mod, "NAME") and hasattr(mod, "run"):
            mods.append(mod)
    return mods


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="avard",
        description="ADXL355/DS18B20 acquisition with streaming Allan variance and noise analysis.",
    )
    parser.add_argument("--version", action="version", version=f"avard {__version__}")
    parser.add_argument(
        "-v", "--verbose", action="count", default=0, help="more log output (-vv for debug)"
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for mod in _command_modules(only):
        # HELP is plain text ("68 % intervals"); argparse would read its % as a format.
        help_text = getattr(mod, "HELP", None)
        if help_text is not None:
            help_text = help_text.replace("%", "%%")
        p = sub.add_parser(mod.NAME, help=help_text, description=mod.__doc__)
        if hasattr(mod, "add_arguments"):
            mod.add_arguments(p)
        p.set_defaults(_run=mod.run)
    return parser


def setup_logging(verbosity: int) -> None:
    """Log to stderr in a form journald keeps: '<level-prefix>name: message', no timestamps
    (journald adds its own)."""
    level = logging.WARNING - 10 * min(verbosity + 1, 2)
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(formatter_for(sys.stderr))   # <N> priority prefixes for journald
    root = logging.getLogger()
    root.handlers[:] = [handler]
    root.setLevel(level)


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    # The first word that is not an option names the command; build only its parser.
    first = next((a for a in argv if not a.startswith("-")), None)
    parser = build_parser(first)
    args = parser.parse_args(argv)
    setup_logging(args.verbose)
    if not getattr(args, "_run", None):
        parser.print_help(sys.stderr)
        return 2
    try:
        return int(args._run(args) or 0)
    except AvardError as exc:
        print(f"avard {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
