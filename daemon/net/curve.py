"""CURVE authentication for the PUB and request sockets: key files, server and client setup.

Keys are ZeroMQ certificate files as pyzmq writes them (``NAME.key`` holds the public key,
``NAME.key_secret`` the public and the secret key). The service needs its own secret file and a
directory of authorised client public keys; a client needs the server's public key and its own
secret file. Authorisation runs through ZAP (``zmq.auth.thread.ThreadAuthenticator``): a peer
whose public key is not in the directory completes no handshake and receives nothing.

Key material is never logged: log lines name files only, and pyzmq's authenticator (which logs
client keys at debug level) gets a logger held at WARNING.
"""

from __future__ import annotations

import datetime
import logging
import os
import stat
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import zmq
import zmq.auth
from avard.core.errors import ConfigError
from zmq.auth.thread import ThreadAuthenticator

log = logging.getLogger(__name__)

# pyzmq's authenticator logs client public keys at debug level; keep it above that.
_zap_log = logging.getLogger("avard.curve.zap")
_zap_log.setLevel(logging.WARNING)

_BANNER = (
    "#   ****  Generated on {now} by avard keys  ****\n"
    "#   ZeroMQ CURVE {what} Certificate\n"
    "{warning}\n"
)


def _write_cert(path: Path, public: bytes, secret: bytes | None, mode: int) -> None:
    """Write a certificate in pyzmq's format, created with ``mode`` from the first byte on.

    O_EXCL: never overwrite an existing key (a lost secret cannot be recovered).
    """
    what = "**Secret**" if secret else "Public"
    warning = (
        "#   DO NOT PROVIDE THIS FILE TO OTHER USERS nor change its permissions.\n"
        if secret else
        "#   Exchange securely, or use a secure mechanism to verify the contents\n"
        "#   of this file after exchange. Store public certificates in your home\n"
        "#   directory, in the .curve subdirectory.\n"
    )
    text = _BANNER.format(now=datetime.datetime.now(datetime.UTC).isoformat(), what=what,
                          warning=warning)
    text += "metadata\ncurve\n"
    text += f'    public-key = "{public.decode("ascii")}"\n'
    if secret:
        text += f'    secret-key = "{secret.decode("ascii")}"\n'
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, mode)
    except FileExistsError:
        raise ConfigError(
            f"{path} exists already; avard keys never overwrites a key (remove it or choose "
            "another --name)"
        ) from None
    with os.fdopen(fd, "w", encoding="ascii") as f:
        f.write(text)
    os.chmod(path, mode)  # umask may have narrowed it; make it exact


def make_keypair(out_dir: str | os.PathLike[str], name: str) -> tuple[Path, Path]:
    """Create ``NAME.key`` (public, 0644) and ``NAME.key_secret`` (0600) in ``out_dir``.

    The directory is created with mode 0700 when missing. Returns (public_path, secret_path).
    """
    if not name or "/" in name or name.startswith("."):
        raise ConfigError(f"key name {name!r} must be a plain file name such as 'server'")
    out = Path(out_dir)
    out.mkdir(mode=0o700, parents=True, exist_ok=True)
    public, secret = zmq.curve_keypair()
    pub_path, sec_path = out / f"{name}.key", out / f"{name}.key_secret"
    _write_cert(sec_path, public, secret, 0o600)
    _write_cert(pub_path, public, None, 0o644)
    log.info("wrote CURVE key pair %s / %s", pub_path, sec_path)
    return pub_path, sec_path


def load_public_key(path: str | os.PathLike[str]) -> bytes:
    """The Z85 public key of a certificate file (public or secret)."""
    try:
        public, _ = zmq.auth.load_certificate(path)
    except (OSError, ValueError) as exc:
        raise ConfigError(f"cannot read a CURVE public key from {path}: {exc}; make one with "
                          "`avard keys --out DIR`") from None
    return public


def load_secret_key(path: str | os.PathLike[str]) -> tuple[bytes, bytes]:
    """(public, secret) from a ``.key_secret`` file that only its owner can read."""
    p = Path(path)
    try:
        mode = p.stat().st_mode
    except OSError as exc:
        raise ConfigError(f"CURVE secret key file {p} is not readable ({exc.strerror}); make "
                          "one with `avard keys --out DIR`") from None
    try:
        public, secret = zmq.auth.load_certificate(p)
    except (OSError, ValueError) as exc:
        raise ConfigError(f"cannot read CURVE keys from {p}: {exc}") from None
    # what the file holds first: a public NAME.key given here is the wrong file, whatever
    # its mode (a chmod would not help)
    if not secret:
        raise ConfigError(f"{p} holds no secret key, only a public one; give the "
                          "NAME.key_secret file that `avard keys` wrote beside it")
    if mode & (stat.S_IRWXG | stat.S_IRWXO):
        raise ConfigError(
            f"CURVE secret key file {p} is readable by others (mode {stat.S_IMODE(mode):04o}); "
            f"run `chmod 600 {p}`"
        )
    return public, secret


@dataclass(frozen=True)
class CurveServerConfig:
    """The ``[curve]`` config section of the service (daemon/config.py).

    server_secret_key_file: the service's ``.key_secret`` file (mode 0600).
    authorized_keys_dir: directory of client public ``*.key`` files allowed to connect.
    """

    server_secret_key_file: Path
    authorized_keys_dir: Path

    @classmethod
    def from_mapping(cls, section: dict[str, Any]) -> CurveServerConfig:
        """Build from a parsed ``[curve]`` table; ConfigError names a missing key."""
        try:
            return cls(Path(section["server_secret_key_file"]),
                       Path(section["authorized_keys_dir"]))
        except KeyError as exc:
            raise ConfigError(
                f"[curve] needs the key {exc.args[0]!r} (see config/avard.toml)"
            ) from None

    @classmethod
    def from_config(cls, cfg: Any) -> CurveServerConfig | None:
        """The ``[curve]`` section of a validated config; None unless ``enabled = true``."""
        section = cfg.get("curve", {})
        if not section.get("enabled"):
            return None
        return cls.from_mapping(section)

    def check(self) -> None:
        """Refuse unreadable/unsafe secret keys and a missing or empty authorised directory."""
        load_secret_key(self.server_secret_key_file)
        d = self.authorized_keys_dir
        if not d.is_dir():
            raise ConfigError(f"[curve] authorized_keys_dir {d} is not a directory; make it "
                              "and put the clients' NAME.key files in it")
        if not any(d.glob("*.key")):
            log.warning("no authorised client keys (*.key) in %s: nobody can connect", d)


@dataclass(frozen=True)
class CurveClientConfig:
    """What a subscriber needs: the server's public key and its own secret key file."""

    server_public_key_file: Path
    client_secret_key_file: Path


class CurveServer:
    """A ZAP authenticator on one context plus the server keys, applied to server sockets."""

    def __init__(self, context: zmq.Context, config: CurveServerConfig) -> None:
        config.check()
        self.public, self._secret = load_secret_key(config.server_secret_key_file)
        self._auth = ThreadAuthenticator(context, log=_zap_log)
        self._auth.start()
        # loads every *.key in the directory now; call reload() after adding keys
        self._dir = config.authorized_keys_dir
        self._auth.configure_curve(domain="*", location=str(self._dir))
        log.info("CURVE on: server key from %s, client keys from %s",
                 config.server_secret_key_file, self._dir)

    def reload(self) -> None:
        """Re-read the authorised client keys (after adding or removing a file)."""
        self._auth.configure_curve(domain="*", location=str(self._dir))
        log.info("CURVE client keys reloaded from %s", self._dir)

    def apply(self, sock: zmq.Socket) -> None:
        """Make ``sock`` a CURVE server; call before bind."""
        sock.curve_secretkey = self._secret
        sock.curve_publickey = self.public
        sock.curve_server = True

    def stop(self) -> None:
        self._auth.stop()


def apply_client(sock: zmq.Socket, config: CurveClientConfig) -> None:
    """Make ``sock`` a CURVE client of the server whose public key is configured; before connect."""
    public, secret = load_secret_key(config.client_secret_key_file)
    sock.curve_serverkey = load_public_key(config.server_public_key_file)
    sock.curve_publickey = public
    sock.curve_secretkey = secret
