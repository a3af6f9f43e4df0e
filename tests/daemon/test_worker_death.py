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


def _run_dying(stage: type, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
               capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    """`avard run --simulate` whose ``stage`` dies at every chunk: (exit status, stderr)."""
    monkeypatch.setattr(stage, "handle", _die)
    status = cli.main(["run", "--simulate", "quiet-lab", "--duration", "30",
                       "--data-dir", str(tmp_path / "rec")])
    return status, capsys.readouterr().err


def test_a_dead_worker_exits_with_a_status_systemd_restarts(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    status, err = _run_dying(AllanStage, tmp_path, monkeypatch, capsys)
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


def test_a_dead_publisher_thread_is_restarted_in_place_and_its_block_becomes_a_gap(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """#26: a dead worker exited 70 and systemd restarted the whole service (a restart gap in
    the recording). The publisher's output is a copy of what the recording and the
    accumulators hold, so its thread is restarted in place: the run goes on, nothing is lost
    from the recording, and the block it died on reaches subscribers as a gap record."""
    from avard.daemon.service.publisher_stage import PublisherStage

    from .test_faults_bus import run_rig

    original = PublisherStage.handle
    seen = {"n": 0, "died_at": None}

    def die_once(self: Any, chunk: Any) -> None:
        if chunk.n:
            seen["n"] += 1
            if seen["n"] == 4:
                seen["died_at"] = int(chunk.index[0])
                raise OSError(24, "Too many open files")
        original(self, chunk)

    monkeypatch.setattr(PublisherStage, "handle", die_once)
    rig = run_rig(tmp_path, 30.0)          # raises ServiceFault if the death ends the run
    pub = next(w for w in rig.svc.workers if w.name == "publisher")
    assert pub.restarts == 1 and pub.error is None
    gaps = [r for t, r in rig.listener.records
            if r.get("kind") == "gap" and r.get("reason") == "publisher_restart"]
    assert len(gaps) == 1 and gaps[0]["i0"] == seen["died_at"] and gaps[0]["n"] > 0
    events = [r for t, r in rig.listener.records
              if r.get("kind") == "event" and r.get("name") == "publisher_restart"]
    assert len(events) == 1 and events[0]["detail"]["samples"] == gaps[0]["n"]
    st = rig.listener.sub.stats
    assert st.samples_unexplained == 0 and st.messages_lost == 0
    # the recording lost nothing: one run, no gap of any kind
    assert rig.kinds("gap") == []


def test_a_publisher_that_keeps_dying_exits_with_a_status_systemd_restarts(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    from avard.daemon.service.publisher_stage import PublisherStage
    from avard.daemon.service.supervisor import MAX_STAGE_RESTARTS

    status, err = _run_dying(PublisherStage, tmp_path, monkeypatch, capsys)
    assert err.count("restarting it (#") == MAX_STAGE_RESTARTS
    assert "publisher thread stopped" in err and status == ServiceFault.exit_status
