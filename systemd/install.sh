#!/usr/bin/env bash
# Install avard as a hardened systemd service on a Raspberry Pi (or any systemd machine).
#
#   sudo systemd/install.sh                 # install, enable and start
#   sudo systemd/install.sh --no-start      # install and enable, start later
#   systemd/install.sh --dry-run            # print what would be done, change nothing
#   sudo systemd/install.sh --prefix /srv/avard   # venv elsewhere than /opt/avard
#
# What it does (each step is idempotent, so running it again upgrades in place):
#   1. a Python venv in PREFIX (default /opt/avard) with avard installed from this checkout,
#      and `avard` on everyone's PATH: a link /usr/local/bin/avard -> PREFIX/bin/avard;
#   2. the system user and groups from systemd/avard.sysusers (systemd-sysusers);
#   3. /etc/avard (root:avard 0750) from systemd/avard.tmpfiles (systemd-tmpfiles);
#   4. /etc/avard/avard.toml from config/avard.toml, only if there is none yet (yours is kept),
#      with the data directory set to the unit's StateDirectory /var/lib/avard;
#   5. `avard check-config` on that file, as the avard user, before anything starts;
#   6. the unit in /etc/systemd/system, daemon-reload, enable (and start unless --no-start);
#   7. unless --no-start: wait until the unit is active and still up a few seconds later, else
#      print the last lines of its journal and exit 1.
# The recording in /var/lib/avard is 0750 avard:avard: read it as a member of the avard group
# (`sudo usermod -aG avard $USER`, then log in again) or with sudo.
# Remove with: systemctl disable --now avard; rm /etc/systemd/system/avard.service
#   /usr/lib/sysusers.d/avard.conf /usr/lib/tmpfiles.d/avard.conf /usr/local/bin/avard;
#   rm -r PREFIX (the recording in /var/lib/avard and the config in /etc/avard are left).
set -euo pipefail

PREFIX=/opt/avard
START=1
DRY=0
usage() { sed -n '2,24p' "$0" | sed 's/^# \{0,1\}//'; }
while [ $# -gt 0 ]; do
    case "$1" in
        --prefix) PREFIX="${2:?--prefix needs a directory}"; shift 2 ;;
        --no-start) START=0; shift ;;
        --dry-run) DRY=1; shift ;;
        -h|--help) usage; exit 0 ;;
        *) echo "install.sh: unknown option '$1' (try --help)" >&2; exit 2 ;;
    esac
done
case "$PREFIX" in
    /*) ;;
    *) echo "install.sh: --prefix must be an absolute path, got '$PREFIX'" >&2; exit 2 ;;
esac

HERE="$(cd "$(dirname "$0")" && pwd)"
REPO="$(dirname "$HERE")"
CONF=/etc/avard/avard.toml
UNIT=/etc/systemd/system/avard.service

run() {
    # Print every step; execute it unless --dry-run.
    printf '+ %s\n' "$*"
    if [ "$DRY" -eq 0 ]; then "$@"; fi
}

if [ "$DRY" -eq 0 ] && [ "$(id -u)" -ne 0 ]; then
    echo "install.sh: must run as root (sudo $0), or use --dry-run to see the steps" >&2
    exit 1
fi
for tool in systemctl systemd-sysusers systemd-tmpfiles python3; do
    command -v "$tool" >/dev/null || {
        echo "install.sh: '$tool' not found; avard's installer needs systemd and python3" >&2
        exit 1
    }
done
python3 -c 'import sys; sys.exit(sys.version_info < (3, 11))' || {
    echo "install.sh: avard needs Python 3.11 or newer (found $(python3 --version))" >&2
    exit 1
}

# 1. The venv. Not --system-site-packages: the service must not depend on what apt installed.
run python3 -m venv "$PREFIX"
run "$PREFIX/bin/python" -m pip install -q --upgrade pip
run "$PREFIX/bin/python" -m pip install -q "$REPO"
run install -D -m 0644 "$REPO/docs/reliability.md" "$PREFIX/share/doc/reliability.md"
# `avard watch`, `avard analyze` ... by name, for every user; a file there that is not a link
# (another avard installed by hand) is kept and said.
LINK=/usr/local/bin/avard
if [ -e "$LINK" ] && [ ! -L "$LINK" ]; then
    echo "= keeping $LINK (not a link; this install's avard is $PREFIX/bin/avard)"
else
    run ln -sfn "$PREFIX/bin/avard" "$LINK"
fi

# 2. and 3. User, groups, /etc/avard.
run install -D -m 0644 "$HERE/avard.sysusers" /usr/lib/sysusers.d/avard.conf
run systemd-sysusers avard.conf
run install -D -m 0644 "$HERE/avard.tmpfiles" /usr/lib/tmpfiles.d/avard.conf
run systemd-tmpfiles --create avard.conf

# 4. The config: never overwrite a config someone edited.
if [ -e "$CONF" ]; then
    echo "= keeping existing $CONF"
else
    # The data directory of the shipped config is for a developer's checkout; the service
    # writes only to its StateDirectory (ProtectSystem=strict makes everything else read-only).
    printf '+ install config/avard.toml as %s (data_dir = /var/lib/avard)\n' "$CONF"
    if [ "$DRY" -eq 0 ]; then
        sed -E 's#^([[:space:]]*data_dir[[:space:]]*=[[:space:]]*).*#\1"/var/lib/avard"#' \
            "$REPO/config/avard.toml" > "$CONF.new"
        chown root:avard "$CONF.new"
        chmod 0640 "$CONF.new"
        mv "$CONF.new" "$CONF"
    fi
fi

# 5. Refuse to install a service that would not start.
run runuser -u avard -- "$PREFIX/bin/avard" check-config "$CONF"

# 6. The unit, pointed at PREFIX.
printf '+ install avard.service as %s (ExecStart in %s)\n' "$UNIT" "$PREFIX"
if [ "$DRY" -eq 0 ]; then
    sed "s#/opt/avard/#$PREFIX/#g" "$HERE/avard.service" > "$UNIT.new"
    chmod 0644 "$UNIT.new"
    mv "$UNIT.new" "$UNIT"
fi
run systemd-analyze verify "$UNIT"
run systemctl daemon-reload
run systemctl enable avard.service
if [ "$DRY" -eq 1 ]; then
    if [ "$START" -eq 1 ]; then
        printf '+ %s\n' "systemctl restart avard.service, then check it stays active"
    fi
    echo "dry run: nothing was installed, changed or started"
    exit 0
fi
GROUP_HINT="the recording in /var/lib/avard is readable by the avard group: 'sudo usermod -aG avard ${SUDO_USER:-\$USER}' (then log in again), or use sudo"
if [ "$START" -eq 0 ]; then
    echo "avard is enabled: start it with 'systemctl start avard'"
    echo "$GROUP_HINT"
    exit 0
fi

# 7. Start and make sure it stays up. Type=notify: `systemctl start` returns once avard sent
#    READY=1 (samples flow) or failed; a unit that dies right after is caught by the second look.
start_failed() {
    echo "install.sh: avard did not start ($1). Last lines of its journal:" >&2
    journalctl -u avard.service -n 15 --no-pager >&2 || true
    echo "install.sh: see more with 'journalctl -u avard -b' and 'systemctl status avard'" >&2
    exit 1
}
# A restart (with avard already running) picks up the new venv and unit.
run systemctl restart avard.service || start_failed "systemctl restart failed"
main_pid=$(systemctl show -p MainPID --value avard.service)
sleep 3
systemctl is-active --quiet avard.service || start_failed "it stopped right after starting"
[ "$(systemctl show -p MainPID --value avard.service)" = "$main_pid" ] ||
    start_failed "it was restarted right after starting"
echo "avard is running: 'systemctl status avard', 'journalctl -u avard -f', 'avard watch tcp://127.0.0.1:5555'"
echo "$GROUP_HINT"
