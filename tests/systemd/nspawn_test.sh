#!/usr/bin/env bash
# avard's unit under a real systemd: boot Debian bookworm in systemd-nspawn, install avard with
# systemd/install.sh --no-start as a user would, and check what only systemd as PID 1 can show.
#
#   sudo tests/systemd/nspawn_test.sh      # .ci/run runs it after `make test`
#
# Needs root, systemd-nspawn (apt-get install systemd-container), debootstrap, and the network
# once: the root (~250 MB, /var/cache/avard-nspawn, AVARD_NSPAWN_CACHE to move it) and the
# wheels of avard's dependencies are built on the first run and reused. Inside the container pip
# never reaches the network: install.sh runs with PIP_NO_INDEX=1 and PIP_FIND_LINKS=/wheels.
# The root boots with --volatile=overlay, so every run starts from the same clean system.
# Checks: the unit starts (READY=1, status line), `avard watch --once` gets data through the
# IP firewall (and the firewall and device cgroup are really enforced here), it stays up past
# two watchdog periods, kill -9 of the main PID is followed by a restart that restores the
# Allan state, reload opens a new segment, `systemctl stop` is clean, `systemd-analyze
# security avard` (online) rates it ≤ MAX_EXPOSURE, and install.sh's own start works and,
# for a config that cannot start (exit 2), fails loudly without a restart loop.
# Wall time: about 3 min with the cache, 8 min cold (debootstrap and wheels first).
# AVARD_NSPAWN_KEEP=1 keeps the logs (journals, install and watch output) of a passing run.
# Exit 0: all held. 1: a check failed, or the container cannot run under CI=true.
# 77: the container cannot run here (not under CI); the reason is printed.
set -euo pipefail
HERE="$(cd "$(dirname "$0")" && pwd)"
REPO="$(cd "$HERE/../.." && pwd)"
CACHE="${AVARD_NSPAWN_CACHE:-/var/cache/avard-nspawn}"
PYTHON="${PYTHON:-$REPO/.venv/bin/python}"
MAX_EXPOSURE=2.0
T_START=$(date +%s)

say() { printf 'nspawn_test: %s\n' "$*"; }
cannot_run() {
    # Where the container cannot run: say exactly why; in CI that is a failure, not a pass.
    say "CANNOT RUN: $*" >&2
    if [ "${CI:-}" = true ]; then exit 1; fi
    exit 77
}
[ "$(id -u)" -eq 0 ] || cannot_run "needs root (systemd-nspawn and debootstrap); run it with sudo"
for tool in systemd-nspawn debootstrap nsenter; do
    command -v "$tool" >/dev/null ||
        cannot_run "'$tool' not found (apt-get install systemd-container debootstrap util-linux)"
done
grep -qw cgroup2 /proc/filesystems || cannot_run "the kernel has no cgroup2 (the unit needs it)"
[ -x "$PYTHON" ] || cannot_run "no $PYTHON to build the wheels with (run 'make .venv/.installed-run')"

ROOT="$("$HERE/nspawn_root.sh" "$CACHE")" || cannot_run "could not build the Debian root"

# Wheels of avard's dependencies and of its build backend, built on the host once per
# pyproject.toml and Python version (the root's Python is the host's: both bookworm, 3.11).
PYVER=$("$PYTHON" -c 'import sys; print("%d.%d" % sys.version_info[:2])')
WKEY=$( (cat "$REPO/pyproject.toml"; echo "$PYVER") | sha256sum | cut -c1-12)
WHEELS="$CACHE/wheels-$WKEY"
if [ ! -e "$WHEELS/.complete" ]; then
    say "building wheels into $WHEELS (once)"
    rm -rf "$WHEELS.tmp"
    mkdir -p "$CACHE"
    "$PYTHON" -m pip wheel -q --wheel-dir "$WHEELS.tmp" "$REPO" pip "setuptools>=68" wheel \
        > "$CACHE/pip-wheel.log" 2>&1 || {
        tail -n 20 "$CACHE/pip-wheel.log" >&2
        cannot_run "pip wheel failed: no wheels for the container (log above)"
    }
    # avard itself is built inside, from the source tree, by install.sh as a user's pip would.
    rm -f "$WHEELS.tmp"/avard-*.whl
    touch "$WHEELS.tmp/.complete"
    rm -rf "$WHEELS"
    mv "$WHEELS.tmp" "$WHEELS"
fi

# The checkout as a user has it (tracked and new files, not .venv or build outputs).
WORK="$(mktemp -d /tmp/avard-nspawn.XXXXXX)"
mkdir "$WORK/src"
if git -C "$REPO" rev-parse --git-dir >/dev/null 2>&1; then
    git -C "$REPO" ls-files -co --exclude-standard -z |
        (cd "$REPO" && tar --null -T - -cf -) | tar -xf - -C "$WORK/src"
else  # an unpacked release, not a git checkout
    tar -C "$REPO" --exclude=./.venv --exclude=./build --exclude='*.egg-info' \
        --exclude=__pycache__ -cf - . | tar -xf - -C "$WORK/src"
fi

MACHINE="avard-test-$$"
NSPAWN_PID=""
LEADER=""
cleanup() {
    local rc=$?
    if [ -n "$LEADER" ] && kill -0 "$LEADER" 2>/dev/null; then
        nsenter -t "$LEADER" -a systemctl poweroff >/dev/null 2>&1 || true
    fi
    if [ -n "$NSPAWN_PID" ]; then
        for _ in $(seq 40); do kill -0 "$NSPAWN_PID" 2>/dev/null || break; sleep 0.5; done
        kill "$NSPAWN_PID" 2>/dev/null || true
        wait "$NSPAWN_PID" 2>/dev/null || true
    fi
    if [ "$rc" -eq 0 ] && [ -z "${AVARD_NSPAWN_KEEP:-}" ]; then rm -rf "$WORK"
    else say "logs kept in $WORK" >&2; fi
}
trap cleanup EXIT

# The host here may have no systemd as PID 1 (no machined, no scope units) and a legacy cgroup
# tree: --register=no and --keep-unit keep nspawn away from the host's service manager, and
# SYSTEMD_NSPAWN_UNIFIED_HIERARCHY=1 gives the container the unified cgroup v2 hierarchy that
# DeviceAllow= and IPAddressDeny= (BPF programs attached to cgroups) need.
# --system-call-filter=bpf: nspawn's own seccomp filter refuses bpf(), and without it the
# container's systemd silently applies neither DeviceAllow= nor IPAddressDeny= (check 4b).
# --private-network: the container's own loopback, so port 5555 never clashes with the host.
SYSTEMD_NSPAWN_UNIFIED_HIERARCHY=1 systemd-nspawn --quiet -D "$ROOT" --volatile=overlay \
    --register=no --keep-unit --system-call-filter=bpf --private-network --console=pipe \
    -M "$MACHINE" \
    --bind="$WORK/src:/src/avard" --bind-ro="$WHEELS:/wheels" -b \
    > "$WORK/console.log" 2>&1 < /dev/null &
NSPAWN_PID=$!

# The container's PID 1 is nspawn's child; commands run in its namespaces with nsenter, so no
# machined (machinectl, systemd-run -M) is needed on the host.
for _ in $(seq 120); do
    # nspawn's first child only sets up the namespaces; PID 1 is the one running systemd.
    for pid in $(pgrep -P "$NSPAWN_PID" || true); do
        [ "$(cat "/proc/$pid/comm" 2>/dev/null)" = systemd ] && LEADER=$pid
    done
    [ -n "$LEADER" ] && break
    kill -0 "$NSPAWN_PID" 2>/dev/null || break
    sleep 0.5
done
if [ -z "$LEADER" ]; then
    tail -n 20 "$WORK/console.log" >&2 || true
    cannot_run "systemd-nspawn did not start a container (console log above)"
fi
in_ct() {
    nsenter -t "$LEADER" -a env -i PATH=/usr/sbin:/usr/bin:/sbin:/bin LANG=C.UTF-8 "$@"
}
# Until its PID 1 has opened its private bus, systemctl cannot connect, and just before it
# has, it answers "offline" (the manager is not up yet; seen once on a loaded CI machine):
# retry either until the deadline.
boot_deadline=$(( $(date +%s) + 90 ))
while :; do
    state=$(in_ct timeout 90 systemctl is-system-running --wait 2>&1 || true)
    [[ "$state" == *"Failed to connect"* || "$state" == offline ]] \
        && [ "$(date +%s)" -lt "$boot_deadline" ] || break
    sleep 0.5
done
case "$state" in
    running|degraded) say "container booted ($state) in $(( $(date +%s) - T_START )) s" ;;
    *) tail -n 20 "$WORK/console.log" >&2 || true
       cannot_run "the container's systemd did not finish booting (state '$state')" ;;
esac

FAILED=0
ok() { say "ok: $*"; }
since_s() { awk -v a="$1" -v b="$(date +%s.%N)" 'BEGIN {printf "%.2f", b - a}'; }
bad() { say "FAIL: $*" >&2; FAILED=1; }
prop() { in_ct systemctl show -p "$1" --value avard.service; }
journal() { in_ct journalctl -u avard.service --no-pager -o short-monotonic "$@"; }
finish() {
    journal > "$WORK/avard.journal" 2>&1 || true
    in_ct journalctl -b --no-pager -o short-monotonic > "$WORK/system.journal" 2>&1 || true
    if [ "$FAILED" -ne 0 ]; then
        say "journal of avard.service (last 40 lines; all in $WORK/avard.journal):" >&2
        tail -n 40 "$WORK/avard.journal" >&2
        exit 1
    fi
    say "all checks held in $(( $(date +%s) - T_START )) s"
    exit 0
}

# 1. Install exactly as a user would, but with pip offline.
if in_ct PIP_NO_INDEX=1 PIP_FIND_LINKS=/wheels PIP_DISABLE_PIP_VERSION_CHECK=1 \
        PIP_ROOT_USER_ACTION=ignore /src/avard/systemd/install.sh --no-start \
        > "$WORK/install.log" 2>&1; then
    ok "systemd/install.sh --no-start"
else
    tail -n 30 "$WORK/install.log" >&2
    bad "systemd/install.sh --no-start failed"; finish
fi

# 2. The emulated sensor instead of the ADXL355: a drop-in, as `systemctl edit avard` makes.
in_ct mkdir -p /etc/systemd/system/avard.service.d
printf '%s\n' '[Service]' 'ExecStart=' \
    'ExecStart=/opt/avard/bin/avard run --config /etc/avard/avard.toml --simulate quiet-lab' |
    in_ct tee /etc/systemd/system/avard.service.d/simulate.conf > /dev/null
in_ct systemctl daemon-reload

# 3. Start: for Type=notify, `systemctl start` returns once READY=1 arrived.
t0=$(date +%s.%N)
if in_ct systemctl start avard.service; then
    ok "started and READY=1 after $(since_s "$t0") s"
else
    bad "systemctl start avard failed"; finish
fi
[ "$(prop ActiveState)/$(prop SubState)" = active/running ] && ok "active/running" ||
    bad "not active/running: $(prop ActiveState)/$(prop SubState)"
status=$(prop StatusText)
[[ "$status" =~ [0-9]+\ samples ]] && ok "STATUS: $status" || bad "no status line: '$status'"
MAIN=$(prop MainPID)

# 4. Data through the IP firewall (IPAddressAllow=localhost), as the avard user would see it.
if in_ct timeout 60 runuser -u avard -- /opt/avard/bin/avard watch tcp://127.0.0.1:5555 \
        --once --wait 30 > "$WORK/watch.txt" 2>&1 && grep -q "ADEV" "$WORK/watch.txt"; then
    ok "avard watch --once: $(grep -m1 -i "samples" "$WORK/watch.txt" | tr -s ' ')"
else
    cat "$WORK/watch.txt" >&2; bad "avard watch --once got no data"
fi

# 4b. The cgroup sandboxing is really enforced in this container (else 4 proves little): the
#     same connection from a transient unit is refused under IPAddressDeny=any alone, and a
#     device outside DeviceAllow= is refused under DevicePolicy=strict.
probe() { in_ct timeout 30 systemd-run --quiet --wait --pipe --collect "$@" > /dev/null 2>&1; }
connect='import socket; socket.create_connection(("127.0.0.1", 5555), timeout=3)'
if probe -p IPAddressDeny=any -p IPAddressAllow=localhost python3 -c "$connect" &&
        ! probe -p IPAddressDeny=any python3 -c "$connect"; then
    ok "IP firewall enforced (localhost allowed, everything else refused)"
else
    bad "IPAddressDeny= is not enforced here: the IP firewall check above proves nothing"
fi
if probe -p DevicePolicy=strict -p "DeviceAllow=/dev/urandom r" head -c1 /dev/urandom &&
        ! probe -p DevicePolicy=strict -p "DeviceAllow=/dev/null rw" head -c1 /dev/urandom; then
    ok "device cgroup enforced (DevicePolicy=strict refuses what DeviceAllow= does not name)"
else
    bad "DevicePolicy=/DeviceAllow= are not enforced in this container"
fi

# 5. Past two watchdog periods with the same process, no restart, and a checkpoint written.
wd_us=$(prop WatchdogUSec)
wd_s=$(in_ct systemd-analyze timespan "$wd_us" | awk '/μs:|us:/ {print int($2 / 1e6)}')
[ "${wd_s:-0}" -gt 0 ] || { bad "no watchdog configured (WatchdogUSec=$wd_us)"; finish; }
until_s=$(( $(date +%s) + 2 * wd_s + 5 ))
while [ "$(date +%s)" -lt "$until_s" ] || ! in_ct test -e /var/lib/avard/allan-state.ckpt; do
    [ "$(prop ActiveState)" = active ] || break
    [ "$(date +%s)" -lt $(( until_s + 120 )) ] || break
    sleep 2
done
if [ "$(prop ActiveState)" = active ] && [ "$(prop MainPID)" = "$MAIN" ] &&
        [ "$(prop NRestarts)" = 0 ]; then
    ok "still up after 2 × WatchdogSec=${wd_s}s, same PID, no restart"
else
    bad "did not stay up past two watchdog periods ($(prop ActiveState), PID $(prop MainPID)," \
        "NRestarts=$(prop NRestarts))"
    finish
fi
in_ct test -e /var/lib/avard/allan-state.ckpt && ok "Allan checkpoint written" ||
    bad "no Allan checkpoint in /var/lib/avard"

# 6. kill -9 of the main PID: systemd restarts it and the Allan state is restored.
since=$(in_ct date '+%Y-%m-%d %H:%M:%S')
in_ct kill -9 "$MAIN"
for _ in $(seq 60); do
    [ "$(prop NRestarts)" = 1 ] && [ "$(prop ActiveState)" = active ] &&
        [ "$(prop SubState)" = running ] && break
    sleep 1
done
if [ "$(prop NRestarts)" = 1 ] && [ "$(prop ActiveState)" = active ]; then
    ok "restarted after kill -9 (PID $MAIN → $(prop MainPID))"
else
    bad "no restart after kill -9 ($(prop ActiveState), NRestarts=$(prop NRestarts))"
fi
restored=$(journal --since "$since" | grep -m1 "restored the Allan accumulators" || true)
[[ "$restored" == *replayed* ]] && ok "${restored#*avard*: }" ||
    bad "the journal after the restart says nothing about restoring the Allan state"

# 6b. systemctl reload: ExecReload= sends SIGHUP (log rotation), the recording goes on in a
#     new segment file, and the process is the same.
reload_at=$(in_ct date '+%Y-%m-%d %H:%M:%S')
main_before=$(prop MainPID)
segments_before=$(in_ct sh -c 'ls /var/lib/avard/*.avr | wc -l')
in_ct systemctl reload avard.service || bad "systemctl reload avard failed"
for _ in $(seq 20); do
    [ "$(in_ct sh -c 'ls /var/lib/avard/*.avr | wc -l')" -gt "$segments_before" ] && break
    sleep 0.5
done
if [ "$(in_ct sh -c 'ls /var/lib/avard/*.avr | wc -l')" -gt "$segments_before" ] &&
        [ "$(prop MainPID)" = "$main_before" ] &&
        journal --since "$reload_at" | grep -q "reopening the recording"; then
    ok "systemctl reload: a new segment, same process"
else
    bad "systemctl reload did not open a new segment in the same process"
fi

# 7. A clean stop: SIGTERM, flushed and closed, exit status 0, no SIGKILL needed.
t0=$(date +%s.%N)
in_ct systemctl stop avard.service
stop_s=$(since_s "$t0")
if [ "$(prop Result)" = success ] && [ "$(prop ExecMainStatus)" = 0 ] &&
        ! journal --since "$since" | grep -q "Killing process"; then
    ok "systemctl stop: clean in $stop_s s (exit 0)"
else
    bad "unclean stop: Result=$(prop Result) ExecMainStatus=$(prop ExecMainStatus)"
fi
if journal | grep -Eq "Operation not permitted \(|Address family not supported|status=6/ABRT"; then
    bad "libzmq aborted at some point (see the journal)"
fi

# 8. The exposure rating of the unit as loaded by this systemd (not --offline).
in_ct systemd-analyze security --no-pager avard.service > "$WORK/security.txt" 2>&1 || true
exposure=$(sed -n 's/.*Overall exposure level for avard.service: \([0-9.]*\).*/\1/p' \
    "$WORK/security.txt")
if [ -n "$exposure" ] && awk -v e="$exposure" -v m="$MAX_EXPOSURE" 'BEGIN {exit !(e <= m)}'; then
    ok "systemd-analyze security avard (online): exposure $exposure ≤ $MAX_EXPOSURE"
else
    cat "$WORK/security.txt" >&2
    bad "online exposure '${exposure:-none}' is not ≤ $MAX_EXPOSURE"
fi

# 9. install.sh's own start: a service that cannot start (exit 2, here a missing config) makes
#    it fail with the journal's last lines, and RestartPreventExitStatus=2 means no restarts.
install_start() {
    in_ct PIP_NO_INDEX=1 PIP_FIND_LINKS=/wheels PIP_DISABLE_PIP_VERSION_CHECK=1 \
        PIP_ROOT_USER_ACTION=ignore /src/avard/systemd/install.sh > "$WORK/$1.log" 2>&1
}
printf '%s\n' '[Service]' 'ExecStart=' \
    'ExecStart=/opt/avard/bin/avard run --config /etc/avard/missing.toml --simulate quiet-lab' |
    in_ct tee /etc/systemd/system/avard.service.d/zz-broken.conf > /dev/null
if install_start install-broken; then
    bad "install.sh said it worked with a service that cannot start"
elif grep -q "no such config file" "$WORK/install-broken.log" &&
        grep -q "journalctl -u avard" "$WORK/install-broken.log"; then
    ok "install.sh with a broken config: exit 1, the journal's error line and where to look"
else
    tail -n 20 "$WORK/install-broken.log" >&2
    bad "install.sh failed without showing the service's error"
fi
sleep 7  # longer than RestartSec=5s: a restart would have happened by now
if [ "$(prop ExecMainStatus)" = 2 ] && [ "$(prop NRestarts)" = 0 ] &&
        [ "$(prop ActiveState)" = failed ]; then
    ok "exit status 2 is not restarted (RestartPreventExitStatus=2)"
else
    bad "exit 2: ExecMainStatus=$(prop ExecMainStatus) NRestarts=$(prop NRestarts)" \
        "ActiveState=$(prop ActiveState)"
fi
in_ct rm /etc/systemd/system/avard.service.d/zz-broken.conf
in_ct systemctl reset-failed avard.service
if install_start install-start && grep -q "^avard is running" "$WORK/install-start.log" &&
        [ "$(prop ActiveState)" = active ]; then
    ok "install.sh starts the unit and waits until it is active"
else
    tail -n 20 "$WORK/install-start.log" >&2
    bad "install.sh did not start the unit"
fi
in_ct systemctl stop avard.service
finish
