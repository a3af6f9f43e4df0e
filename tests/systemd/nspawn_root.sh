#!/usr/bin/env bash
# Build (once) the minimal Debian bookworm root that tests/systemd/nspawn_test.sh boots.
#   tests/systemd/nspawn_root.sh [CACHE]     # default /var/cache/avard-nspawn
# Prints the root's path. The root is never modified afterwards: the test boots it with
# --volatile=overlay, so every run starts from the same clean system and the cache stays valid.
set -euo pipefail
CACHE="${1:-${AVARD_NSPAWN_CACHE:-/var/cache/avard-nspawn}}"
MIRROR="${AVARD_DEBIAN_MIRROR:-http://deb.debian.org/debian}"
# What a user's Pi has and the unit and install.sh need: systemd as init, D-Bus, Python 3.11
# with venv, and procps for the unit's ExecReload=/bin/kill (not in a minbase root).
PACKAGES=systemd,systemd-sysv,dbus,procps,python3,python3-venv
# The package list is part of the name: changing it builds a new root instead of reusing one.
KEY=$(printf '%s %s' "$PACKAGES" "$MIRROR" | sha256sum | cut -c1-12)
ROOT="$CACHE/bookworm-$KEY"
if [ ! -e "$ROOT/.avard-root-complete" ]; then
    command -v debootstrap >/dev/null || {
        echo "nspawn_root.sh: debootstrap not installed (apt-get install debootstrap)" >&2
        exit 1
    }
    mkdir -p "$CACHE"
    rm -rf "$ROOT.tmp"
    echo "nspawn_root.sh: debootstrap bookworm into $ROOT (once; a few minutes)" >&2
    debootstrap --variant=minbase --include="$PACKAGES" bookworm "$ROOT.tmp" "$MIRROR" \
        > "$CACHE/debootstrap.log" 2>&1 || {
        echo "nspawn_root.sh: debootstrap failed; last lines of $CACHE/debootstrap.log:" >&2
        tail -n 20 "$CACHE/debootstrap.log" >&2
        exit 1
    }
    # A machine-id makes journald keep one journal; the hostname names the container's logs.
    systemd-machine-id-setup --root="$ROOT.tmp" >/dev/null
    echo avard-test > "$ROOT.tmp/etc/hostname"
    rm -rf "$ROOT.tmp/var/cache/apt/archives/"*.deb
    touch "$ROOT.tmp/.avard-root-complete"
    rm -rf "$ROOT"
    mv "$ROOT.tmp" "$ROOT"
fi
echo "$ROOT"
