"""A worker thread that dies (issue 26, item 7): the service stops with exit status 70, which
the unit's Restart=on-failure restarts, never 2 (RestartPreventExitStatus=2 kept the service
down for a weekend); and the unit bounds the fd table (LimitNOFILE) so a local peer cannot
exhaust it silently."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from avard.core.errors import ServiceFault
from avard.daemon import cli
from avard.daemon.service.allan_stage import AllanStage

UNIT = Path(__file__).resolve().parents[2] / "systemd" / "avard.service"


def _die(self: Any, chunk: Any) -> None:
    raise OSError(24, "Too many open files")


def _unit() -> dict[str, list[str]]:
    keys: dict[str, list[str]] = {}
    section = ""
    for line in UNIT.read_text().splitlines():
        line = line.strip()
        if line.startswith("["):
            section = line
        elif "=" in line and not line.startswith("#") and section == "[Service]":
            k, v = line.split("=", 1)
            keys.setdefault(k, []).append(v)
    return keys


def test_a_dead_worker_exits_with_a_status_systemd_restarts(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setattr(AllanStage, "handle", _die)
    status = cli.main(["run", "--simulate", "quiet-lab", "--duration", "30",
                       "--data-dir", str(tmp_path / "rec")])
    err = capsys.readouterr().err
    assert "allan thread stopped" in err
    assert status == ServiceFault.exit_status == 70
    unit = _unit()
    prevented = {int(s) for v in unit.get("RestartPreventExitStatus", []) for s in v.split()}
    assert status not in prevented
    assert unit["Restart"] == ["on-failure"]


def test_the_unit_bounds_the_fd_table() -> None:
    unit = _unit()
    assert "LimitNOFILE" in unit
    soft, _, hard = unit["LimitNOFILE"][-1].partition(":")
    assert int(soft) >= 4096 and int(hard or soft) >= int(soft)


def test_check_config_states_the_rate_that_holds_on_the_real_clock(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from avard.daemon.hw.pacing import HELD_HZ_PROCESS_FIFO

    held = f"only {HELD_HZ_PROCESS_FIFO:g} Hz was measured free of FIFO overruns"
    cases = [(4000, "", held), (1000, "", held), (HELD_HZ_PROCESS_FIFO, "", None),
             (125, "", None), (125, "gpiochip0:25", "with INT1 the FIFO is drained by the "
                                                    "service's thread")]
    for odr, int1, said in cases:
        cfg = tmp_path / f"a{odr:g}.toml"
        cfg.write_text(f"[sensor]\nodr_hz = {odr}\nint1_gpio = \"{int1}\"\n[recording]\n"
                       f"data_dir = \"{tmp_path / 'rec'}\"\n")
        assert cli.main(["check-config", str(cfg)]) == 0
        out = capsys.readouterr().out
        assert ("by a reader process on the hardware" in out) == (not int1), out
        if said is None:
            assert "note:" not in out, out
        else:
            assert said in out, out
