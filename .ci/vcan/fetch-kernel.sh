#!/usr/bin/env bash
# Fetches the Debian kernel the vcan VM boots (no CAN in the host kernel) and keeps only what the
# VM needs: vmlinuz and the CAN modules. Idempotent; called by .ci/setup (needs apt, network, root
# or write access to the cache directory).
#
#   IDENT_VCAN_KERNEL_DIR  where to keep it (default /var/cache/ident-vcan)
set -euo pipefail
kdir=${IDENT_VCAN_KERNEL_DIR:-/var/cache/ident-vcan}
# CAN (raw, and the broadcast manager python-can uses for periodic frames) + vcan; virtio-pci and 9p for the host's root shared read-only (python-canopen in the VM).
modules=(kernel/net/can/can.ko kernel/net/can/can-raw.ko kernel/net/can/can-bcm.ko
         kernel/drivers/net/can/dev/can-dev.ko
         kernel/drivers/net/can/vcan.ko
         kernel/drivers/virtio/virtio_ring.ko kernel/drivers/virtio/virtio.ko
         kernel/drivers/virtio/virtio_pci_modern_dev.ko kernel/drivers/virtio/virtio_pci_legacy_dev.ko
         kernel/drivers/virtio/virtio_pci.ko kernel/fs/netfs/netfs.ko kernel/fs/fscache/fscache.ko
         kernel/net/9p/9pnet.ko kernel/net/9p/9pnet_virtio.ko kernel/fs/9p/9p.ko)

# A kernel already there is good enough when it has every module above.
for have in "$kdir"/*/boot/vmlinuz-*; do
  [ -e "$have" ] || continue
  root=$(dirname "$(dirname "$have")")
  release=${have##*/vmlinuz-}
  complete=1
  for m in "${modules[@]}"; do
    compgen -G "$root/lib/modules/$release/$m*" >/dev/null || complete=0
  done
  if [ "$complete" = 1 ]; then exit 0; fi
  echo "fetch-kernel: $root lacks modules the VM now needs; fetching again" >&2
  rm -rf "$root"
done
# The versioned package linux-image-amd64 currently points at (e.g. linux-image-6.1.0-56-amd64).
pkg=$(apt-cache depends linux-image-amd64 2>/dev/null |
      sed -n 's/^ *Depends: \(linux-image-[0-9][^ ]*-amd64\)$/\1/p' | head -n1)
if [ -z "$pkg" ]; then
  apt-get update -qq
  pkg=$(apt-cache depends linux-image-amd64 |
        sed -n 's/^ *Depends: \(linux-image-[0-9][^ ]*-amd64\)$/\1/p' | head -n1)
fi
if [ -z "$pkg" ]; then
  echo "fetch-kernel: cannot resolve linux-image-amd64 to a versioned package (apt sources?)" >&2
  exit 1
fi
mkdir -p "$kdir"
work=$(mktemp -d "$kdir/.fetch.XXXXXX")
trap 'rm -rf "$work"' EXIT
chmod 777 "$work"  # apt-get download drops privileges to _apt
(cd "$work" && apt-get download -qq "$pkg" 2>/dev/null || apt-get download "$pkg")
dpkg -x "$work"/"$pkg"_*.deb "$work/root"
release=$(basename "$(ls -d "$work"/root/lib/modules/*)")
dest="$work/$pkg"
mkdir -p "$dest/boot" "$dest/lib/modules/$release"
cp "$work/root/boot/vmlinuz-$release" "$dest/boot/"
for m in "${modules[@]}"; do
  src=$(ls "$work/root/lib/modules/$release/$m"* | head -n1)  # .ko or .ko.xz
  mkdir -p "$dest/lib/modules/$release/$(dirname "$m")"
  cp "$src" "$dest/lib/modules/$release/$(dirname "$m")/"
done
chmod -R a+rX "$dest"
mv "$dest" "$kdir/$pkg"
echo "fetch-kernel: $pkg ($release) in $kdir/$pkg"
