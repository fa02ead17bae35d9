#!/usr/bin/env bash
# Runs test binaries inside a small qemu VM whose kernel has CAN, with vcan0 up (CAN FD capable).
#
#   .ci/vcan/run-in-vm.sh [--env NAME=VALUE]... [--timeout SECONDS] [--host-root] BINARY [ARGS...]
#
# --host-root shares this host's root file system read-only with the VM (virtio 9p, mounted at
# /host with /proc, /sys and /dev bound in) and puts a `python3` first on PATH that
# runs this host's python3 (with its installed packages) chrooted into /host: programs written by
# others (python-canopen, python-can) then talk over the VM's vcan0. Absolute host paths of files
# the binary passes to python are the same inside the chroot; the binary itself reads them under
# $IDENT_HOST_ROOT (= /host).
#
# BINARY runs as root inside the VM (working directory /payload, PATH has busybox (whose `ip`
# handles `type vcan`), candump, cansend and cangen). Its output appears on the console, which
# this script prints. The VM reports back through a marker line `VCAN-RESULT: ok` or `VCAN-RESULT: fail ...`; the exit code is 0 only on
# `ok`. A missing marker (crash, hang, timeout) is a failure too.
#
# Prerequisites (installed by .ci/setup): qemu-system-x86, busybox-static, can-utils, cpio, and a
# Debian kernel unpacked by .ci/vcan/fetch-kernel.sh under $IDENT_VCAN_KERNEL_DIR
# (default /var/cache/ident-vcan). Exit code 3 = a prerequisite is missing. The VM uses TCG (KVM hangs on this kind of host).
# The base initramfs (busybox, modules, can-utils) is cached under $IDENT_VCAN_CACHE (default
# ${TMPDIR:-/tmp}/ident-vcan-$UID), keyed by a hash of its inputs; the payload is rebuilt each run.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
kdir=${IDENT_VCAN_KERNEL_DIR:-/var/cache/ident-vcan}
cache=${IDENT_VCAN_CACHE:-${TMPDIR:-/tmp}/ident-vcan-$(id -u)}
timeout_s=${IDENT_VCAN_TIMEOUT:-150}
envs=()
host_root=0
while [ $# -gt 0 ]; do
  case "$1" in
    --env) envs+=("$2"); shift 2 ;;
    --host-root) host_root=1; shift ;;
    --timeout) timeout_s=$2; shift 2 ;;
    --) shift; break ;;
    -*) echo "run-in-vm: unknown option $1" >&2; exit 2 ;;
    *) break ;;
  esac
done
if [ $# -lt 1 ]; then
  echo "usage: $0 [--env NAME=VALUE]... [--timeout SECONDS] BINARY [ARGS...]" >&2; exit 2
fi
bin=$(readlink -f "$1"); shift
[ -x "$bin" ] || { echo "run-in-vm: $bin is not an executable file" >&2; exit 2; }

missing=()
for tool in qemu-system-x86_64 cpio candump cansend cangen ldd; do
  command -v "$tool" >/dev/null || missing+=("$tool")
done
if [ ! -x /bin/busybox ] || ldd /bin/busybox >/dev/null 2>&1; then
  missing+=("a statically linked /bin/busybox (busybox-static)")
fi
vmlinuz=$(ls "$kdir"/*/boot/vmlinuz-* 2>/dev/null | sort | tail -n1 || true)
[ -n "$vmlinuz" ] || missing+=("a Debian kernel in $kdir (.ci/vcan/fetch-kernel.sh)")
if [ ${#missing[@]} -gt 0 ]; then
  echo "run-in-vm: missing prerequisites: ${missing[*]}" >&2
  echo "run-in-vm: run .ci/setup (as root) to install them" >&2
  exit 3
fi
kroot=$(dirname "$(dirname "$vmlinuz")")

# Copies an executable and the shared libraries ldd lists (plus the loader) into $1.
copy_with_libs() {
  local root=$1 exe=$2 dest=$3 lib
  mkdir -p "$root$(dirname "$dest")"
  cp -L "$exe" "$root$dest"
  for lib in $(ldd "$exe" 2>/dev/null | grep -o '/[^ ]*' || true); do
    [ -e "$root$lib" ] && continue
    mkdir -p "$root$(dirname "$lib")"
    cp -L "$lib" "$root$lib"
  done
}

# Loaded in this order when the host's root is shared (virtio-pci, then 9p over virtio).
share_modules="virtio_ring virtio virtio_pci_modern_dev virtio_pci_legacy_dev virtio_pci netfs fscache 9pnet 9pnet_virtio 9p"

# ---- base initramfs: cached, keyed by its inputs ------------------------------------------------
mkdir -p "$cache"
key=$( { sha256sum "$here/run-in-vm.sh" /bin/busybox "$(command -v candump)" \
          "$(command -v cansend)" "$(command -v cangen)";
         find "$kroot/lib" -type f -print0 | sort -z | xargs -0 sha256sum; } | sha256sum | cut -c1-16)
base="$cache/base-$key.cpio"
if [ ! -s "$base" ]; then
  stage=$(mktemp -d "$cache/stage.XXXXXX")
  mkdir -p "$stage"/{bin,sbin,dev,proc,sys,tmp,run,lib/modules,payload}
  cp /bin/busybox "$stage/bin/busybox"
  for m in can can-raw can-bcm can-dev vcan $share_modules; do
    src=$(find "$kroot/lib/modules" -name "$m.ko" -o -name "$m.ko.xz" | head -n1)
    [ -n "$src" ] || { echo "run-in-vm: module $m not found under $kroot (re-run .ci/setup)" >&2; rm -rf "$stage"; exit 3; }
    case "$src" in
      *.xz) xz -dc "$src" > "$stage/lib/modules/$m.ko" ;;
      *) cp "$src" "$stage/lib/modules/$m.ko" ;;
    esac
  done
  for t in candump cansend cangen; do copy_with_libs "$stage" "$(command -v $t)" "/usr/bin/$t"; done
  cat > "$stage/init" <<'INIT'
#!/bin/busybox sh
/bin/busybox --install -s /bin
export PATH=/usr/bin:/usr/sbin:/bin:/sbin
mount -t proc proc /proc; mount -t sysfs sys /sys; mount -t devtmpfs dev /dev
mkdir -p /dev/pts && mount -t devpts -o ptmxmode=0666 devpts /dev/pts  # pseudo-terminals (simulated shaker)
mount -t tmpfs tmp /tmp
fail() { echo "VCAN-RESULT: fail ($*)"; sync; poweroff -f; sleep 5; }
for m in can can-raw can-bcm can-dev vcan; do
  insmod /lib/modules/$m.ko || fail "insmod $m"
done
ip link set lo up
ip link add dev vcan0 type vcan || fail "ip link add vcan0"
ip link set vcan0 mtu 72 || fail "vcan0 mtu 72 (CAN FD)"
ip link set vcan0 up || fail "vcan0 up"
if [ -e /payload/host-root ]; then
  for m in virtio_ring virtio virtio_pci_modern_dev virtio_pci_legacy_dev virtio_pci netfs fscache 9pnet 9pnet_virtio 9p; do
    insmod /lib/modules/$m.ko || fail "insmod $m"
  done
  mkdir -p /host
  mount -t 9p -o trans=virtio,version=9p2000.L,ro,msize=262144 hostroot /host || fail "mount the host's root (9p)"
  # /host/tmp stays the host's: a CI clone of the repository lives there.
  for d in proc sys dev; do mount --bind /$d /host/$d || fail "bind /$d into /host"; done
  export PATH=/payload/bin:$PATH IDENT_HOST_ROOT=/host
fi
echo "VCAN-READY: $(cut -d' ' -f1 /proc/uptime) s after boot"
. /payload/run.sh
rc=$?
if [ "$rc" = 0 ]; then echo "VCAN-RESULT: ok"; else echo "VCAN-RESULT: fail (exit $rc)"; fi
sync
poweroff -f
sleep 5
INIT
  chmod +x "$stage/init"
  (cd "$stage" && find . | sort | cpio -o -H newc --quiet) > "$stage.cpio"
  find "$cache" -maxdepth 1 -name 'base-*.cpio' -mmin +60 -delete  # stale keys
  mv "$stage.cpio" "$base"  # atomic: concurrent runs never see a partial archive
  rm -rf "$stage"
fi

# ---- payload: the binary, its libraries and the command line -------------------------------------
run=$(mktemp -d "$cache/run.XXXXXX")
trap 'rm -rf "$run"' EXIT
pstage="$run/payload-root"
mkdir -p "$pstage/payload"
copy_with_libs "$pstage" "$bin" "/payload/$(basename "$bin")"
# Debug info is most of a test binary's size and slows the VM's initramfs unpacking; symbols stay.
if command -v strip >/dev/null; then strip --strip-debug "$pstage/payload/$(basename "$bin")" 2>/dev/null || true; fi
qemu_share=()
if [ "$host_root" = 1 ]; then
  # The interpreter itself, not a shim (pyenv's needs its environment).
  py=$(python3 -c 'import sys; print(sys.executable)' 2>/dev/null || true)
  [ -n "$py" ] || { echo "run-in-vm: --host-root needs python3 on this host" >&2; exit 3; }
  mkdir -p "$pstage/payload/bin"
  printf '#!/bin/sh\nexec chroot /host %q "$@"\n' "$py" > "$pstage/payload/bin/python3"
  chmod +x "$pstage/payload/bin/python3"
  touch "$pstage/payload/host-root"
  qemu_share=(-virtfs "local,path=/,mount_tag=hostroot,security_model=none,readonly=on")
fi
{
  echo "cd /payload"
  for e in "${envs[@]}"; do printf 'export %q\n' "$e"; done
  printf '%q ' "./$(basename "$bin")" "$@"; echo
} > "$pstage/payload/run.sh"
(cd "$pstage" && find . | sort | cpio -o -H newc --quiet) > "$run/payload.cpio"
cat "$base" "$run/payload.cpio" > "$run/initrd.cpio"

log="$run/console.log"
start=$(date +%s.%N)
set +e
timeout --kill-after=5 "$timeout_s" qemu-system-x86_64 -accel tcg -cpu max -smp 2 -m 1024 \
  -nographic -no-reboot -nic none "${qemu_share[@]}" \
  -kernel "$vmlinuz" -initrd "$run/initrd.cpio" \
  -append "console=ttyS0 quiet panic=-1 loglevel=3" </dev/null 2>&1 | tee "$log"
qrc=${PIPESTATUS[0]}
set -e
elapsed=$(awk -v a="$start" -v b="$(date +%s.%N)" 'BEGIN { printf "%.1f", b - a }')
result=$(grep -a -o 'VCAN-RESULT: [a-z]*' "$log" | tail -n1 | tr -d '\r' || true)
if [ "$qrc" = 124 ] || [ "$qrc" = 137 ]; then
  echo "run-in-vm: VM timed out after ${timeout_s} s (set IDENT_VCAN_TIMEOUT to change)" >&2
  exit 1
fi
echo "run-in-vm: VM finished in ${elapsed} s (qemu exit $qrc), ${result:-no VCAN-RESULT marker}" >&2
[ "$result" = "VCAN-RESULT: ok" ]
