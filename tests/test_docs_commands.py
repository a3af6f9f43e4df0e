"""Every `avard` command line the README and docs show exists: the command, each of its
options, and (where the line has no placeholders such as DATA or FILE) the whole line parses
with the real argument parser."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest
from avard.daemon.cli import build_parser

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
COMMANDS = {a.dest for a in build_parser()._subparsers._group_actions[0]._choices_actions}
PLACEHOLDER = re.compile(r"^[A-Z][A-Z0-9_]*(\.\w+)?$|\.\.\.|^\[|\]$")


def _code_fragments(text: str) -> list[str]:
    """Lines of fenced code blocks (continuation lines joined) and inline code spans."""
    out: list[str] = []
    fenced = False
    pending = ""
    for line in text.splitlines():
        if line.lstrip().startswith("```"):
            fenced = not fenced
            continue
        if fenced:
            pending += line.rstrip("\\").rstrip() + " " if line.endswith("\\") else ""
            if not line.endswith("\\"):
                out.append(pending + line)
                pending = ""
        else:
            out += re.findall(r"`([^`]+)`", line)
    return out


def _invocations() -> list[tuple[str, str]]:
    found = []
    for doc in DOCS:
        for frag in _code_fragments(doc.read_text(encoding="utf-8")):
            for m in re.finditer(r"(?:^|[\s/;])avard\s+([a-z][a-z-]*)(?=\s|$)(.*)", frag):
                item = (doc.name, f"{m.group(1)}{m.group(2)}".strip())
                if m.group(1) in COMMANDS and item not in found:
                    found.append(item)
    return found


INVOCATIONS = _invocations()


def test_the_docs_show_every_command() -> None:
    assert {line.split()[0] for _, line in INVOCATIONS} == COMMANDS


@pytest.mark.parametrize(("doc", "line"), INVOCATIONS,
                         ids=[f"{d}: {ln[:60]}" for d, ln in INVOCATIONS])
def test_a_documented_command_line_exists_and_parses(doc: str, line: str) -> None:
    words = shlex.split(line.split(" #")[0].split(" > ")[0].split(" | ")[0], posix=True)
    words = [w.strip("[]") for w in words if w.strip("[]")]
    command = words[0]
    parser = build_parser(command)
    sub = parser._subparsers._group_actions[0].choices[command]
    known = set(sub._option_string_actions) | set(parser._option_string_actions)
    for w in words[1:]:
        if w.startswith("--"):
            assert w.split("=")[0] in known, f"{doc}: `avard {line}`: no option {w} in " \
                                             f"`avard {command} --help`"
    # a bare name ("`avard analyze` reads …") names the command; a line with arguments and
    # no placeholders is one to type, and must parse
    if len(words) > 1 and not any(PLACEHOLDER.search(w) for w in words[1:]):
        try:
            parser.parse_args(words)
        except SystemExit as exc:
            raise AssertionError(f"{doc}: `avard {line}` does not parse") from exc
