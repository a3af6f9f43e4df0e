"""The systemd unit, sysusers and tmpfiles files and their installer, checked with systemd's tools.

What can be checked without booting systemd is checked here: `systemd-analyze verify`,
`systemd-analyze security --offline=true` (exposure ≤ 2.0, parsed from its output), sysusers and
tmpfiles applied to a scratch root, the installer's dry run, and the settings the service relies
on, named one by one, and the ExecStart line run outside systemd. The unit's seccomp lines are
applied for real in tests/systemd/, and the unit is booted under systemd in a container there.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.systemd.unit_file import parse_unit, scratch_config

REPO = Path(__file__).resolve().parents[2]
SYSTEMD = REPO / "systemd"
UNIT = SYSTEMD / "avard.service"
VENV_AVARD = Path(sys.executable).with_name("avard")
MAX_EXPOSURE = 2.0

needs_analyze = pytest.mark.skipif(
    shutil.which("systemd-analyze") is None, reason="systemd-analyze not installed"
)


@pytest.fixture(scope="module")
def unit() -> dict[str, dict[str, list[str]]]:
    return parse_unit(UNIT.read_text())


@pytest.fixture(scope="module")
def local_unit(tmp_path_factory) -> Path:
    """The unit with ExecStart pointed at this venv's `avard` (verify checks it exists)."""
    text = UNIT.read_text().replace("/opt/avard/bin/avard", str(VENV_AVARD))
    assert str(VENV_AVARD) in text
    path = tmp_path_factory.mktemp("unit") / "avard.service"
    path.write_text(text)
    return path


def _one(unit, section: str, key: str) -> str:
    values = unit[section].get(key)
    assert values, f"[{section}] {key}= missing from {UNIT.name}"
    return values[-1]


def _seconds(value: str) -> float:
    """systemd time span ('30s', '30min', '1h 5s', '5') in seconds."""
    scale = {"": 1, "s": 1, "sec": 1, "ms": 1e-3, "min": 60, "m": 60, "h": 3600, "hr": 3600}
    total = 0.0
    for number, unit_name in re.findall(r"(\d+(?:\.\d+)?)\s*([a-z]*)", value):
        total += float(number) * scale[unit_name]
    return total


# ---------------------------------------------------------------- systemd-analyze


@needs_analyze
def test_systemd_analyze_verify_passes(local_unit):
    proc = subprocess.run(
        ["systemd-analyze", "verify", str(local_unit)], capture_output=True, text=True
    )
    assert proc.returncode == 0, proc.stderr
    # verify reports unknown keys and bad values as warnings with exit 0: there must be none.
    complaints = [line for line in proc.stderr.splitlines() if "avard.service" in line]
    assert complaints == []


def _security(path: Path) -> tuple[float, dict[str, tuple[bool, str]]]:
    proc = subprocess.run(
        ["systemd-analyze", "security", "--offline=true", "--no-pager", str(path)],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 0, proc.stderr
    match = re.search(r"Overall exposure level for \S+: (\d+(?:\.\d+)?)", proc.stdout)
    assert match, f"no exposure line in:\n{proc.stdout}"
    checks: dict[str, tuple[bool, str]] = {}
    for line in proc.stdout.splitlines():
        mark = line[:1]
        if mark and mark in "✓✗":
            name = line[1:].split()[0]
            checks[name] = (mark == "✓", line)
    return float(match.group(1)), checks


@needs_analyze
def test_security_exposure_at_most_two(local_unit):
    exposure, checks = _security(local_unit)
    assert exposure <= MAX_EXPOSURE, f"exposure {exposure} > {MAX_EXPOSURE}"
    # The settings the score relies on, each rated as applied by systemd itself.
    relied_on = [
        "User=/DynamicUser=",
        "NoNewPrivileges=",
        "ProtectSystem=",
        "ProtectHome=",
        "PrivateTmp=",
        "ProtectKernelTunables=",
        "ProtectKernelModules=",
        "ProtectKernelLogs=",
        "ProtectControlGroups=",
        "ProtectClock=",
        "ProtectHostname=",
        "ProtectProc=",
        "ProcSubset=",
        "PrivateMounts=",
        "MemoryDenyWriteExecute=",
        "RestrictNamespaces=~user",
        "RestrictAddressFamilies=~AF_PACKET",
        "SystemCallArchitectures=",
        "SystemCallFilter=~@privileged",
        "SystemCallFilter=~@clock",
        "CapabilityBoundingSet=~CAP_SYS_ADMIN",
        "CapabilityBoundingSet=~CAP_SYS_RAWIO",
        "RestrictSUIDSGID=",
        "LockPersonality=",
        "RestrictRealtime=",
        "NotifyAccess=",
    ]
    failed = [checks.get(name, (False, f"{name} not rated"))[1] for name in relied_on
              if not checks.get(name, (False, ""))[0]]
    assert failed == []


@needs_analyze
def test_exposure_score_reacts_to_the_hardening(local_unit, tmp_path):
    # The parse is real: stripping the sandbox must push the same tool's score far up.
    keep = ("Type=", "ExecStart=", "User=", "Group=", "[", "Description=", "WantedBy=")
    bare = "\n".join(
        line for line in local_unit.read_text().splitlines()
        if line.startswith(keep)
    )
    path = tmp_path / "avard.service"
    path.write_text(bare + "\n")
    hardened, _ = _security(local_unit)
    stripped, _ = _security(path)
    assert stripped > hardened + 4.0


# ---------------------------------------------------------------- the settings, by name


def test_runs_as_its_own_user_with_the_bus_groups(unit):
    svc = unit["Service"]
    assert _one(unit, "Service", "User") == "avard"
    assert "DynamicUser" not in svc  # a static user keeps ownership of /var/lib/avard stable
    groups = " ".join(svc["SupplementaryGroups"]).split()
    assert sorted(groups) == ["gpio", "i2c", "spi"]


def test_only_the_bus_devices_are_allowed(unit):
    svc = unit["Service"]
    assert _one(unit, "Service", "DevicePolicy") == "closed"
    # PrivateDevices=yes would hide /dev/spidev* and /dev/i2c-*: it must not be set.
    assert svc.get("PrivateDevices", ["no"])[-1] in {"no", "false", "0"}
    allowed = {value.split()[0]: value.split()[1] for value in svc["DeviceAllow"]}
    assert allowed == {"char-spi": "rw", "char-i2c": "rw", "char-gpiochip": "rw"}


def test_privileges_and_filesystem(unit):
    for key, value in {
        "NoNewPrivileges": "yes",
        "ProtectSystem": "strict",
        "ProtectHome": "yes",
        "StateDirectory": "avard",
        "MemoryDenyWriteExecute": "yes",
        "SystemCallArchitectures": "native",
    }.items():
        assert _one(unit, "Service", key) == value, key
    assert unit["Service"]["CapabilityBoundingSet"] == [""]  # empty: every capability dropped
    assert _one(unit, "Service", "WorkingDirectory") == "/var/lib/avard"
    assert _one(unit, "Service", "RestrictRealtime") == "yes"


DENIED_SETS = ["@privileged", "@resources", "@mount", "@swap", "@reboot", "@raw-io", "@module",
               "@obsolete", "@cpu-emulation", "@debug", "@clock"]


def test_syscall_filter_gives_back_only_sched_setscheduler(unit):
    """An allow list, minus the dangerous sets, plus the one call libzmq cannot start without.

    Every libzmq thread calls pthread_setschedparam() (syscall sched_setscheduler) and aborts
    when it is refused (issue #17: SIGABRT under the real systemd). That call, and nothing else,
    is given back; RestrictRealtime=yes still refuses real-time policies through it."""
    filters = unit["Service"]["SystemCallFilter"]
    assert filters[0] == "@system-service"  # first entry an allow list: default is to deny
    denied = [f for f in filters[1:] if f.startswith("~")]
    allowed_back = [f for f in filters[1:] if not f.startswith("~")]
    assert sorted(" ".join(denied).replace("~", "").split()) == sorted(DENIED_SETS)
    # Order matters (systemd applies the lines in turn): the exception comes after the denial.
    assert filters[-1] == "sched_setscheduler"
    assert allowed_back == ["sched_setscheduler"]
    assert _one(unit, "Service", "SystemCallErrorNumber") == "EPERM"


def test_network_is_tcp_and_unix_only_and_localhost_unless_configured(unit):
    families = _one(unit, "Service", "RestrictAddressFamilies").split()
    # AF_NETLINK only because libzmq's bind calls getifaddrs() and aborts on EAFNOSUPPORT
    # (issue #17); no AF_PACKET, no AF_BLUETOOTH, nothing else.
    assert sorted(families) == ["AF_INET", "AF_INET6", "AF_NETLINK", "AF_UNIX"]
    assert len(unit["Service"]["RestrictAddressFamilies"]) == 1  # one line: no ~ override later
    assert _one(unit, "Service", "IPAddressDeny") == "any"
    assert _one(unit, "Service", "IPAddressAllow") == "localhost"


def test_notify_watchdog_and_restart_policy_fit_a_60_hour_run(unit):
    assert _one(unit, "Service", "Type") == "notify"
    assert _one(unit, "Service", "NotifyAccess") == "main"
    watchdog = _seconds(_one(unit, "Service", "WatchdogSec"))
    assert 5 <= watchdog <= 120  # long enough for an fsync on a slow SD card, short enough to act
    assert _one(unit, "Service", "Restart") == "on-failure"
    # Exit status 2 (bad config, missing device: a human must act) is never restarted.
    assert _one(unit, "Service", "RestartPreventExitStatus").split() == ["2"]
    restart_s = _seconds(_one(unit, "Service", "RestartSec"))
    burst = int(_one(unit, "Unit", "StartLimitBurst"))
    interval = _seconds(_one(unit, "Unit", "StartLimitIntervalSec"))
    # A crash loop trips the limit (burst restarts fit easily in the interval) ...
    assert burst * (restart_s + 1) < interval
    # ... while one crash an hour, for 60 hours, never does.
    assert interval < 3600 * burst
    assert burst >= 3
    assert _one(unit, "Service", "ExecReload").endswith("-HUP $MAINPID")  # SIGHUP reopens files


def test_exec_start_reads_the_config_from_etc_avard(unit):
    argv = _one(unit, "Service", "ExecStart").split()
    assert argv[:2] == ["/opt/avard/bin/avard", "run"]
    assert argv[argv.index("--config") + 1] == "/etc/avard/avard.toml"
    assert "--simulate" not in argv


# ---------------------------------------------------------------- sysusers, tmpfiles, install.sh


def _scratch_root(tmp_path: Path) -> Path:
    root = tmp_path / "root"
    (root / "etc").mkdir(parents=True)
    return root


@pytest.mark.skipif(shutil.which("systemd-sysusers") is None, reason="no systemd-sysusers")
def test_sysusers_makes_the_user_and_the_bus_groups(tmp_path):
    root = _scratch_root(tmp_path)
    subprocess.run(
        ["systemd-sysusers", f"--root={root}", str(SYSTEMD / "avard.sysusers")],
        check=True, capture_output=True,
    )
    passwd_lines = (root / "etc/passwd").read_text().splitlines()
    passwd = {line.split(":")[0]: line.split(":") for line in passwd_lines}
    groups = {line.split(":")[0] for line in (root / "etc/group").read_text().splitlines()}
    assert {"avard", "spi", "i2c", "gpio"} <= groups
    user = passwd["avard"]
    assert int(user[2]) < 1000  # a system user
    assert user[5] == "/var/lib/avard" and user[6].endswith("nologin")


@pytest.mark.skipif(shutil.which("systemd-tmpfiles") is None, reason="no systemd-tmpfiles")
def test_tmpfiles_make_etc_avard_readable_only_by_the_group(tmp_path):
    root = _scratch_root(tmp_path)
    subprocess.run(
        ["systemd-sysusers", f"--root={root}", str(SYSTEMD / "avard.sysusers")],
        check=True, capture_output=True,
    )
    proc = subprocess.run(
        ["systemd-tmpfiles", f"--root={root}", "--create", str(SYSTEMD / "avard.tmpfiles")],
        capture_output=True, text=True,
    )
    assert proc.returncode == 0, proc.stderr
    avard_gid = next(
        int(line.split(":")[2]) for line in (root / "etc/group").read_text().splitlines()
        if line.startswith("avard:")
    )
    for sub in ("etc/avard", "etc/avard/curve"):
        st = (root / sub).stat()
        assert st.st_mode & 0o777 == 0o750, sub
        assert st.st_gid == avard_gid and st.st_uid == 0, sub


@needs_analyze
def test_tmpfiles_make_the_state_directory_as_the_unit_does(unit, tmp_path):
    """install.sh runs `avard check-config` as the avard user before the first start, and
    check-config checks that the data folder is writable: the folder the unit's
    StateDirectory= would make at start must exist by then, with the same owner and mode (the
    real-systemd test found every fresh install refused without it)."""
    root = _scratch_root(tmp_path)
    subprocess.run(["systemd-sysusers", f"--root={root}", str(SYSTEMD / "avard.sysusers")],
                   check=True, capture_output=True)
    proc = subprocess.run(
        ["systemd-tmpfiles", f"--root={root}", "--create", str(SYSTEMD / "avard.tmpfiles")],
        capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    user = _one(unit, "Service", "User")
    uid, gid = next((int(f[2]), int(f[3])) for f in (
        line.split(":") for line in (root / "etc/passwd").read_text().splitlines())
        if f[0] == user)
    st = (root / "var/lib" / _one(unit, "Service", "StateDirectory")).stat()
    assert st.st_mode & 0o777 == int(_one(unit, "Service", "StateDirectoryMode"), 8)
    assert (st.st_uid, st.st_gid) == (uid, gid)


def test_install_script_dry_run_lists_every_step_and_changes_nothing(tmp_path):
    script = SYSTEMD / "install.sh"
    subprocess.run(["bash", "-n", str(script)], check=True)
    proc = subprocess.run(
        ["bash", str(script), "--dry-run", "--prefix", str(tmp_path / "venv"), "--no-start"],
        capture_output=True, text=True,
    )
    assert proc.returncode == 0, proc.stderr
    out = proc.stdout
    for step in (
        f"{tmp_path}/venv/bin/python -m pip install -q {REPO}",
        f"ln -sfn {tmp_path}/venv/bin/avard /usr/local/bin/avard",  # `avard` on PATH
        "systemd-sysusers avard.conf",
        "systemd-tmpfiles --create avard.conf",
        "check-config /etc/avard/avard.toml",
        "systemd-analyze verify /etc/systemd/system/avard.service",
        "systemctl enable avard.service",
    ):
        assert step in out, step
    assert "systemctl restart" not in out and "enable --now" not in out
    assert out.rstrip().endswith("dry run: nothing was installed, changed or started")
    assert "avard is" not in out  # neither "running" nor "enabled": nothing happened
    assert not (tmp_path / "venv").exists()


def test_install_script_dry_run_lists_the_start_and_its_check(tmp_path):
    proc = subprocess.run(
        ["bash", str(SYSTEMD / "install.sh"), "--dry-run", "--prefix", str(tmp_path / "venv")],
        capture_output=True, text=True,
    )
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert lines[-2] == "+ systemctl restart avard.service, then check it stays active"
    assert lines[-1] == "dry run: nothing was installed, changed or started"
    assert "avard is running" not in proc.stdout


def test_install_script_refuses_a_relative_prefix():
    proc = subprocess.run(
        ["bash", str(SYSTEMD / "install.sh"), "--dry-run", "--prefix", "opt/avard"],
        capture_output=True, text=True,
    )
    assert proc.returncode == 2
    assert "absolute path" in proc.stderr


# ---------------------------------------------------------------- the ExecStart line, run


PR_SET_MDWE, PR_MDWE_REFUSE_EXEC_GAIN = 65, 1
# Applies MemoryDenyWriteExecute's rule to the process (and, across execve, to avard): the
# kernel refuses writable+executable mappings, as systemd's seccomp filter does.
MDWE_EXEC = (
    "import ctypes, os, sys\n"
    "libc = ctypes.CDLL(None, use_errno=True)\n"
    f"if libc.prctl({PR_SET_MDWE}, {PR_MDWE_REFUSE_EXEC_GAIN}, 0, 0, 0) != 0:\n"
    "    sys.exit(f'prctl(PR_SET_MDWE) failed: errno {ctypes.get_errno()}')\n"
    "os.execv(sys.argv[1], sys.argv[1:])\n"
)


def _mdwe_supported() -> bool:
    proc = subprocess.run(
        [sys.executable, "-c", MDWE_EXEC, "/bin/true"], capture_output=True, text=True
    )
    return proc.returncode == 0


def _exec_start_argv(unit, config: Path) -> list[str]:
    argv = _one(unit, "Service", "ExecStart").split()
    argv[0] = str(VENV_AVARD)
    argv[argv.index("--config") + 1] = str(config)
    return argv


@pytest.mark.skipif(shutil.which("setpriv") is None, reason="setpriv (util-linux) not installed")
def test_exec_start_runs_unprivileged_with_no_new_privs_and_mdwe(unit, tmp_path):
    """The unit's ExecStart line (plus --simulate, no hardware here) started the way the
    hardening starts it: as an unprivileged user, no new privileges, every capability
    dropped, W^X memory enforced by the kernel, sd_notify socket and watchdog set; it gets
    READY=1, feeds the watchdog, records, and stops cleanly on SIGTERM within TimeoutStopSec."""
    import os
    import signal
    import socket
    import tempfile
    import threading
    import time

    from avard.core.io.recording import RecordingReader

    if not _mdwe_supported():
        pytest.skip("kernel without PR_SET_MDWE (Linux < 6.3)")
    # Outside pytest's 0700 tmp tree, so that the unprivileged user can reach it.
    base = Path(tempfile.mkdtemp(prefix="avard-exec-", dir="/tmp"))
    base.chmod(0o755)
    config = scratch_config(base)
    config.chmod(0o644)
    data = base / "data"
    notify_path = base / "notify.sock"
    notify = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    notify.bind(str(notify_path))
    notify_path.chmod(0o666)
    notify.settimeout(0.05)
    got: list[str] = []
    stop = threading.Event()

    def collect() -> None:
        while not stop.is_set():
            try:
                got.append(notify.recv(4096).decode())
            except TimeoutError:
                continue

    reader = threading.Thread(target=collect, daemon=True)
    reader.start()

    wrapper = ["setpriv", "--no-new-privs", "--inh-caps=-all", "--bounding-set=-all"]
    as_nobody = ["--reuid=65534", "--regid=65534", "--clear-groups"]
    # Root here: become nobody, as User=avard would, if nobody can execute this venv's avard
    # at all (not when its interpreter lies under /root; the rest of the sandbox still holds).
    unprivileged = os.geteuid() == 0 and subprocess.run(
        [*wrapper, *as_nobody, sys.executable, "-c", MDWE_EXEC, str(VENV_AVARD), "--version"],
        capture_output=True
    ).returncode == 0
    if unprivileged:
        os.chown(data, 65534, 65534)
        wrapper += as_nobody
    argv = [*wrapper, sys.executable, "-c", MDWE_EXEC,
            *_exec_start_argv(unit, config), "--simulate", "quiet-lab", "--speed", "20"]
    env = dict(os.environ, NOTIFY_SOCKET=str(notify_path), WATCHDOG_USEC="1000000",
               HOME=str(base), PYTHONUNBUFFERED="1")
    proc = subprocess.Popen(argv, cwd=base, env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 90
        while not any("READY=1" in m for m in got):
            assert proc.poll() is None, proc.communicate()[1][-3000:]
            assert time.monotonic() < deadline, "no READY=1 within 90 s"
            time.sleep(0.05)
        time.sleep(1.5)  # watchdog pings every WATCHDOG_USEC/2 = 0.5 s while samples advance
        t0 = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
        stop_s = time.monotonic() - t0
    finally:
        if proc.poll() is None:
            proc.kill()
        stop.set()
        reader.join(2)
        notify.close()
    assert proc.returncode == 0, err[-3000:]
    assert stop_s < _seconds(_one(unit, "Service", "TimeoutStopSec"))
    assert any("WATCHDOG=1" in m for m in got)
    assert any("STOPPING=1" in m for m in got)
    status = [m for m in got if "STATUS=" in m]
    assert status and re.search(r"\d+ samples", status[-1])
    assert "prctl" not in err  # W^X held: numpy, msgpack, pyzmq never asked for it
    segs = list(data.glob("*.avr"))
    assert segs
    if unprivileged:
        assert all(s.stat().st_uid == 65534 for s in segs)
    reader_ = RecordingReader(data)
    recs = list(reader_)
    assert reader_.problems == [] and any(r["kind"] == "raw" for r in recs)
    shutil.rmtree(base, ignore_errors=True)
