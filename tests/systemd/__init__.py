"""The systemd unit under its own sandbox: seccomp applied for real, and booted in a container."""
