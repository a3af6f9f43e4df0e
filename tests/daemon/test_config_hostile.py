"""Config files and command lines that used to hang, crash or pass and then fail (#16 item 9,
#13 item 5): each is refused with one line and exit status 2 before anything starts, by
``avard check-config`` and ``avard run`` alike (one validation)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from avard.daemon import config
from avard.daemon.cli import main
from avard.daemon.net.curve import make_keypair


def _refused(capsys: pytest.CaptureFixture, argv: list[str], *words: str) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    for w in words:
        assert w in err, err
    return err


def _both(capsys: pytest.CaptureFixture, cfg: Path, tmp: Path, *words: str) -> None:
    """check-config and run refuse the same file with the same reason."""
    _refused(capsys, ["check-config", str(cfg)], *words)
    _refused(capsys, ["run", "--config", str(cfg), "--simulate", "quiet-lab", "--speed", "0",
                      "--duration", "1"], *words)


def _cfg(tmp: Path, text: str, data_dir: Path | None = None) -> Path:
    d = data_dir or tmp / "rec"
    p = tmp / "avard.toml"
    p.write_text(f'[recording]\ndata_dir = "{d}"\n[publish]\nenabled = false\n' + text)
    return p


def test_a_device_as_config_is_refused_without_reading_it(capsys) -> None:
    _refused(capsys, ["check-config", "/dev/zero"], "/dev/zero", "a device",
             "not a regular file")


def test_a_directory_as_config_is_refused(capsys, tmp_path) -> None:
    _refused(capsys, ["check-config", str(tmp_path)], "a directory")


def test_a_huge_config_is_refused_by_size(capsys, tmp_path) -> None:
    big = tmp_path / "big.toml"
    big.write_bytes(b"#" * (config.MAX_CONFIG_BYTES + 1))
    _refused(capsys, ["check-config", str(big)], "byte limit")


@pytest.mark.parametrize("which", ["config", "key"])
def test_a_fifo_as_config_or_key_file_is_refused_and_does_not_hang(tmp_path, which) -> None:
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    if which == "config":
        target = fifo
    else:
        keys = tmp_path / "keys"
        keys.mkdir()
        target = _cfg(tmp_path, f'[curve]\nenabled = true\nserver_secret_key_file = "{fifo}"\n'
                      f'authorized_keys_dir = "{keys}"\n')
    done = subprocess.run([sys.executable, "-m", "avard.daemon.cli", "check-config",
                           str(target)], capture_output=True, text=True, timeout=60)
    assert done.returncode == 2
    assert "a FIFO" in done.stderr and "Traceback" not in done.stderr, done.stderr


def test_a_utf8_byte_order_mark_is_accepted(capsys, tmp_path) -> None:
    p = tmp_path / "bom.toml"
    p.write_bytes(b"\xef\xbb\xbf[allan]\noverlap = 4\n")
    assert config.load_config(p)["allan"]["overlap"] == 4


def test_overlap_must_be_a_power_of_two(capsys, tmp_path) -> None:
    _both(capsys, _cfg(tmp_path, "[allan]\noverlap = 3\n"), tmp_path, "allan.overlap = 3",
          "one of 1, 2, 4, 8")


def test_sensor_ids_are_validated(capsys, tmp_path) -> None:
    cfg = _cfg(tmp_path, '[temperature]\nids = ["../../../etc/passwd"]\n')
    _both(capsys, cfg, tmp_path, "'../../../etc/passwd' is not a DS18B20 id")


def test_run_from_root_with_home_root_gives_no_root_to_write_under(capsys, tmp_path,
                                                                   monkeypatch) -> None:
    cfg = _cfg(tmp_path, "", data_dir=Path("/etc/avard-evil"))
    monkeypatch.chdir("/")
    monkeypatch.setenv("HOME", "/")
    monkeypatch.delenv("STATE_DIRECTORY", raising=False)
    assert Path("/") not in config.allowed_roots()
    _both(capsys, cfg, tmp_path, "/etc/avard-evil", "not under an allowed directory")
    assert not Path("/etc/avard-evil").exists()


def test_ring_memory_is_checked_against_the_machine(capsys, tmp_path, monkeypatch) -> None:
    monkeypatch.setattr(config, "machine_memory_bytes", lambda: 512 * 2**20)   # a Pi 3 A+
    cfg = _cfg(tmp_path, "[sensor]\nodr_hz = 4000.0\n[service]\nring_s = 3600.0\n")
    _both(capsys, cfg, tmp_path, "service.ring_s = 3600", "423 MiB", "512 MiB")
    ok = _cfg(tmp_path, "[sensor]\nodr_hz = 4000.0\n[service]\nring_s = 30.0\n")
    assert config.load_config(ok)["service"]["ring_s"] == 30.0


@pytest.mark.parametrize("flags, words", [
    (["--seed", "-1"], ["--seed -1"]),
    (["--speed", "1e-300"], ["--speed 1e-300"]),
    (["--speed", "nan"], ["--speed nan"]),
    (["--duration", "nan"], ["--duration nan"]),
    (["--duration", "inf"], ["--duration inf"]),
])
def test_run_refuses_bad_numbers_on_the_command_line(capsys, tmp_path, flags, words) -> None:
    argv = ["run", "--simulate", "quiet-lab", "--data-dir", str(tmp_path / "rec"), *flags]
    if "--duration" not in flags:
        argv += ["--duration", "1"]
    _refused(capsys, argv, *words)


def test_simulate_refuses_a_negative_seed_and_endless_hours(capsys, tmp_path) -> None:
    out = str(tmp_path / "x.npz")
    _refused(capsys, ["simulate", "--seed", "-1", "--hours", "0.001", "--out", out], "--seed")
    _refused(capsys, ["simulate", "--hours", "inf", "--out", out], "--hours")


# -- check-config checks what run checks (#13 item 5) -------------------------------------


def _curve(tmp: Path, secret: Path, keys: Path) -> Path:
    return _cfg(tmp, f'[curve]\nenabled = true\nserver_secret_key_file = "{secret}"\n'
                f'authorized_keys_dir = "{keys}"\n')


def test_check_config_refuses_what_run_would_refuse(capsys, tmp_path) -> None:
    pub, sec = make_keypair(tmp_path / "server", "server")
    keys = tmp_path / "clients"
    keys.mkdir()
    make_keypair(keys, "client")
    (keys / "client.key_secret").unlink()
    good = _curve(tmp_path, sec, keys)
    assert main(["check-config", str(good)]) == 0
    capsys.readouterr()
    # a missing secret key file
    _both(capsys, _curve(tmp_path, tmp_path / "nope.key_secret", keys), tmp_path,
          "no such CURVE secret key file")
    # the public key named as the secret one
    _both(capsys, _curve(tmp_path, pub, keys), tmp_path, "holds no secret key")
    # a secret key others can read
    sec.chmod(0o640)
    _both(capsys, _curve(tmp_path, sec, keys), tmp_path, "mode 0640", "chmod 600")
    sec.chmod(0o600)
    # a missing authorised-keys directory
    _both(capsys, _curve(tmp_path, sec, tmp_path / "none"), tmp_path,
          "authorized_keys_dir", "is not a directory")
    # a data directory that cannot be made (its parent is a file)
    (tmp_path / "file").write_text("x")
    _both(capsys, _cfg(tmp_path, "", data_dir=tmp_path / "file" / "rec"), tmp_path,
          "recording.data_dir", "is not a directory")


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write anywhere")
def test_check_config_refuses_an_unwritable_data_dir(capsys, tmp_path) -> None:
    ro = tmp_path / "ro"
    ro.mkdir(mode=0o500)
    _both(capsys, _cfg(tmp_path, "", data_dir=ro / "rec"), tmp_path, "not writable")
