#!/bin/sh
# The paced EtherCAT cycle against this machine's own floor (issue 13 item 7).
#
#   scripts/cycle-bench.sh [SECONDS] [PERIOD_US...]      (default: about 10 s at 1000 250 125 100 µs)
#
# For each period, inside a private network namespace with a veth pair v0 <-> v1:
#   * `fieldprobe sim ethercat` plays a coupler and eight CiA 402 servos on v1 (its own clock,
#     SCHED_FIFO 70 when permitted: the devices stand for hardware);
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
# A program of about SECONDS: eight axes 0 -> 100 -> 0 at a path feed of 6000 mm/min; the
# path of one move is sqrt(8) * 100 mm = 283 mm, 2.83 s, so a round trip takes 5.66 s.
ROUNDS=$(( (SECONDS_RUN * 100 + 565) / 566 ))
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
RUN_S=$((ROUNDS * 566 / 100 + 1))
DEV="--device esi/fieldprobe-ek1100.xml --device esi/fieldprobe-cia402-servo.xml:8"
# Wake-up latency (send time - deadline, µs) of the master's cycles from its cycle log:
# "p50 p99 max count>P/2". The master spins the last 50 µs before a deadline (cyclictest does
# not), so its p50 is about 0; a cycle whose work ran past the next deadline is an overrun in the
# summary line instead (its slot had no frame).
master_latency() {
    awk -F, 'NR > 1 { print $3 - $2 }' "$2" | sort -n |
        awk -v half="$(($1 / 2))" '{ v[NR] = $1; if ($1 > half) late++ }
            END { printf "%.0f %.0f %.0f %d\n", v[int(NR * 0.5) + 1], v[int(NR * 0.99) + 1], v[NR], late }'
}
# The same from cyclictest's histogram (-h): "p50 p99 max count>P/2".
cyclictest_latency() {
    awk -v half="$(($1 / 2))" '
        /^[0-9]+ +[0-9]+/ { n[$1 + 0] = $2; tot += $2; if ($1 + 0 > half) late += $2 }
        /Histogram Overflows/ { over = $NF + 0 }
        /Max Latencies/ { max = $NF + 0 }
        END { tot += over; late += over; c = 0
              for (i = 0; i in n || c < tot; i++) { c += n[i]
                  if (p50 == "" && c >= 0.5 * tot) p50 = i
                  if (p99 == "" && c >= 0.99 * tot) p99 = i
                  if (i > 100000) break }
              printf "%d %d %d %d\n", p50, p99, max, late }' "$2"
}
for P in $PERIODS; do
    EMU_PRIO=""; [ -n "$PRIO" ] && EMU_PRIO="--rt-priority 70 --mlock"
    timeout $((RUN_S * 2 + 30)) $BIN sim ethercat --iface v1 $DEV --seconds $((RUN_S * 2 + 20)) \
        $EMU_PRIO 2>"$TMP/emu.log" &
    EMU=$!
    i=0
    while ! grep -q "listening on" "$TMP/emu.log" 2>/dev/null && [ $i -lt 100 ]; do
        sleep 0.1; i=$((i + 1))
    done
    LOOPS=$((RUN_S * 1000000 / P))
    CT_PRIO=80; [ -z "$PRIO" ] && CT_PRIO=0
    cyclictest -m -q -p "$CT_PRIO" -i "$P" -l "$LOOPS" -h $((P * 4)) > "$TMP/ct.txt" 2>&1 &
    CT=$!
    timeout $((RUN_S * 2 + 20)) $BIN run "$TMP/bench8.nc" --machine examples/machines/bench8.toml \
        --link ethercat:v0 --set cycle_time_us="$P" $PRIO --mlock --cycle-log "$TMP/cycles.csv" \
        >/dev/null 2>"$TMP/run.log" || true
    wait "$CT" || true
    kill "$EMU" 2>/dev/null || true
    wait "$EMU" 2>/dev/null || true
    echo "== period $P µs, 8 axes, ${RUN_S} s"
    grep '^cycle:' "$TMP/run.log" || { echo "run failed:"; tail -3 "$TMP/run.log"; continue; }
    grep -E '^error' "$TMP/run.log" | head -2 || true
    set -- $(master_latency "$P" "$TMP/cycles.csv")
    M50=$1 M99=$2 MMAX=$3 MLATE=$4
    set -- $(cyclictest_latency "$P" "$TMP/ct.txt")
    C50=$1 C99=$2 CMAX=$3 CLATE=$4
    OVR=$(sed -n 's/.*overruns \([0-9]*\).*/\1/p' "$TMP/run.log")
    echo "wake-up latency, µs (p50 / p99 / max, wakes later than P/2):"
    echo "  master     $M50 / $M99 / $MMAX, $MLATE"
    echo "  cyclictest $C50 / $C99 / $CMAX, $CLATE"
    awk -v a="$M99" -v b="$C99" -v c="$MMAX" -v d="$CMAX" 'BEGIN {
        printf "  ratio master / cyclictest: p99 %.2f, max %.2f\n", a / (b > 0 ? b : 1), c / (d > 0 ? d : 1) }'
    echo "  slots without a frame: master overruns $OVR, cyclictest wakes later than P/2: $CLATE"
done
