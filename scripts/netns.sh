#!/usr/bin/env bash
# Runs a command in a private network namespace whose only interface is loopback with a
# multicast route, so LCM's udpm:// traffic never leaves this process tree.
# Usage: scripts/netns.sh COMMAND [ARGS...]
set -euo pipefail
if (($# == 0)); then echo "usage: $0 COMMAND [ARGS...]" >&2; exit 2; fi
if [[ "${PFNAV_IN_NETNS:-}" == "1" ]]; then exec "$@"; fi
if [[ $EUID -eq 0 ]]; then ns=(unshare --net); else ns=(unshare --net --map-root-user); fi
exec "${ns[@]}" env PFNAV_IN_NETNS=1 bash -c '
    set -euo pipefail
    ip link set lo up
    ip link set lo multicast on
    ip route add 224.0.0.0/4 dev lo
    exec "$@"' netns-shell "$@"
