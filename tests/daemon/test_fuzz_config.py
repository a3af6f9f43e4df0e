"""Hostile config files against the config loader (avard.daemon.config): hypothesis fuzzing.

Whatever a config file holds (unknown sections and keys, wrong types, NaN and infinities,
integers of 400 digits, NUL bytes, deep nesting, bytes that are not UTF-8, a directory instead
of a file, write paths outside the allowed directories or escaping them through ``..`` and
symlinks) the loader either returns a config whose every value has its schema type and range,
or raises ConfigError naming the key. Nothing else escapes and nothing starts.
"""

from __future__ import annotations

import json
import math
import os
import tomllib
from pathlib import Path
from typing import Any

import pytest
from avard.core.errors import ConfigError
from avard.daemon import config as C
from hypothesis import given
from hypothesis import strategies as st

from .test_fuzz_frames import fuzz_settings, make_counter, mutated, save_counts

REPO = Path(__file__).resolve().parents[2]
SHIPPED = (REPO / "config" / "avard.toml").read_bytes()


@pytest.fixture(scope="module")
def counter(request):
    c = make_counter(request)
    yield c
    save_counts(request, c)


# -------------------------------------------------------------------------- a tiny TOML writer


def _toml_str(s: str) -> str:
    # JSON string escapes are TOML basic-string escapes; TOML also wants DEL escaped.
    return json.dumps(s, ensure_ascii=False).replace("\x7f", "\\u007f")


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return _toml_str(v)
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{_toml_str(k)} = {_toml_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(type(v))


def to_toml(doc: dict[str, Any]) -> str:
    """Top-level non-tables first (TOML requires it), then one [table] per dict."""
    lines = [f"{_toml_str(k)} = {_toml_value(v)}" for k, v in doc.items()
             if not isinstance(v, dict)]
    for sec, table in doc.items():
        if isinstance(table, dict):
            lines.append(f"[{_toml_str(sec)}]")
            lines += [f"{_toml_str(k)} = {_toml_value(v)}" for k, v in table.items()]
    return "\n".join(lines) + "\n"


# -------------------------------------------------------------------------- strategies

_toml_ints = st.one_of(st.integers(-(2**63), 2**63 - 1), st.sampled_from([0, 1, -1, 2**31]))
_scalars = st.one_of(
    st.booleans(), _toml_ints, st.floats(), st.text(max_size=30),
    st.sampled_from(["", "/", "/etc", "../../etc", "\x00", "~nouser/x", "tcp://[::1:5",
                     "tcp://0.0.0.0:5555", "tcp://127.0.0.1:*", "ipc:///tmp/x", "spi", "i2c",
                     "tcp://127.0.0.1:99999999999"]),
)
toml_values = st.recursive(
    _scalars,
    lambda children: st.one_of(st.lists(children, max_size=4),
                               st.dictionaries(st.text(max_size=6), children, max_size=4)),
    max_leaves=12,
)
_section_names = st.one_of(st.sampled_from(sorted(C.SCHEMA)), st.text(max_size=8))


@st.composite
def schema_values(draw) -> tuple[str, str, Any]:
    """A real key with a value near its type and range, or of another type entirely."""
    sec = draw(st.sampled_from(sorted(C.SCHEMA)))
    name = draw(st.sampled_from(sorted(C.SCHEMA[sec])))
    key = C.SCHEMA[sec][name]
    near: list[Any] = [key.default]
    if key.lo is not None:
        near += [key.lo, key.lo - 1, math.nextafter(float(key.lo), -math.inf)]
    if key.hi is not None:
        near += [key.hi, key.hi + 1, float(key.hi) * 10]
    if key.choices:
        near += list(key.choices)
    value = draw(st.one_of(st.sampled_from(near), toml_values,
                           st.sampled_from([math.nan, math.inf, -math.inf, 10**400, -(10**400)])))
    return sec, name, value


@st.composite
def config_docs(draw) -> dict[str, Any]:
    doc: dict[str, Any] = {}
    for sec, name, value in draw(st.lists(schema_values(), max_size=6)):
        doc.setdefault(sec, {})[name] = value
    if draw(st.booleans()):
        doc.update(draw(st.dictionaries(_section_names, toml_values, max_size=3)))
    return doc


# -------------------------------------------------------------------------- checking


def _check_valid(cfg: dict[str, dict[str, Any]]) -> None:
    """A config that was accepted obeys the schema, key by key."""
    assert set(cfg) == set(C.SCHEMA)
    roots = C.allowed_roots()
    for sec, keys in C.SCHEMA.items():
        assert set(cfg[sec]) == set(keys)
        for name, key in keys.items():
            value = cfg[sec][name]
            types = key.type if isinstance(key.type, tuple) else (key.type,)
            assert isinstance(value, types), (sec, name, value)
            if isinstance(value, bool):
                assert bool in types
            if isinstance(value, float):
                assert math.isfinite(value), f"{sec}.{name} = {value} accepted"
            if key.choices is not None:
                assert value in key.choices
            if key.lo is not None:
                assert value >= key.lo
            if key.hi is not None:
                assert value <= key.hi
            if key.path and value:
                p = Path(value)
                assert any(p == r or r in p.parents for r in roots), value


def _outcome(fn, *args: Any) -> Any:
    try:
        return fn(*args)
    except ConfigError as exc:
        message = str(exc)
        assert 10 <= len(message) <= 20_000, f"error message of {len(message)} characters"
        return exc


# -------------------------------------------------------------------------- the fuzzing


@fuzz_settings(200)
@given(doc=config_docs())
def test_validate_config_on_hostile_tables(counter, doc):
    counter.tick("config.validate_config")
    out = _outcome(C.validate_config, doc)
    if isinstance(out, ConfigError):
        # the message names at least one offending section or key
        named = {f"{s}.{k}" for s, t in doc.items() if isinstance(t, dict) for k in t}
        named |= {str(s) for s in doc}
        assert any(n in str(out) for n in named), str(out)
    else:
        _check_valid(out)


@fuzz_settings(100)
@given(doc=config_docs())
def test_load_config_from_toml_text(counter, tmp_path_factory, doc):
    counter.tick("config.load_config")
    text = to_toml(doc)
    path = tmp_path_factory.mktemp("cfg") / "avard.toml"
    path.write_text(text, encoding="utf-8")
    out = _outcome(C.load_config, path)
    if not isinstance(out, ConfigError):
        _check_valid(out)


@fuzz_settings(150)
@given(data=mutated(st.just(SHIPPED)))
def test_load_config_from_damaged_shipped_file(counter, tmp_path_factory, data):
    _load_bytes(counter, tmp_path_factory, data)


@fuzz_settings(200)
@given(data=st.binary(max_size=512))
def test_load_config_from_random_bytes(counter, tmp_path_factory, data):
    _load_bytes(counter, tmp_path_factory, data)


def _load_bytes(counter, tmp_path_factory, data: bytes) -> None:
    """Write ``data`` as a config file and load it: a ConfigError or a valid config."""
    counter.tick("config.load_config")
    path = tmp_path_factory.mktemp("cfg") / "avard.toml"
    path.write_bytes(data)
    out = _outcome(C.load_config, path)
    if not isinstance(out, ConfigError):
        _check_valid(out)


def test_shipped_config_loads_and_equals_the_defaults(counter):
    counter.tick("config.load_config")
    assert C.load_config(REPO / "config" / "avard.toml") == C.load_config(None)


@pytest.mark.parametrize("depth", [50, 5000, 200_000])
def test_deeply_nested_toml_is_refused_not_a_recursion_error(counter, tmp_path, depth):
    counter.tick("config.load_config")
    path = tmp_path / "deep.toml"
    path.write_text("[sensor]\nbus = " + "[" * depth + "1" + "]" * depth + "\n")
    with pytest.raises(ConfigError, match=r"sensor|nested"):
        C.load_config(path)


def test_file_that_is_not_utf8_a_directory_or_unreadable(counter, tmp_path):
    counter.tick("config.load_config", 3)
    latin = tmp_path / "latin1.toml"
    latin.write_bytes(b"[sensor]\nbus = \"sp\xefi\"\n")
    with pytest.raises(ConfigError, match="UTF-8"):
        C.load_config(latin)
    with pytest.raises(ConfigError, match="directory"):
        C.load_config(tmp_path)
    locked = tmp_path / "locked.toml"
    locked.write_text("[sensor]\n")
    locked.chmod(0)
    if os.geteuid() != 0:  # root reads anything
        with pytest.raises(ConfigError, match=r"permission|read"):
            C.load_config(locked)


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf])
@pytest.mark.parametrize(("section", "name"), [("sensor", "poll_hz"),
                                               ("recording", "fsync_interval_s"),
                                               ("allan", "snapshot_interval_s")])
def test_non_finite_numbers_are_refused(counter, section, name, value):
    counter.tick("config.validate_config")
    with pytest.raises(ConfigError, match=f"{section}.{name}"):
        C.validate_config({section: {name: value}})


def test_integers_too_large_for_a_float_are_refused(counter):
    counter.tick("config.validate_config")
    with pytest.raises(ConfigError, match=r"recording\.segment_s"):
        C.validate_config({"recording": {"segment_s": 10**400}})


def test_integer_literal_beyond_pythons_digit_limit_is_refused(counter, tmp_path):
    counter.tick("config.load_config")
    path = tmp_path / "big.toml"
    path.write_text("[sensor]\nspi_bus = 1" + "0" * 5000 + "\n")
    with pytest.raises(ConfigError, match="cannot be read"):
        C.load_config(path)


@pytest.mark.parametrize("path", ["/", "/etc", "/etc/avard", "/var/lib/avard/../../etc",
                                  "/usr/lib/avard", "\x00", "~nouser/data"])
def test_write_paths_outside_the_allowed_directories_are_refused(counter, path):
    counter.tick("config.validate_config")
    with pytest.raises(ConfigError, match=r"recording\.data_dir"):
        C.validate_config({"recording": {"data_dir": path}})


def test_symlink_out_of_an_allowed_directory_is_refused(counter, tmp_path):
    counter.tick("config.validate_config")
    link = tmp_path / "innocent"
    link.symlink_to("/etc")
    with pytest.raises(ConfigError, match="not under an allowed directory"):
        C.validate_config({"recording": {"data_dir": str(link / "avard")}})
    ok = C.validate_config({"recording": {"data_dir": str(tmp_path / "data")}})
    assert ok["recording"]["data_dir"] == str((tmp_path / "data").resolve())


def test_state_directory_of_systemd_is_allowed(counter, monkeypatch, tmp_path):
    counter.tick("config.validate_config")
    state = tmp_path / "state"
    monkeypatch.setenv("STATE_DIRECTORY", str(state))
    monkeypatch.chdir("/")
    assert C.validate_config({"recording": {"data_dir": str(state)}})


def test_every_problem_is_listed_at_once(counter):
    counter.tick("config.validate_config")
    with pytest.raises(ConfigError) as info:
        C.validate_config({"sensor": {"odr_hz": 100.0, "bus": 3, "typo": 1},
                           "nosuch": {}})
    message = str(info.value)
    for part in ("sensor.odr_hz", "sensor.bus", "sensor.typo", "[nosuch]"):
        assert part in message


def test_writer_round_trips(counter):
    # the TOML writer used above is itself right: tomllib reads back what it wrote
    doc = {"a": 1, "s": {"k": "x\u007f\"\\\n", "f": 1.5, "l": [1, [True]], "t": {"z": -2}}}
    assert tomllib.loads(to_toml(doc)) == doc
