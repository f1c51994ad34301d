#!/bin/sh
# The paced EtherCAT cycle against this machine's own floor (issue 13 item 7).
#
#   scripts/cycle-bench.sh [SECONDS] [PERIOD_US...]      (default: 10 s at 1000 250 125 100 µs)
#
# For each period, inside a private network namespace with a veth pair v0 <-> v1:
#   * `fieldprobe sim ethercat` plays a coupler and eight CiA 402 servos on v1 (its own clock);
#   * `fieldprobe run` moves the eight axes of examples/machines/bench8.toml back and forth for
#     SECONDS on v0 (release build, SCHED_FIFO 80 when permitted) and prints its cycle summary
#     (period error mean / p50 / p99 / max, overruns, late frames);
#   * `cyclictest` (Debian rt-tests) runs at the same period, priority and length alongside,
#     the wake-up latency floor this kernel allows a periodic thread.
# Needs root (network namespace, SCHED_FIFO), `cyclictest` and a release build
# (`cargo build --release`). Prints one block per period; nothing leaves the namespace.
set -eu
if [ "${FIELDPROBE_BENCH_INNER:-}" != 1 ]; then
    FIELDPROBE_BENCH_INNER=1 exec unshare -n -- "$0" "$@"
fi
cd "$(dirname "$0")/.."
BIN=target/release/fieldprobe
SECONDS_RUN=${1:-10}
[ $# -gt 0 ] && shift
PERIODS=${*:-1000 250 125 100}
[ -x "$BIN" ] || { echo "cycle-bench: build first: cargo build --release" >&2; exit 2; }
command -v cyclictest >/dev/null || { echo "cycle-bench: cyclictest missing (apt-get install rt-tests)" >&2; exit 2; }
ip link add v0 type veth peer name v1
ip link set v0 up
ip link set v1 up
PRIO="--rt-priority 80"
$BIN run examples/nc/hello.nc --link ethercat:nonexistent $PRIO 2>&1 | grep -q "rt-priority" && PRIO=""
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
# A program of about SECONDS: eight axes 0 -> 100 -> 0 at 6000 mm/min (2 s per round trip).
ROUNDS=$(( (SECONDS_RUN + 1) / 2 ))
{
    echo "%bench8"
    echo "N1 G90 G01 X0 Y0 Z0 U0 V0 W0 X2=0 Y2=0 F6000"
    i=0
    while [ $i -lt "$ROUNDS" ]; do
        echo "X100 Y100 Z100 U100 V100 W100 X2=100 Y2=100"
        echo "X0 Y0 Z0 U0 V0 W0 X2=0 Y2=0"
        i=$((i + 1))
    done
    echo "M30"
} > "$TMP/bench8.nc"
DEV="--device esi/fieldprobe-ek1100.xml --device esi/fieldprobe-cia402-servo.xml:8"
for P in $PERIODS; do
    timeout $((SECONDS_RUN * 4 + 30)) $BIN sim ethercat --iface v1 $DEV --seconds $((SECONDS_RUN * 4 + 20)) \
        2>"$TMP/emu.log" &
    EMU=$!
    i=0
    while ! grep -q "listening on" "$TMP/emu.log" 2>/dev/null && [ $i -lt 100 ]; do
        sleep 0.1; i=$((i + 1))
    done
    LOOPS=$((SECONDS_RUN * 1000000 / P))
    CT_PRIO=80; [ -z "$PRIO" ] && CT_PRIO=0
    cyclictest -m -q -p "$CT_PRIO" -i "$P" -l "$LOOPS" > "$TMP/ct.txt" 2>&1 &
    CT=$!
    timeout $((SECONDS_RUN * 4 + 20)) $BIN run "$TMP/bench8.nc" --machine examples/machines/bench8.toml \
        --link ethercat:v0 --set cycle_time_us="$P" $PRIO --mlock >/dev/null 2>"$TMP/run.log" || true
    wait "$CT" || true
    kill "$EMU" 2>/dev/null || true
    wait "$EMU" 2>/dev/null || true
    echo "== period $P µs, 8 axes, ${SECONDS_RUN} s"
    grep '^cycle:' "$TMP/run.log" || { echo "run failed:"; tail -3 "$TMP/run.log"; }
    grep -E '^error' "$TMP/run.log" | head -2 || true
    echo "cyclictest (same period and priority): $(grep -E 'Min:' "$TMP/ct.txt" | sed 's/.*Min:/Min:/')"
done
