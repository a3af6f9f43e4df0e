"""CURVE: key files with safe permissions, and only authorised subscribers get anything."""

from __future__ import annotations

import logging
import stat
from pathlib import Path

import numpy as np
import pytest
import zmq
import zmq.auth
from avard.core.errors import ConfigError, NetworkError
from avard.core.io import frames as F
from avard.daemon.net.curve import (
    CurveClientConfig,
    CurveServerConfig,
    load_public_key,
    load_secret_key,
    make_keypair,
)
from avard.daemon.net.publisher import Publisher, RequestServer
from avard.daemon.net.subscriber import Subscriber

LOCAL = "tcp://127.0.0.1:*"


def _mode(p: Path) -> int:
    return stat.S_IMODE(p.stat().st_mode)


def test_keypair_files_and_permissions(tmp_path: Path) -> None:
    pub, sec = make_keypair(tmp_path / "keys", "server")
    assert _mode(sec) == 0o600 and _mode(pub) == 0o644
    assert _mode(tmp_path / "keys") == 0o700
    public, secret = load_secret_key(sec)
    assert load_public_key(pub) == public and len(secret) == 40
    # pyzmq reads them too, and the public file holds no secret
    assert zmq.auth.load_certificate(pub) == (public, None)
    assert secret.decode() not in pub.read_text()
    with pytest.raises(ConfigError, match="never overwrites"):
        make_keypair(tmp_path / "keys", "server")
    with pytest.raises(ConfigError, match="plain file name"):
        make_keypair(tmp_path, "../x")


def test_secret_readable_by_others_is_refused(tmp_path: Path) -> None:
    _, sec = make_keypair(tmp_path, "server")
    sec.chmod(0o640)
    with pytest.raises(ConfigError, match="chmod 600"):
        load_secret_key(sec)
    with pytest.raises(ConfigError, match="not readable"):
        load_secret_key(tmp_path / "missing.key_secret")
    public_only = tmp_path / "server.key"
    public_only.chmod(0o600)
    with pytest.raises(ConfigError, match="no secret"):
        load_secret_key(public_only)


def test_config_section_names_missing_key() -> None:
    with pytest.raises(ConfigError, match="authorized_keys_dir"):
        CurveServerConfig.from_mapping({"server_secret_key_file": "/x"})


@pytest.fixture
def keys(tmp_path: Path) -> dict:
    server_pub, server_sec = make_keypair(tmp_path / "server", "server")
    auth_dir = tmp_path / "authorized"
    auth_dir.mkdir()
    good_pub, good_sec = make_keypair(tmp_path / "good", "client")
    (auth_dir / "client.key").write_text(good_pub.read_text())
    _, bad_sec = make_keypair(tmp_path / "bad", "client")
    return {
        "server": CurveServerConfig(server_sec, auth_dir),
        "good": CurveClientConfig(server_pub, good_sec),
        "bad": CurveClientConfig(server_pub, bad_sec),
        "secrets": [load_secret_key(p)[1].decode() for p in (server_sec, good_sec, bad_sec)],
        "publics": [load_secret_key(p)[0].decode() for p in (server_sec, good_sec, bad_sec)],
    }


def _raw(i0: int) -> dict:
    return F.raw_record("", 0, i0, np.full((32, 3), i0, dtype=np.int32), 0.0, 0.0)


def test_only_the_authorised_subscriber_gets_the_stream(
        keys: dict, caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.DEBUG)
    with Publisher(LOCAL, "run-c", curve=keys["server"]) as pub:
        good = Subscriber(pub.endpoint, curve=keys["good"]).connect()
        bad = Subscriber(pub.endpoint, curve=keys["bad"]).connect()
        plain = Subscriber(pub.endpoint).connect()
        try:
            # wait until the authorised subscription is through (PUB drops before that)
            for _ in range(500):
                pub.publish("status", F.status_record("", 0, {}, 0.0, 0.0))
                if good.recv(0.01) is not None:
                    break
            else:
                raise AssertionError("authorised subscriber never connected")
            while good.recv(0.1) is not None:
                pass
            for i in range(200):
                pub.publish("raw", _raw(32 * i))
            got = []
            while len(got) < 200:
                m = good.recv(3.0)
                assert m is not None, f"authorised subscriber stalled after {len(got)}"
                if m.topic == "raw":
                    got.append(m)
            assert [m.record["i0"] for m in got] == [32 * i for i in range(200)]
            assert good.stats.topics["raw"].lost == 0
            assert bad.recv(0.3) is None and plain.recv(0.1) is None
            assert bad.stats.messages_received == 0 == plain.stats.messages_received
            assert pub.stats()["auth_failures"] >= 1
        finally:
            for s in (good, bad, plain):
                s.close()
    for key in keys["secrets"] + keys["publics"]:
        assert key not in caplog.text


def test_request_server_with_curve(keys: dict) -> None:
    with RequestServer(LOCAL, {"status": lambda a: {"ok": 1}}, curve=keys["server"]) as srv:
        good = Subscriber("tcp://127.0.0.1:1", request_endpoint=srv.endpoint, curve=keys["good"],
                          request_timeout_s=20.0)  # generous: the machine may be loaded
        bad = Subscriber("tcp://127.0.0.1:1", request_endpoint=srv.endpoint, curve=keys["bad"],
                         request_timeout_s=0.5)
        try:
            assert good.request("status") == {"ok": 1}
            with pytest.raises(NetworkError, match="no reply"):
                bad.request("status")
        finally:
            good.close()
            bad.close()


def test_keys_command(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    from avard.daemon import cli

    out = tmp_path / "k"
    assert cli.main(["keys", "--out", str(out), "--name", "pi", "--name", "laptop"]) == 0
    text = capsys.readouterr().out
    for name in ("pi", "laptop"):
        public, secret = load_secret_key(out / f"{name}.key_secret")
        assert _mode(out / f"{name}.key_secret") == 0o600
        assert public.decode() not in text and secret.decode() not in text
        assert str(out / f"{name}.key") in text
    assert 'server_secret_key_file = "' in text
    # a second run refuses to overwrite and says so
    assert cli.main(["keys", "--out", str(out), "--name", "pi"]) == 2
    assert "never overwrites" in capsys.readouterr().err


def test_reload_keys_admits_a_newly_authorised_client(keys: dict, tmp_path: Path) -> None:
    with RequestServer(LOCAL, {"status": lambda a: {"ok": 1}}, curve=keys["server"]) as srv:
        bad = Subscriber("tcp://127.0.0.1:1", request_endpoint=srv.endpoint, curve=keys["bad"],
                         request_timeout_s=0.5)
        try:
            with pytest.raises(NetworkError):
                bad.request("status")
            # authorise the "bad" client's public key, reload, and it gets in
            public, _ = load_secret_key(keys["bad"].client_secret_key_file)
            pub_file = keys["bad"].client_secret_key_file.with_suffix(".key")
            assert load_public_key(pub_file) == public
            target = keys["server"].authorized_keys_dir / "newcomer.key"
            target.write_text(pub_file.read_text())
            srv.reload_keys()
            bad.request_timeout_s = 20.0
            assert bad.request("status") == {"ok": 1}
        finally:
            bad.close()


def test_a_public_key_given_as_the_secret_one_is_named_as_such(tmp_path) -> None:
    """Not "chmod 600": a public NAME.key (mode 0644 as written) is the wrong file."""
    pub, _sec = make_keypair(tmp_path, "laptop")
    with pytest.raises(ConfigError, match="holds no secret key, only a public one") as e:
        load_secret_key(pub)
    assert "chmod" not in str(e.value)
