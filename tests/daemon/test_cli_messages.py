"""The messages the issue found misleading now say what is really wrong."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from avard.core.errors import ConfigError
from avard.daemon.cli import main


def _err(capsys: pytest.CaptureFixture[str]) -> str:
    return capsys.readouterr().err


def test_a_constant_channel_is_called_constant_not_too_short(tmp_path: Path, capsys) -> None:
    p = tmp_path / "const.npz"
    rng = np.random.default_rng(2)
    np.savez(p, accel=np.column_stack([np.full(20000, 9.81), rng.normal(0, 1e-3, (20000, 2))]),
             rate_hz=100.0)
    assert main(["analyze", str(p)]) == 2
    err = _err(capsys)
    assert "channel x" in err and "constant" in err and "longer" not in err


def test_a_truncated_npz_is_called_truncated(tmp_path: Path, capsys) -> None:
    good = tmp_path / "good.npz"
    np.savez(good, accel=np.zeros((1000, 3)), rate_hz=100.0)
    cut = tmp_path / "cut.npz"
    cut.write_bytes(good.read_bytes()[:5000])
    assert main(["analyze", str(cut)]) == 2
    err = _err(capsys)
    assert "cut.npz" in err and "truncated" in err and "numpy.savez" not in err


def test_a_txt_file_is_read_as_csv_and_says_so(tmp_path: Path, capsys) -> None:
    rng = np.random.default_rng(3)
    p = tmp_path / "export.txt"
    p.write_text("x,y,z\n" + "\n".join(",".join(f"{v:.6e}" for v in row)
                                       for row in rng.normal(0, 1e-3, (4000, 3))))
    assert main(["analyze", str(p), "--rate", "100"]) == 0
    assert "export.txt: reading it as CSV" in _err(capsys)


def test_record_refuses_a_file_name_for_its_folder(tmp_path: Path, capsys) -> None:
    out = tmp_path / "x.npz"
    assert main(["record", "tcp://127.0.0.1:9", "--out", str(out), "--wait", "1"]) == 2
    err = _err(capsys)
    assert "a recording is a folder" in err and "--out" in err and str(out.with_suffix("")) in err
    assert not out.exists()


def test_run_by_hand_does_not_create_a_system_folder(capsys) -> None:
    from avard.daemon.config import check_runtime, load_config

    cfg = load_config(None, **{"recording.data_dir": "/var/lib/avard/test-not-there"})
    with pytest.raises(ConfigError, match="does not create system folders"):
        check_runtime(cfg, environ={})
    check_runtime(cfg, environ={"INVOCATION_ID": "abc"})  # systemd: StateDirectory=


def test_check_config_refuses_what_run_refuses(tmp_path: Path, capsys) -> None:
    """check-config's --help promises "a config that passes here starts": a missing system
    folder that `avard run` by hand refuses is refused by check-config too, in its words."""
    if Path("/var/lib/avard").exists():
        pytest.skip("/var/lib/avard exists on this machine")
    cfg = tmp_path / "avard.toml"
    cfg.write_text('[recording]\ndata_dir = "/var/lib/avard/test-not-there"\n')
    assert main(["check-config", str(cfg)]) == 2
    check_err = _err(capsys)
    assert "does not create system folders" in check_err
    assert main(["run", "--config", str(cfg), "--simulate", "quiet-lab", "--duration", "1"]) == 2
    run_err = _err(capsys)
    assert check_err.split(": ", 1)[-1] in run_err


def test_run_without_config_says_which_it_uses(capsys) -> None:
    # the default /var/lib/avard is missing here: the run stops before starting anything
    if Path("/var/lib/avard").exists():
        pytest.skip("/var/lib/avard exists on this machine")
    assert main(["run", "--simulate", "quiet-lab", "--duration", "1"]) == 2
    err = _err(capsys)
    assert "no --config: using the built-in defaults" in err
    assert "/var/lib/avard does not exist" in err and "--data-dir" in err
    assert not Path("/var/lib/avard").exists()


def test_a_closed_pipe_ends_quietly() -> None:
    """`avard simulate --list | head -1`: the reader leaving is not an error to report."""
    import subprocess
    import sys

    p = subprocess.Popen([sys.executable, "-m", "avard.daemon.cli", "simulate", "--list"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert p.stdout is not None and p.stderr is not None
    p.stdout.close()  # before anything is written: the first write meets EPIPE
    err = p.stderr.read().decode()
    assert p.wait(60) == 141, err
    assert "Traceback" not in err and "Exception ignored" not in err


def test_a_refused_connection_gets_network_advice() -> None:
    import errno
    import os

    from avard.core.errors import describe_os_error

    text = describe_os_error(ConnectionRefusedError(errno.ECONNREFUSED,
                                                    os.strerror(errno.ECONNREFUSED)))
    assert "check the address and that the service runs" in text


def test_check_config_show_prints_toml_that_reads_back_to_the_same_config(
        tmp_path: Path, capsys) -> None:
    import tomllib

    from avard.daemon.config import load_config

    src = Path(__file__).parents[2] / "config" / "avard.toml"
    data = tmp_path / "rec"
    assert main(["check-config", str(src), "--data-dir", str(data), "--show"]) == 0
    shown = capsys.readouterr().out
    assert "True" not in shown and "False" not in shown and "= true" in shown
    parsed = tomllib.loads(shown)  # the whole output, summary included (as comments)
    again = tmp_path / "shown.toml"
    again.write_text(shown)
    assert load_config(again) == load_config(src, **{"recording.data_dir": str(data)}) \
        == {sec: {k: v for k, v in t.items()} for sec, t in load_config(again).items()}
    assert parsed["recording"]["data_dir"] == str(data)


def test_a_csv_with_decimal_commas_gets_a_hint(tmp_path: Path, capsys) -> None:
    csv = tmp_path / "lab.csv"
    csv.write_text("t;x;y;z\n0,0;0,1;0,2;9,8\n0,008;0,1;0,2;9,8\n")
    assert main(["analyze", str(csv)]) == 2
    err = _err(capsys)
    assert "decimal commas" in err and "decimal points" in err
    good = tmp_path / "ok.csv"  # a number that is wrong for another reason: no such hint
    good.write_text("t;x\n0.0;abc\n0.008;0.1\n")
    assert main(["analyze", str(good)]) == 2
    assert "decimal commas" not in _err(capsys)


def test_help_keeps_the_lines_of_a_command_description(capsys) -> None:
    """--help printed the examples and lists of a command's description folded into one
    paragraph."""
    with pytest.raises(SystemExit):
        main(["watch", "--help"])
    out = capsys.readouterr().out
    assert "\n* rate: the service's fitted ODR" in out
    with pytest.raises(SystemExit):
        main(["probe", "--help"])
    assert "(default 2500)" in " ".join(capsys.readouterr().out.split())
