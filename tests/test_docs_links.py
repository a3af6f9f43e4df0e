"""Every relative link in the docs resolves: its file exists and its #anchor is a heading of
that file (GitHub's slug of it). The references link their history in docs/log/ by anchor,
and a heading renamed or a section moved there would otherwise leave the link dead unseen."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = sorted([ROOT / "README.md", *(ROOT / "docs").glob("*.md"),
                *(ROOT / "docs" / "log").glob("*.md")])

_FENCE = re.compile(r"^(```|~~~)")
_LINK = re.compile(r"(?<!!)\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
_HTML_ANCHOR = re.compile(r"<a\s+(?:id|name)=\"([^\"]+)\"")


def _prose(text: str) -> list[str]:
    """The lines outside fenced code blocks, inline code spans blanked."""
    out, fenced = [], False
    for line in text.splitlines():
        if _FENCE.match(line.strip()):
            fenced = not fenced
            continue
        if not fenced:
            out.append(re.sub(r"`[^`]*`", lambda m: "x" * len(m.group(0)), line))
    return out


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, every character but letters, digits, `_`,
    `-` and spaces dropped (inline code's backticks too), spaces to hyphens."""
    s = re.sub(r"<[^>]+>", "", heading.strip().lower())
    s = re.sub(r"[^\w\- ]", "", s)
    return s.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    """The anchors GitHub makes for ``path``: each heading's slug (a repeated one with -1,
    -2, … appended) and explicit <a id=…> anchors."""
    seen: dict[str, int] = {}
    out: set[str] = set()
    fenced = False
    for line in path.read_text(encoding="utf-8").splitlines():
        if _FENCE.match(line.strip()):
            fenced = not fenced
            continue
        if fenced:
            continue
        m = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if m:
            base = slug(m.group(1))
            n = seen.get(base, 0)
            seen[base] = n + 1
            out.add(base if n == 0 else f"{base}-{n}")
        out.update(_HTML_ANCHOR.findall(line))
    return out


def _links(page: Path) -> list[tuple[int, str]]:
    return [(i + 1, m.group(1)) for i, line in enumerate(_prose(page.read_text(encoding="utf-8")))
            for m in _LINK.finditer(line)]


def test_the_slug_is_githubs():
    assert slug("How the fit works (`avard.core.model.fit.fit_noise`)") == \
        "how-the-fit-works-avardcoremodelfitfit_noise"
    assert slug("A change point's interval, from its likelihood (trans23g)") == \
        "a-change-points-interval-from-its-likelihood-trans23g"
    assert slug("core/io/source.py — the one record source") == \
        "coreiosourcepy--the-one-record-source"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_relative_link_and_anchor_resolves(page):
    bad = []
    cache: dict[Path, set[str]] = {}
    for line, target in _links(page):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target):  # http:, https:, mailto:
            continue
        path_part, _, anchor = target.partition("#")
        dest = page if not path_part else (page.parent / path_part).resolve()
        if not dest.exists():
            bad.append(f"{page.name}:{line}: {target}: no such file")
            continue
        if anchor and dest.suffix == ".md":
            if dest not in cache:
                cache[dest] = anchors(dest)
            if anchor not in cache[dest]:
                bad.append(f"{page.name}:{line}: {target}: no heading with that anchor")
    assert not bad, "\n".join(bad)
