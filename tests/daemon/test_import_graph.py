"""The package layering, read off the source: daemon/hw (drivers, emulator, the rig) imports
nothing from the service, the network or the commands, not even lazily inside a function or
under TYPE_CHECKING; the two meet only in the composition root (daemon/compose.py)."""

from __future__ import annotations

import ast
from pathlib import Path

import avard.daemon

DAEMON = Path(avard.daemon.__file__).parent
#: What hardware code may not reach: the layers built on top of it.
ABOVE_HW = ("avard.daemon.service", "avard.daemon.net", "avard.daemon.commands",
            "avard.daemon.web", "avard.daemon.compose", "avard.daemon.cli")


def imported_modules(source: str, module: str) -> set[str]:
    """Every module ``source`` (the text of ``module``) imports, anywhere in the file,
    relative imports resolved."""
    out: set[str] = set()
    package = module.rsplit(".", 1)[0]
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")
                base = ".".join(parts[:len(parts) - node.level + 1] + ([base] if base else []))
            out.add(base)
            out.update(f"{base}.{a.name}" for a in node.names)
    return out


def _violations(files: dict[str, str]) -> list[str]:
    return sorted(f"{mod} imports {imp}" for mod, src in files.items()
                  for imp in imported_modules(src, mod)
                  if imp.startswith(ABOVE_HW))


def _hw_sources() -> dict[str, str]:
    return {f"avard.daemon.hw.{p.stem}": p.read_text(encoding="utf-8")
            for p in sorted((DAEMON / "hw").glob("*.py"))}


def test_hw_imports_nothing_from_the_service_or_above() -> None:
    files = _hw_sources()
    assert "avard.daemon.hw.rig" in files and "avard.daemon.hw.simulation" in files
    assert _violations(files) == []


def test_the_check_sees_lazy_relative_and_type_checking_imports() -> None:
    """The check itself can fail: each way of importing the service is caught."""
    bad = {
        "avard.daemon.hw.a": "def f():\n    from avard.daemon.service.supervisor import Service\n",
        "avard.daemon.hw.b": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
                             "    import avard.daemon.service.ring\n",
        "avard.daemon.hw.c": "from ..service import supervisor\n",
        "avard.daemon.hw.d": "from .. import compose\n",
    }
    assert {v.split()[0] for v in _violations(bad)} == set(bad)
    assert _violations({"avard.daemon.hw.e": "from .timebase import Clock\n"}) == []


def test_the_composition_root_is_where_hw_and_service_meet() -> None:
    mods = imported_modules((DAEMON / "compose.py").read_text(encoding="utf-8"),
                            "avard.daemon.compose")
    assert any(m.startswith("avard.daemon.hw.rig") for m in mods)
    assert any(m.startswith("avard.daemon.service.supervisor") for m in mods)
