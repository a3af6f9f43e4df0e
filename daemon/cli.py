"""The ``avard`` command line: finds the subcommands in ``avard.daemon.commands``.

Errors the user can fix become one clear line on stderr and exit status 2: every ``AvardError``
(bad data, config, output path, hardware, network) and every ``OSError`` a command did not turn
into one itself (permission, missing folder, full disk, read-only file system), named with its
file and what to do. Anything else is a bug and keeps its traceback.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import pkgutil
import sys
from collections.abc import Sequence
from typing import TextIO

# One BLAS thread unless the user asks for more: avard's matrix products are small (C×C sums
# of products, GLS fits), and a default thread pool on a loaded machine or a Pi's four slow
# cores made an analysis 8–33× slower. Set before the first numpy import of this process.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

from avard.core.errors import AvardError, describe_os_error  # noqa: E402  (after BLAS)
from avard.daemon import __version__, commands  # noqa: E402
from avard.daemon.service.logfmt import formatter_for  # noqa: E402
from avard.daemon.service.stop_signals import StopSignal  # noqa: E402

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
        # the description as written: its examples and lists keep their lines
        p = sub.add_parser(mod.NAME, help=help_text, description=mod.__doc__,
                           formatter_class=argparse.RawDescriptionHelpFormatter)
        if hasattr(mod, "add_arguments"):
            mod.add_arguments(p)
        p.set_defaults(_run=mod.run, _narrates=getattr(mod, "NARRATES", False))
    return parser


class _StderrHandler(logging.StreamHandler):
    """Writes to ``sys.stderr`` as it is when a line is logged, not as it was when logging
    was set up (as logging's own last-resort handler does): a handler bound to the stream of
    the moment kept writing to it after the caller replaced and closed it (an in-process
    ``main()`` under a test's capture left every later log line a 'Logging error')."""

    def __init__(self) -> None:
        logging.Handler.__init__(self)

    @property
    def stream(self) -> TextIO:  # type: ignore[override]
        return sys.stderr


def setup_logging(verbosity: int, narrates: bool = True) -> None:
    """Log to stderr in a form journald keeps: '<level-prefix>name: message', no timestamps
    (journald adds its own). INFO lines by default only for the commands that narrate (the
    service, web, record, simulate); the others print results and show INFO with -v, so
    log lines are not mixed into what they print.

    Idempotent: a second call replaces the handler the first one added and leaves every
    other handler of the root logger where it is (one ``main()`` after another in a process,
    a test's log capture)."""
    level = logging.WARNING - 10 * min(verbosity + (1 if narrates else 0), 2)
    handler = _StderrHandler()
    handler.setFormatter(formatter_for(sys.stderr))   # <N> priority prefixes for journald
    root = logging.getLogger()
    root.handlers[:] = [h for h in root.handlers if not isinstance(h, _StderrHandler)]
    root.addHandler(handler)
    root.setLevel(level)


def _fail(command: str, message: str, status: int = 2) -> int:
    """Print the one line the README promises (messages never span lines) and return
    ``status`` (2 unless the error says otherwise: see AvardError.exit_status)."""
    one_line = " ".join(message.split())
    print(f"avard {command}: error: {one_line}", file=sys.stderr)
    return status


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    # The first word that is not an option names the command; build only its parser.
    first = next((a for a in argv if not a.startswith("-")), None)
    parser = build_parser(first)
    args = parser.parse_args(argv)
    setup_logging(args.verbose, getattr(args, "_narrates", True))
    if not getattr(args, "_run", None):
        parser.print_help(sys.stderr)
        return 2
    try:
        return int(args._run(args) or 0)
    except AvardError as exc:
        return _fail(args.command, str(exc), exc.exit_status)
    except BrokenPipeError:
        # `avard analyze x.npz | head`: the reader left; end quietly, as cat does
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 141
    except OSError as exc:
        # Raised by the file system under any command (EACCES on a recording of the service's
        # group, ENOSPC, EROFS): the user's to fix, so one line, never a traceback.
        log.debug("OSError in %s", args.command, exc_info=True)
        return _fail(args.command, describe_os_error(exc))
    except KeyboardInterrupt:
        return 130
    except StopSignal as exc:  # SIGTERM/SIGHUP inside a command that unwinds on them
        print(f"avard {args.command}: {exc}", file=sys.stderr)
        return 128 + exc.signum


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
