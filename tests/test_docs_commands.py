"""Every `avard` command line the README and docs show exists: the command, each of its
options, and (where the line has no placeholders such as DATA or FILE) the whole line parses
with the real argument parser."""

from __future__ import annotations

import os
import re
import shlex
import signal
import socket
import subprocess
import sys
import time
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


# ---- docs/getting-started.md: every command run here or marked as needing the Pi ----------

GETTING_STARTED = ROOT / "docs" / "getting-started.md"
NEEDS_PI = "# needs the Pi"


def _shell_lines(path: Path) -> list[str]:
    """The command lines of the page's ```sh blocks (comment-only lines left out)."""
    out, fenced = [], False
    for line in path.read_text(encoding="utf-8").splitlines():
        if line.startswith("```"):
            fenced = line.strip() == "```sh"
            continue
        if fenced and line.strip() and not line.lstrip().startswith("#"):
            out.append(line.strip())
    return out


GS_LINES = _shell_lines(GETTING_STARTED)
#: the lines the walk below runs, as the page writes them (it swaps in free ports)
RUN_HERE = [
    "make demo",
    "avard run --simulate quiet-lab --speed 0 --duration 600 --data-dir rec",
    "avard analyze rec",
    "avard check-config config/avard.toml --data-dir rec",
    "avard watch tcp://127.0.0.1:5555",
    "avard web tcp://127.0.0.1:5555 --listen 127.0.0.1:8080",
    "avard explain rec --report report",
]


def test_every_getting_started_command_is_run_here_or_needs_the_pi() -> None:
    unmarked = [ln for ln in GS_LINES if NEEDS_PI not in ln]
    assert sorted(unmarked) == sorted(RUN_HERE)
    assert any(NEEDS_PI in ln for ln in GS_LINES)


@pytest.mark.parametrize("line", [ln for ln in GS_LINES if NEEDS_PI in ln])
def test_a_getting_started_line_for_the_pi_is_spelled_right(line: str) -> None:
    cmd = line.split(NEEDS_PI)[0].strip()
    subprocess.run(["bash", "-n", "-c", cmd], check=True)
    words = shlex.split(cmd)
    if words[0] == "avard":
        build_parser(words[1]).parse_args(words[1:])


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _wait_http(url: str, proc: subprocess.Popen) -> bytes:  # type: ignore[type-arg]
    import urllib.request

    deadline = time.monotonic() + 120  # a bound on a hang only
    while True:
        try:
            with urllib.request.urlopen(url, timeout=30) as r:
                return bytes(r.read())
        except OSError:
            assert proc.poll() is None, "avard web ended"
            assert time.monotonic() < deadline, f"{url} never answered"
            time.sleep(0.2)


@pytest.mark.parametrize("with_report", [
    False, pytest.param(True, marks=pytest.mark.slow)], ids=["walk", "walk+explain-report"])
def test_the_getting_started_walk_on_the_emulated_sensor(tmp_path: Path,
                                                        with_report: bool) -> None:
    """Step 0, 2, 4, 5 and 6 of the page as written, in a scratch folder (ports swapped).
    `explain --report` (seconds of CPU for its figures) runs in the slow set."""
    pub, req, http = _free_port(), _free_port(), _free_port()
    ports = tmp_path / "ports.toml"
    ports.write_text(f'[publish]\nendpoint = "tcp://127.0.0.1:{pub}"\n'
                     f'request_endpoint = "tcp://127.0.0.1:{req}"\n')
    (tmp_path / "config").mkdir()
    (tmp_path / "config" / "avard.toml").write_text(
        (ROOT / "config" / "avard.toml").read_text())
    env = dict(os.environ, PATH=f"{Path(sys.executable).parent}:{os.environ['PATH']}")

    def swap(line: str) -> str:
        return (line.replace("5555", str(pub)).replace("8080", str(http))
                .replace("--data-dir rec", f"--data-dir {tmp_path / 'rec'}"))

    def sh(line: str, *extra: str) -> subprocess.CompletedProcess[str]:
        p = subprocess.run(["bash", "-c", " ".join([swap(line), *extra])], cwd=tmp_path,
                           env=env, capture_output=True, text=True, timeout=1200)
        assert p.returncode == 0, f"`{line}`: {p.stderr[-2000:]}"
        return p

    # make demo: what it runs (the full run is the slow set's, tests/daemon/test_demo.py)
    dry = subprocess.run(["make", "-n", "demo"], cwd=ROOT, capture_output=True, text=True)
    assert "bin/avard demo" in dry.stdout
    sh(RUN_HERE[1], "--config", str(ports))
    assert "velocity_random_walk" in sh(RUN_HERE[2]).stdout
    assert "valid" in sh(RUN_HERE[3]).stdout
    if with_report:
        assert sh(RUN_HERE[6]).stdout.startswith("avard explain:")
        assert (tmp_path / "report" / "report.md").exists()

    # watch and web against a running (emulated) service
    service = subprocess.Popen(
        ["avard", "run", "--simulate", "quiet-lab", "--speed", "20", "--config", str(ports),
         "--data-dir", str(tmp_path / "live")], cwd=tmp_path, env=env,
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        watched = sh(RUN_HERE[4], "--once", "--wait", "300").stdout
        assert "ADEV" in watched and "samples" in watched
        pytest.importorskip("aiohttp", reason="avard web needs the 'web' extra")
        web = subprocess.Popen(["bash", "-c", "exec " + swap(RUN_HERE[5])], cwd=tmp_path,
                               env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            page = _wait_http(f"http://127.0.0.1:{http}/", web)
            assert b"Allan deviation" in page
        finally:
            web.send_signal(signal.SIGTERM)
            assert web.wait(60) == 0
    finally:
        service.send_signal(signal.SIGTERM)
        service.wait(60)
