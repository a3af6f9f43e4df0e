"""One module per ``avard`` subcommand.

Each module defines ``NAME`` (the subcommand), ``HELP`` (one line), ``add_arguments(parser)``
and ``run(args) -> int``. ``avard.daemon.cli`` finds them here, so adding a command never
means editing a shared list.
"""
