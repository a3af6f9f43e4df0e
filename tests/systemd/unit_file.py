"""Reading systemd unit files the way systemd does, for the tests: keys repeat and accumulate."""

from __future__ import annotations

import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
UNIT = REPO / "systemd" / "avard.service"

Unit = dict[str, dict[str, list[str]]]


def parse_unit(text: str) -> Unit:
    """Sections → key → every value in order (systemd keys may repeat and accumulate)."""
    sections: Unit = {}
    current: dict[str, list[str]] | None = None
    for raw in text.splitlines():
        line = raw.strip()
        if not line or line[0] in "#;":
            continue
        if line.startswith("[") and line.endswith("]"):
            current = sections.setdefault(line[1:-1], {})
            continue
        assert current is not None, f"setting outside a section: {line!r}"
        key, _, value = line.partition("=")
        current.setdefault(key.strip(), []).append(value.strip())
    return sections


def scratch_config(folder: Path) -> Path:
    """The shipped config with a data directory in ``folder`` and ports the kernel picks
    (``folder``/avard.toml; the data directory ``folder``/data is made)."""
    data = folder / "data"
    data.mkdir()
    text = (REPO / "config" / "avard.toml").read_text()
    text = re.sub(r"(?m)^data_dir = .*$", f'data_dir = "{data}"', text)
    text = re.sub(r"tcp://127\.0\.0\.1:555[56]", "tcp://127.0.0.1:0", text)
    path = folder / "avard.toml"
    path.write_text(text)
    return path
