#!/usr/bin/env bash
# Set up a virtual SocketCAN interface for the SocketCAN tests (tests/system/can_transport.rs
# `socketcan_vcan_round_trip`), the way socketcan-rs's scripts/vcan.sh does:
#
#   sudo scripts/vcan.sh [IFACE]          # default vcan0
#
# Needs root (or CAP_NET_ADMIN) and a kernel with the vcan module (CONFIG_CAN_VCAN). Exits
# non-zero with a message saying what is missing otherwise. Idempotent: an existing IFACE is
# only brought up.
set -euo pipefail

IFACE="${1:-vcan0}"
say() { echo "vcan.sh: $*" >&2; }

command -v ip >/dev/null || { say "FAILED: no \`ip\` command (install iproute2)"; exit 1; }

if ! ip link show dev "$IFACE" >/dev/null 2>&1; then
    if [ -d /sys/module/vcan ]; then
        :
    elif command -v modprobe >/dev/null; then
        modprobe vcan 2>/dev/null || say "modprobe vcan failed (no module for this kernel, or not root)"
    else
        say "no modprobe here; relying on vcan being built into the kernel"
    fi
    if ! err="$(ip link add dev "$IFACE" type vcan 2>&1)"; then
        say "FAILED: \`ip link add dev $IFACE type vcan\`: $err"
        case "$err" in
            *"Unknown device type"*|*"not supported"*)
                say "this kernel has no vcan (SocketCAN) support; SocketCAN tests will SKIP" ;;
            *"Operation not permitted"*)
                say "run as root (sudo scripts/vcan.sh $IFACE)" ;;
        esac
        exit 1
    fi
fi
# mtu 72 allows CAN FD frames as well (socketcan-rs does the same); classic CAN works either way.
ip link set dev "$IFACE" mtu 72 2>/dev/null || true
if ! err="$(ip link set up "$IFACE" 2>&1)"; then
    say "FAILED: \`ip link set up $IFACE\`: $err"
    exit 1
fi
say "ok: $(ip -details link show dev "$IFACE" | head -1)"
