"""daemon/hw/rig.py: one place chooses the backend (argument, $AVARD_BACKEND, then hardware)."""

from __future__ import annotations

from pathlib import Path

import pytest
from avard.core.errors import ConfigError
from avard.daemon.compose import compose
from avard.daemon.config import load_config
from avard.daemon.config_types import Config
from avard.daemon.hw.rig import BACKEND_ENV, build_rig, choose_backend, describe_rig


def test_backend_precedence_and_bad_values(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(BACKEND_ENV, raising=False)
    assert choose_backend(None) is None                       # hardware by default
    monkeypatch.setenv(BACKEND_ENV, "simulate:paper-table3")
    assert choose_backend(None) == "paper-table3"
    assert choose_backend("quiet-lab") == "quiet-lab"         # the argument wins
    monkeypatch.setenv(BACKEND_ENV, "hardware")
    assert choose_backend(None) is None
    for bad in ("simulate", "simulate:", "emulator"):
        monkeypatch.setenv(BACKEND_ENV, bad)
        with pytest.raises(ConfigError, match="simulate:PRESET"):
            choose_backend(None)


def test_env_backend_builds_the_simulated_rig_and_its_service(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(BACKEND_ENV, "simulate:quiet-lab")
    cfg = Config.from_dict(load_config(None, **{"recording.data_dir": str(tmp_path),
                                                "publish.enabled": False}))
    rig = build_rig(describe_rig(cfg, seed=4, speed=None))
    assert rig.simulate == "quiet-lab" and rig.info["device"] == "ADXL355 (emulated)"
    assert rig.info["name"] == "adxl355" == rig.spec.sensors[0].name   # into the header
    svc = compose(cfg, rig)
    svc.run(30.0)
    assert svc.header()["sensor"]["name"] == "adxl355"
    st = svc.final_status
    assert st["samples"] > 30 * 120 and st["overruns"] == 0
    # the simulated DS18B20s reached the service through the rig's wiring
    assert svc.temp_names == ["chip", *rig.parts["sims"].names]
    with pytest.raises(ConfigError, match="unknown preset"):
        describe_rig(cfg, simulate="no-such-preset")
