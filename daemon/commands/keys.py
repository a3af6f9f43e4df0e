"""Make CURVE key pairs for the service and its subscribers.

Each NAME gives ``DIR/NAME.key`` (public, mode 0644: safe to copy) and ``DIR/NAME.key_secret``
(public + secret, mode 0600: stays where it is made). Existing files are never overwritten.
The secret keys are never printed or logged.

Typical use: ``avard keys --out /etc/avard/curve --name server`` on the Pi, ``avard keys --out
~/.avard --name laptop`` on each subscriber, then copy ``laptop.key`` into the service's
``authorized_keys_dir`` and ``server.key`` to the subscriber.
"""

from __future__ import annotations

import argparse
import sys

from avard.core.io.outputs import check_output_dir
from avard.daemon.net.curve import make_keypair

NAME = "keys"
HELP = "make CURVE key pairs (secret files 0600) for the service and its subscribers"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", required=True, metavar="DIR",
                        help="directory for the key files (created with mode 0700)")
    parser.add_argument("--name", action="append", metavar="NAME",
                        help="key pair name; repeat for several (default: server and client)")


def run(args: argparse.Namespace) -> int:
    names = args.name or ["server", "client"]
    check_output_dir(args.out, what=f"--out {args.out}", create=True)
    out = sys.stdout
    for name in names:
        public, secret = make_keypair(args.out, name)
        out.write(f"{name}: public {public}\n{' ' * len(name)}  secret {secret} (mode 0600)\n")
    out.write(
        "\nService ([curve] in the config):\n"
        "  enabled = true\n"
        f"  server_secret_key_file = \"{args.out}/{names[0]}.key_secret\"\n"
        "  authorized_keys_dir = \"/etc/avard/authorized_keys\"   # clients' NAME.key files\n"
        "Subscriber: avard watch/record ENDPOINT --server-key SERVER.key "
        "--client-key CLIENT.key_secret\n"
    )
    return 0
