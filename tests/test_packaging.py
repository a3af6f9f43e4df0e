"""The wheel ships every package of core/ and daemon/.

pyproject.toml lists the packages by hand (the package-dir mapping core → avard.core does not
let setuptools discover them), so a new sub-package that is not listed is silently missing from
`pip install avard` while every test of the editable checkout still passes.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _packages_on_disk() -> set[str]:
    found = set()
    for top, name in (("core", "avard.core"), ("daemon", "avard.daemon")):
        for init in (ROOT / top).rglob("__init__.py"):
            rel = init.parent.relative_to(ROOT / top).parts
            found.add(".".join((name, *rel)))
    return found


def test_every_package_with_an_init_is_listed_for_the_wheel() -> None:
    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())
                 ["tool"]["setuptools"]["packages"])
    on_disk = _packages_on_disk()
    assert on_disk - listed == set(), "add these to [tool.setuptools] packages"
    # data-only packages (the web page's static files) have no __init__.py
    assert {p for p in listed - on_disk if not p.endswith(".static")} == set()
