"""The service configuration: one schema (declared in config_types.py), TOML in, a checked nested
dict out.

Every key has a type, a default, a unit and what is allowed (a range or a set of choices).
Unknown sections or keys, wrong types and out-of-range values are refused *before* anything
starts, with the key's name, the value found and what is allowed, all problems at once
(:class:`ConfigError`). ``avard check-config FILE`` runs exactly this.

Paths the service writes (the data directory) must lie under an allowed root: the systemd
state directory (``$STATE_DIRECTORY``), /var/lib/avard, the user's home, the system temporary
directory or the current directory, each resolved (symlinks followed) and never / or a system
directory such as /etc (a service started from / or with HOME=/ gets no such root). This keeps
a typo or a hostile config from pointing the recorder (which deletes old segments for
retention) at /etc or /.

Files are read only when they are regular files, and only up to a size limit: a FIFO, a
device (/dev/zero) or a directory named as the config or a key file is refused at once
instead of hanging or exhausting memory. A UTF-8 byte-order mark is accepted.

:func:`check_runtime` adds what depends on the machine (the data directory writable, the
CURVE key files and their modes, the authorised-keys directory). ``avard check-config`` and
``avard run`` call the same two functions, so a config that passes check-config starts.
"""

from __future__ import annotations

import ipaddress
import math
import os
import re
import stat
import tempfile
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from avard.core.errors import ConfigError
from avard.daemon.config_types import ODR_CHOICES, Key, schema

__all__ = ["ODR_CHOICES", "SCHEMA", "Key", "load_config", "validate_config"]

#: The keys, read off the typed dataclasses of daemon/config_types.py (declared once there).
SCHEMA: dict[str, dict[str, Key]] = schema()


#: Largest config file read (bytes): a real one is a few kB.
MAX_CONFIG_BYTES = 1 << 20
#: Largest CURVE key file read (bytes): a real one is about 300 bytes.
MAX_KEY_FILE_BYTES = 64 << 10
#: Ring memory per sample (bytes): int32 counts × 3, int64 index, float64 time
#: (daemon/service/ring.py).
RING_BYTES_PER_SAMPLE = 3 * 4 + 8 + 8
#: The ring may take at most this share of the machine's physical memory.
RING_MEMORY_SHARE = 0.25
#: Never an allowed root for data_dir, even as the current directory or $HOME.
SYSTEM_DIRS = frozenset(Path(p) for p in ("/", "/bin", "/boot", "/dev", "/etc", "/lib",
                                          "/lib64", "/proc", "/run", "/sbin", "/sys", "/usr",
                                          "/var"))
_SENSOR_NAME = re.compile(r"[A-Za-z0-9_.-]{1,32}")
_DS18B20_ID = re.compile(r"(28-)?[0-9a-fA-F]{12}")


def read_regular_file(path: str | Path, what: str, limit: int) -> bytes:
    """The bytes of ``path`` if it is a regular file of at most ``limit`` bytes.

    Opened non-blocking and checked with fstat before reading, so a FIFO (which would block
    the open or the read forever), a device such as /dev/zero (endless) or a directory is
    refused with one line instead of hanging or exhausting memory."""
    p = Path(path)
    try:
        fd = os.open(p, os.O_RDONLY | os.O_NONBLOCK | os.O_NOCTTY | os.O_CLOEXEC)
    except FileNotFoundError:
        raise ConfigError(f"{p}: no such {what}") from None
    except OSError as exc:
        raise ConfigError(f"{p}: cannot read the {what} ({exc.strerror}); check its "
                          "permissions") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            kind = ("a directory" if stat.S_ISDIR(st.st_mode) else
                    "a FIFO" if stat.S_ISFIFO(st.st_mode) else
                    "a device" if stat.S_ISCHR(st.st_mode) or stat.S_ISBLK(st.st_mode) else
                    "a socket" if stat.S_ISSOCK(st.st_mode) else "not a file")
            raise ConfigError(f"{p}: the {what} is {kind}, not a regular file; name the file "
                              "itself")
        if st.st_size > limit:
            raise ConfigError(f"{p}: the {what} is {st.st_size} bytes, more than the "
                              f"{limit}-byte limit; is this the right file?")
        parts: list[bytes] = []
        got = 0
        while got <= limit:
            chunk = os.read(fd, limit + 1 - got)
            if not chunk:
                break
            parts.append(chunk)
            got += len(chunk)
        if got > limit:   # grew while we read it
            raise ConfigError(f"{p}: the {what} is more than the {limit}-byte limit")
        return b"".join(parts)
    except OSError as exc:
        raise ConfigError(f"{p}: cannot read the {what} ({exc.strerror})") from None
    finally:
        os.close(fd)


def machine_memory_bytes() -> int | None:
    """Physical memory of this machine (bytes), None when unknown."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return None


def ring_bytes(cfg: Mapping[str, Any]) -> int:
    """Memory of the ring buffer for this config (bytes); the service sizes it the same way."""
    sensors = cfg.get("sensors") or [cfg["sensor"]]
    return sum((int(cfg["service"]["ring_s"] * float(s["odr_hz"]) * 1.1) + 64)
               * RING_BYTES_PER_SAMPLE for s in sensors)


def default_config() -> dict[str, dict[str, Any]]:
    """Every key at its default value."""
    return {sec: {k: _copy(key.default) for k, key in keys.items()}
            for sec, keys in SCHEMA.items()}


def _copy(v: Any) -> Any:
    return list(v) if isinstance(v, list) else v


def allowed_roots() -> list[Path]:
    """Directories under which the service may write."""
    roots = [Path("/var/lib/avard"), Path(tempfile.gettempdir()), Path.cwd()]
    if os.environ.get("STATE_DIRECTORY"):
        roots += [Path(p) for p in os.environ["STATE_DIRECTORY"].split(":") if p]
    if os.environ.get("HOME"):
        roots.append(Path(os.environ["HOME"]))
    out: list[Path] = []
    for r in roots:
        try:
            resolved = r.resolve()
        except (OSError, RuntimeError, ValueError):
            continue
        # a service started from / or with HOME=/ must not make all of / writable
        if resolved not in SYSTEM_DIRS and resolved not in out:
            out.append(resolved)
    return out


def _check_value(name: str, key: Key, value: Any) -> tuple[Any, str | None]:
    types = key.type if isinstance(key.type, tuple) else (key.type,)
    # TOML booleans are not numbers here, whatever Python thinks of bool ⊂ int.
    ok = isinstance(value, types) and not (isinstance(value, bool) and bool not in types)
    if not ok:
        return value, f"{name} = {value!r}: wrong type, allowed is {key.allowed()}"
    if list in types:
        if not all(isinstance(v, str) for v in value):
            return value, f"{name} = {value!r}: allowed is {key.allowed()}"
        return list(value), None
    if isinstance(value, float) and not math.isfinite(value):
        # TOML has nan and inf; every comparison with NaN is False, so the range check below
        # would let it through
        return value, f"{name} = {value!r}: not a finite number, allowed is {key.allowed()}"
    if float in types:
        try:
            value = float(value)
        except OverflowError:  # TOML integers are unbounded
            return value, (f"{name}: an integer of {value.bit_length()} bits is too large, "
                           f"allowed is {key.allowed()}")
    if key.choices is not None and value not in key.choices:
        return value, f"{name} = {value!r}: out of range, allowed is {key.allowed()}"
    if (key.lo is not None and value < key.lo) or (key.hi is not None and value > key.hi):
        return value, f"{name} = {value!r}: out of range, allowed is {key.allowed()}"
    if key.path and value:
        try:
            resolved = Path(value).expanduser().resolve()
        except (ValueError, RuntimeError, OSError) as exc:  # NUL byte, ~nosuchuser, loops
            return value, (f"{name} = {value!r}: not a usable path ({exc}); name a directory "
                           "such as /var/lib/avard")
        roots = allowed_roots()
        if not any(resolved == r or r in resolved.parents for r in roots):
            return value, (f"{name} = {value!r}: not under an allowed directory "
                           f"({', '.join(str(r) for r in roots)}); choose a path below one "
                           "of them (systemd: StateDirectory=)")
        value = str(resolved)
    return value, None


def _check_endpoints(cfg: dict[str, dict[str, Any]], problems: list[str]) -> None:
    pub = cfg["publish"]
    for key in ("endpoint", "request_endpoint"):
        ep = pub[key]
        try:
            parts = urlsplit(ep)
            parts.hostname  # noqa: B018  (raises ValueError for a malformed [IPv6] host)
        except ValueError as exc:
            problems.append(f"publish.{key} = {ep!r}: not a valid endpoint ({exc}); write "
                            "tcp://HOST:PORT")
            continue
        if parts.scheme not in ("tcp", "ipc", "inproc"):
            problems.append(f"publish.{key} = {ep!r}: allowed is a ZeroMQ endpoint "
                            "tcp://HOST:PORT, ipc://PATH or inproc://NAME")
            continue
        if parts.scheme != "tcp":
            continue
        host = parts.hostname or ""
        port_text = parts.netloc.rpartition(":")[2]
        # "*" or 0: an ephemeral port chosen at bind time (tests, several instances)
        if not (port_text == "*" or (port_text.isdigit() and int(port_text) < 65536)):
            problems.append(f"publish.{key} = {ep!r}: a tcp endpoint needs a port "
                            "(tcp://127.0.0.1:5555)")
        if host in ("localhost",):
            continue
        try:
            loopback = ipaddress.ip_address(host).is_loopback
        except ValueError:
            loopback = False
        if not loopback and not pub["allow_remote"]:
            problems.append(f"publish.{key} = {ep!r}: binds beyond loopback; set "
                            "publish.allow_remote = true to do that on purpose (and consider "
                            "[curve] enabled = true)")
    if pub["endpoint"] == pub["request_endpoint"] and not pub["endpoint"].endswith((":0", ":*")):
        problems.append("publish.endpoint and publish.request_endpoint are the same; "
                        "give the request socket its own port")
    if cfg["curve"]["enabled"]:
        for key in ("server_secret_key_file", "authorized_keys_dir"):
            if not cfg["curve"][key]:
                problems.append(f"curve.{key} is empty: with curve.enabled = true it must "
                                "name the file/directory made by `avard keys`")


def validate_config(raw: Mapping[str, Any], source: str = "config") -> dict[str, Any]:
    """Merge ``raw`` over the defaults and check every key; ConfigError lists all problems."""
    cfg: dict[str, Any] = default_config()
    problems: list[str] = []
    entries: list[dict[str, Any]] | None = None
    for sec, table in raw.items():
        if sec == "sensor" and isinstance(table, list):
            entries = _check_sensor_entries(table, problems)
            continue
        if sec not in SCHEMA:
            problems.append(f"[{sec}]: unknown section; known sections are "
                            f"{', '.join(SCHEMA)}")
            continue
        if not isinstance(table, Mapping):
            problems.append(f"{sec} = {table!r}: must be a [{sec}] table")
            continue
        _check_table(sec, f"[{sec}]", table, cfg[sec], problems)
    if entries:
        cfg["sensor"] = entries[0]
        cfg["sensors"] = entries
    else:
        _check_sensor_name("sensor.name", cfg["sensor"]["name"], problems)
    for sid in cfg["temperature"]["ids"]:
        if not _DS18B20_ID.fullmatch(sid):
            problems.append(f"temperature.ids: {sid!r} is not a DS18B20 id; write ids like "
                            "'28-0316a2797cff' (as under /sys/bus/w1/devices)")
    if not problems:
        _check_endpoints(cfg, problems)
        need, have = ring_bytes(cfg), machine_memory_bytes()
        if have and need > RING_MEMORY_SHARE * have:
            most = RING_MEMORY_SHARE * have / RING_BYTES_PER_SAMPLE / 1.1 / cfg["sensor"][
                "odr_hz"]
            problems.append(f"service.ring_s = {cfg['service']['ring_s']:g}: at "
                            f"{cfg['sensor']['odr_hz']:g} Hz the ring takes {need / 2**20:.0f} "
                            f"MiB, more than {RING_MEMORY_SHARE:.0%} of this machine's "
                            f"{have / 2**20:.0f} MiB; use ring_s ≤ {math.floor(most):d}")
        if cfg["recording"]["enabled"] and not cfg["recording"]["data_dir"]:
            problems.append("recording.data_dir is empty: name a directory or set "
                            "recording.enabled = false")
    if problems:
        raise ConfigError(f"{source}: " + "; ".join(problems))
    return cfg


def _check_table(label: str, title: str, table: Mapping[str, Any], into: dict[str, Any],
                 problems: list[str], *, section: str | None = None) -> None:
    """Each key of ``table`` checked against ``SCHEMA[section or label]``; the checked values
    go into ``into``, the problems (named ``label.key``) into ``problems``."""
    keys = SCHEMA[section or label]
    for name, value in table.items():
        key = keys.get(name)
        if key is None:
            problems.append(f"{label}.{name}: unknown key; known keys in {title} are "
                            f"{', '.join(keys)}")
            continue
        checked, problem = _check_value(f"{label}.{name}", key, value)
        if problem:
            problems.append(problem)
        else:
            into[name] = checked


def _check_sensor_name(where: str, name: str, problems: list[str]) -> None:
    # the name is a directory of a several-sensor recording and part of a topic: no '.', '..'
    if not _SENSOR_NAME.fullmatch(name) or name in (".", ".."):
        problems.append(f"{where} = {name!r}: use 1 to 32 letters, digits, '-', '_' or '.' "
                        "(not '.' or '..')")


def _check_sensor_entries(tables: list[Any], problems: list[str]) -> list[dict[str, Any]]:
    """The ``[[sensor]]`` entries, each checked like a ``[sensor]`` table over the defaults;
    names and wiring are then checked together by the rig's one rule (``RigSpec``): no two
    sensors with one name, one chip select or one I2C address."""
    keys = SCHEMA["sensor"]
    out: list[dict[str, Any]] = []
    for n, table in enumerate(tables, 1):
        if not isinstance(table, Mapping):
            problems.append(f"sensor #{n} = {table!r}: each [[sensor]] must be a table")
            continue
        entry = {k: _copy(key.default) for k, key in keys.items()}
        label = f"sensor #{n}"
        _check_table(label, "[[sensor]]", table, entry, problems, section="sensor")
        if "name" not in table and len(tables) > 1:
            problems.append(f"{label}: several sensors need a name each (name = \"left\")")
        _check_sensor_name(f"{label}.name", entry["name"], problems)
        out.append(entry)
    if not tables:
        problems.append("[[sensor]]: no entries; give at least one sensor")
    elif len(out) == len(tables):
        from avard.daemon.config_types import SensorConfig
        from avard.daemon.hw.rig import RigSpec, SensorSpec

        try:
            RigSpec(tuple(SensorSpec.from_config(SensorConfig(**e)) for e in out))
        except ConfigError as exc:
            problems.append(str(exc))
    return out


def load_config(path: str | Path | None, **overrides: Any) -> dict[str, Any]:
    """Read and check a TOML config file (None: the defaults), then apply dotted overrides
    such as ``{"recording.data_dir": "/tmp/x"}`` (checked like the file's own keys)."""
    raw: dict[str, Any] = {}
    source = "defaults"
    if path is not None:
        p = Path(path)
        source = str(p)
        data = read_regular_file(p, "config file", MAX_CONFIG_BYTES)
        try:
            text = data.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise ConfigError(f"{p}: not UTF-8 text (bad byte at offset {exc.start}); save "
                              "the file as UTF-8") from None
        text = text.removeprefix("\ufeff")   # a byte-order mark (Windows editors) is harmless
        try:
            raw = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise ConfigError(f"{p}: not valid TOML ({exc}); fix the syntax at that "
                              "line") from None
        except RecursionError:  # tomllib recurses once per nested array or inline table
            raise ConfigError(f"{p}: values nested too deeply for a config file; fix the "
                              "file") from None
        except ValueError as exc:  # e.g. an integer beyond Python's 4300-digit str limit
            raise ConfigError(f"{p}: a value cannot be read ({exc}); fix the file") from None
    for dotted, value in overrides.items():
        if value is None:
            continue
        sec, _, name = dotted.partition(".")
        raw.setdefault(sec, {})
        if isinstance(raw[sec], dict):
            raw[sec][name] = value
    return validate_config(raw, source)


def effective_poll_hz(cfg: Mapping[str, Mapping[str, Any]]) -> float:
    """The FIFO drain rate at the nominal ODR (daemon/hw/pacing.py; the reader uses the fitted
    one): the configured least rate, raised to drain the 32-set FIFO when half full."""
    from avard.daemon.hw.pacing import drain_period_s

    return 1.0 / drain_period_s(float(cfg["sensor"]["odr_hz"]), float(cfg["sensor"]["poll_hz"]))


# --------------------------------------------------------------------------------------------
# what depends on this machine: checked by both `avard check-config` and `avard run`


#: What to do about a data directory the service cannot write (check_runtime and the service).
DATA_DIR_ADVICE = ("under systemd StateDirectory= provides it, by hand use --data-dir DIR or "
                   "`sudo install -d -o $USER /var/lib/avard`")


#: Folders that belong to the system: created by systemd (StateDirectory=) or an installer,
#: never as a side effect of trying the service by hand.
SYSTEM_PREFIXES = ("/var/", "/etc/", "/usr/", "/opt/", "/srv/", "/run/")


def check_runtime(cfg: Mapping[str, Mapping[str, Any]],
                  environ: Mapping[str, str] = os.environ) -> None:
    """Check what ``avard run`` needs from the machine, all problems at once (ConfigError):
    the data directory writable (or creatable; a missing system folder only when systemd
    starts us, which sets $INVOCATION_ID for every unit it runs and whose StateDirectory=
    makes it), and with CURVE on the server's secret key file (a regular file only its owner
    can read, holding a secret key, not a public one) and the authorised-keys directory (a
    directory of regular ``*.key`` files). ``avard run`` and ``avard check-config`` both call
    this, so a config that passes check-config starts."""
    problems: list[str] = []
    rec = cfg["recording"]
    data_dir = str(rec["data_dir"])
    if (rec["enabled"] and not os.path.exists(data_dir)
            and data_dir.startswith(SYSTEM_PREFIXES) and not environ.get("INVOCATION_ID")):
        problems.append(
            f"recording.data_dir {data_dir} does not exist and avard run does not create "
            "system folders unless systemd starts it (StateDirectory= makes it); by hand, "
            "record elsewhere with --data-dir DIR, or create it first")
    elif rec["enabled"]:
        problem = _writable_dir(Path(rec["data_dir"]))
        if problem:
            problems.append(f"recording.data_dir = {rec['data_dir']!r}: {problem}; "
                            + DATA_DIR_ADVICE)
    if cfg["curve"]["enabled"]:
        problems += _curve_problems(cfg["curve"])
    if problems:
        raise ConfigError("; ".join(problems))


def _writable_dir(d: Path) -> str | None:
    """None when the service can create and write ``d``, else why not."""
    probe = d
    while not probe.exists():
        if probe.parent == probe:
            return "no existing parent directory"
        probe = probe.parent
    if not probe.is_dir():
        return f"{probe} is not a directory"
    if not os.access(probe, os.W_OK | os.X_OK):
        what = "it" if probe == d else f"its parent {probe}"
        return f"{what} is not writable by this user"
    return None


def _curve_problems(curve: Mapping[str, Any]) -> list[str]:
    problems: list[str] = []
    key = Path(curve["server_secret_key_file"])
    try:
        data = read_regular_file(key, "CURVE secret key file", MAX_KEY_FILE_BYTES)
        mode = stat.S_IMODE(key.stat().st_mode)
        if not re.search(rb"^\s*secret-key\s*=", data, re.MULTILINE):
            problems.append(f"curve.server_secret_key_file {key} holds no secret key (a public "
                            ".key file?); name the NAME.key_secret file made by `avard keys`")
        elif mode & (stat.S_IRWXG | stat.S_IRWXO):
            problems.append(f"curve.server_secret_key_file {key} is readable by others "
                            f"(mode {mode:04o}); run `chmod 600 {key}`")
    except ConfigError as exc:
        problems.append(f"curve.server_secret_key_file: {exc}")
    except OSError as exc:
        problems.append(f"curve.server_secret_key_file {key}: {exc.strerror}")
    d = Path(curve["authorized_keys_dir"])
    if not d.is_dir():
        problems.append(f"curve.authorized_keys_dir {d} is not a directory; make it and put the "
                        "clients' NAME.key files in it")
    else:
        for f in sorted(d.glob("*.key")):
            try:
                read_regular_file(f, "client public key file", MAX_KEY_FILE_BYTES)
            except ConfigError as exc:
                problems.append(f"curve.authorized_keys_dir: {exc}")
    return problems


# --------------------------------------------------------------------------------------------
# command-line numbers shared by run and simulate


def check_seed(seed: int | None) -> None:
    """A simulator seed: a non-negative integer (numpy's seed sequences take no others)."""
    if seed is not None and not 0 <= seed < 2**64:
        raise ConfigError(f"--seed {seed}: must be an integer from 0 to 2**64 - 1")


def check_positive_seconds(flag: str, value: float | None) -> None:
    """A duration on the command line: a finite number > 0."""
    if value is not None and not (math.isfinite(value) and value > 0):
        raise ConfigError(f"{flag} {value}: must be a finite number > 0")
