#!/usr/bin/env bash
# Fetches the Debian kernel the vcan VM boots (no CAN in the host kernel) and keeps only what the
# VM needs: vmlinuz and the CAN modules. Idempotent; called by .ci/setup (needs apt, network, root
# or write access to the cache directory).
#
#   IDENT_VCAN_KERNEL_DIR  where to keep it (default /var/cache/ident-vcan)
set -euo pipefail
kdir=${IDENT_VCAN_KERNEL_DIR:-/var/cache/ident-vcan}
modules=(kernel/net/can/can.ko kernel/net/can/can-raw.ko kernel/drivers/net/can/dev/can-dev.ko
         kernel/drivers/net/can/vcan.ko)

# Whatever kernel is already there is good enough: the VM only needs CAN + vcan modules.
if compgen -G "$kdir/*/boot/vmlinuz-*" >/dev/null; then
  exit 0
fi
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
