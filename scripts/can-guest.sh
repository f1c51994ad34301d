#!/usr/bin/env bash
# Run a command inside a small Linux guest that has SocketCAN, for the SocketCAN tests on a
# machine whose own kernel has none (tests/system/socketcan.rs, docs/canopen.md "SocketCAN tests").
#
#   scripts/can-guest.sh [--timeout SECS] [--] COMMAND [ARG]...   run COMMAND in the guest
#   scripts/can-guest.sh --check                                  say whether a guest can run
#   scripts/can-guest.sh --build                                  only build (or find) the guest
#
# The guest is Debian's own kernel (linux-image-amd64, its modules vcan, can-raw, can-bcm,
# can-gw, veth, 9p) booted by qemu-system-x86_64 under software emulation (TCG; KVM is not
# needed) with a busybox initramfs. Its root is this machine's whole filesystem over 9p, so the
# test binaries, the python venvs and can-utils run unchanged; the guest's /tmp, /run and
# /dev/shm are its own tmpfs. COMMAND runs as root in the current directory with the current
# environment, with `lo` and `vcan0` up. Its stdout and stderr are printed after it ends (to
# stdout and stderr), and its exit status is this script's.
#
# Exit status: COMMAND's; 124 when it ran out of time (the guest is killed); 125 when no guest
# can run here (the message says what is missing: qemu-system-x86, busybox-static, cpio, kmod,
# or the kernel package that `apt-get download` fetches).
#
# The guest (kernel + initramfs, ~10 MB) is built once from Debian packages into the cache,
# ${FIELDPROBE_GUEST_DIR:-${XDG_CACHE_HOME:-$HOME/.cache}/fieldprobe-guest}, outside the repo,
# and rebuilt when missing. Nothing is installed on the host by this script; .ci/run installs
# the packages (apt-get install qemu-system-x86 busybox-static cpio kmod can-utils).
#
# Environment: FIELDPROBE_GUEST_DIR (cache), FIELDPROBE_GUEST_MEM (MiB, default 2048),
# FIELDPROBE_GUEST_CPUS (default: the host's CPU count, at most 4), FIELDPROBE_GUEST_KERNEL_PKG
# (default: what linux-image-amd64 depends on), FIELDPROBE_GUEST_QEMU (default
# qemu-system-x86_64).
set -euo pipefail

say() { echo "can-guest: $*" >&2; }
die_missing() { say "no guest can run here: $*"; exit 125; }

TIMEOUT=900
MODE=run
while [ $# -gt 0 ]; do
    case "$1" in
        --timeout) TIMEOUT="${2:?--timeout needs seconds}"; shift 2 ;;
        --check) MODE=check; shift ;;
        --build) MODE=build; shift ;;
        --) shift; break ;;
        -*) say "unknown option $1 (allowed: --timeout SECS, --check, --build, --)"; exit 2 ;;
        *) break ;;
    esac
done
case "$TIMEOUT" in
    ''|*[!0-9]*) say "--timeout $TIMEOUT: expected whole seconds 1..86400"; exit 2 ;;
esac
if [ "$MODE" = run ] && [ $# -eq 0 ]; then
    say "usage: scripts/can-guest.sh [--timeout SECS] [--] COMMAND [ARG]..."
    exit 2
fi

CACHE="${FIELDPROBE_GUEST_DIR:-${XDG_CACHE_HOME:-$HOME/.cache}/fieldprobe-guest}"
MODULES="vcan can-raw can-bcm can-gw veth 9p 9pnet_virtio virtio_pci"

QEMU="${FIELDPROBE_GUEST_QEMU:-qemu-system-x86_64}"
missing=""
for c in "$QEMU:qemu-system-x86" busybox:busybox-static cpio:cpio depmod:kmod \
    modprobe:kmod dpkg-deb:dpkg; do
    command -v "${c%%:*}" >/dev/null 2>&1 || missing="$missing ${c##*:}"
done
if [ -n "$missing" ]; then
    die_missing "install the Debian packages:$missing"
fi
BUSYBOX="$(command -v busybox)"
if ldd "$BUSYBOX" >/dev/null 2>&1; then
    die_missing "busybox at $BUSYBOX is dynamically linked (install busybox-static)"
fi

kernel_pkg() {
    if [ -n "${FIELDPROBE_GUEST_KERNEL_PKG:-}" ]; then
        echo "$FIELDPROBE_GUEST_KERNEL_PKG"
        return
    fi
    apt-cache depends linux-image-amd64 2>/dev/null |
        sed -n 's/^ *Depends: \(linux-image-[0-9].*-amd64\)$/\1/p' | head -1
}

# Build the guest into $CACHE/$PKG (kernel, initrd.img), once.
build() {
    local pkg="$1" dir="$CACHE/$1"
    if [ -s "$dir/vmlinuz" ] && [ -s "$dir/initrd.img" ]; then
        return 0
    fi
    say "building the guest from $pkg into $dir (once)"
    local work
    work="$(mktemp -d "$CACHE/build.XXXXXX")"
    (
        cd "$work"
        if ! apt-get download "$pkg" >download.log 2>&1; then
            cat download.log >&2
            die_missing "apt-get download $pkg failed (no Debian package registry?)"
        fi
        dpkg-deb -x ./*.deb deb
        local kver
        kver="$(ls deb/lib/modules | head -1)"
        [ -n "$kver" ] && [ -f "deb/boot/vmlinuz-$kver" ] || die_missing "$pkg has no kernel"
        depmod -b deb "$kver"
        mkdir -p initrd/bin initrd/proc initrd/sys initrd/dev initrd/host "initrd/lib/modules/$kver"
        cp "$BUSYBOX" initrd/bin/busybox
        local m f
        for m in $MODULES; do
            for f in $(modprobe -d deb -S "$kver" --show-depends "$m" | awk '$1 == "insmod" {print $2}'); do
                rel="${f#*/lib/modules/"$kver"/}"
                mkdir -p "initrd/lib/modules/$kver/$(dirname "$rel")"
                cp "$f" "initrd/lib/modules/$kver/$rel"
            done
        done
        cp deb/lib/modules/"$kver"/modules.order deb/lib/modules/"$kver"/modules.builtin* \
            "initrd/lib/modules/$kver/"
        depmod -b initrd "$kver"
        cat >initrd/init <<'INIT'
#!/bin/busybox sh
/bin/busybox mkdir -p /sbin /usr/bin /usr/sbin
/bin/busybox --install -s
mount -t proc proc /proc
mount -t sysfs sys /sys
mount -t devtmpfs dev /dev
for m in MODULES_HERE; do modprobe "$m" || echo "guest: modprobe $m failed" >/dev/console; done
run="$(sed -n 's/.* fp\.run=\([^ ]*\).*/\1/p' /proc/cmdline)"
if mount -t 9p -o trans=virtio,version=9p2000.L,msize=512000,cache=loose host /host; then
    mount -t proc proc /host/proc
    mount -t sysfs sys /host/sys
    mount -t devtmpfs dev /host/dev
    mount -t devpts devpts /host/dev/pts 2>/dev/null
    mount -t tmpfs tmp /host/tmp
    mount -t tmpfs run /host/run
    mount -t tmpfs shm /host/dev/shm 2>/dev/null
    chroot /host /bin/sh -c 'ip link set lo up && ip link add dev vcan0 type vcan && ip link set up vcan0' \
        >/dev/console 2>&1 || echo "guest: vcan0 not up" >/dev/console
    chroot /host /bin/bash "$run/cmd.sh" >"/host$run/stdout" 2>"/host$run/stderr"
    echo $? >"/host$run/status"
    sync
else
    echo "guest: 9p mount of the host failed" >/dev/console
fi
poweroff -f
INIT
        sed -i "s/MODULES_HERE/$MODULES/" initrd/init
        chmod +x initrd/init
        (cd initrd && find . | cpio -o -H newc --quiet | gzip -1 >../initrd.img)
        mkdir -p "$dir"
        cp "deb/boot/vmlinuz-$kver" "$dir/vmlinuz.tmp"
        mv initrd.img "$dir/initrd.img"
        mv "$dir/vmlinuz.tmp" "$dir/vmlinuz"
    ) || { rc=$?; rm -rf "$work"; return $rc; }
    rm -rf "$work"
}

mkdir -p "$CACHE"
PKG="$(kernel_pkg)"
[ -n "$PKG" ] || die_missing "apt-cache knows no linux-image-amd64 (run apt-get update)"
build "$PKG"
GUEST="$CACHE/$PKG"

if [ "$MODE" = check ]; then
    echo "ok: $GUEST"
    exit 0
fi
[ "$MODE" = build ] && exit 0

# The run's files live in the cache, not in /tmp: the guest's /tmp is its own.
mkdir -p "$CACHE/runs"
RUN="$(mktemp -d "$CACHE/runs/run.XXXXXX")"
trap 'rm -rf "$RUN"' EXIT
{
    echo "#!/bin/bash"
    export -p | grep -v -E '^declare -x (OLDPWD|PWD|SHLVL|_|TMPDIR)='
    printf 'cd %q || exit 126\n' "$PWD"
    printf 'export TMPDIR=/tmp FIELDPROBE_IN_GUEST=1\n'
    printf 'exec'
    printf ' %q' "$@"
    printf '\n'
} >"$RUN/cmd.sh"

CPUS="${FIELDPROBE_GUEST_CPUS:-$(nproc)}"
[ "$CPUS" -gt 4 ] && CPUS=4
ACCEL=(-accel tcg,thread=multi)
set +e
timeout --kill-after=10 "$TIMEOUT" "$QEMU" "${ACCEL[@]}" -m "${FIELDPROBE_GUEST_MEM:-2048}" \
    -smp "$CPUS" -nographic -no-reboot -nic none \
    -kernel "$GUEST/vmlinuz" -initrd "$GUEST/initrd.img" \
    -append "console=ttyS0 quiet loglevel=3 panic=-1 fp.run=$RUN" \
    -virtfs "local,path=/,mount_tag=host,security_model=passthrough,multidevs=remap" \
    </dev/null >"$RUN/console" 2>&1
qrc=$?
set -e
[ -f "$RUN/stdout" ] && cat "$RUN/stdout"
[ -f "$RUN/stderr" ] && cat "$RUN/stderr" >&2
if [ "$qrc" -eq 124 ] || [ "$qrc" -eq 137 ]; then
    say "timed out after ${TIMEOUT} s; guest console:"
    tail -20 "$RUN/console" >&2
    exit 124
fi
if [ ! -s "$RUN/status" ]; then
    say "the guest ended without running the command (qemu exit $qrc); guest console:"
    tail -40 "$RUN/console" >&2
    exit 125
fi
exit "$(cat "$RUN/status")"
