#!/bin/sh
# Run a command inside a private user + network namespace with a veth pair v0 <-> v1 (both up).
# Nothing on the host changes; the namespace and the pair vanish when the command exits.
#
#   scripts/netns.sh sh -c 'fieldprobe sim ethercat --iface v1 --device esi/fieldprobe-ek1100.xml & \
#                           sleep 0.2; my-master v0'
#
# Needs `unshare` (util-linux), `ip` (iproute2) and unprivileged user namespaces.
set -eu
if [ "${FIELDPROBE_NETNS_INNER:-}" != 1 ]; then
    FIELDPROBE_NETNS_INNER=1 exec unshare -rn -- "$0" "$@"
fi
ip link add v0 type veth peer name v1
ip link set v0 up
ip link set v1 up
exec "$@"
