#!/usr/bin/env bash
# Build (or reuse from the cache) the kernel and initramfs of the vcan VM.
#
# Usage: scripts/vcanvm/build.sh
# Prints two lines on stdout: the kernel image, then the initramfs. Progress goes to stderr.
#
# The kernel is Debian's stock `linux-image-<abi>-amd64` (the target of the `linux-image-amd64`
# meta package), only downloaded and unpacked, never installed: it has CAN, CAN_RAW, CAN_BCM,
# CAN_VCAN and 9p as modules. (`linux-image-cloud-amd64` lacks CAN and 9p: unusable.)
# The initramfs holds a static busybox, those modules and scripts/vcanvm/init.
#
# Cache: ${RDM_VCANVM_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/rdm-vcanvm}/<abi>/
#   vmlinux                 uncompressed kernel (qemu boots it through its PVH entry point,
#                           which skips the in-guest XZ decompression: ~2 s per boot, not ~4.5 s)
#   lib/modules/<abi>/      the needed .ko files with their modules.dep
#   initramfs-<hash>.cpio.gz  keyed by a hash of init + module list, so editing init rebuilds it
# The .deb itself is deleted after unpacking. Nothing is written into the repository.
#
# Environment: RDM_VCANVM_KERNEL=<abi> pins the kernel (e.g. 6.1.0-56-amd64);
#              RDM_VCANVM_CACHE overrides the cache directory; PYTHON (default python3).
set -euo pipefail
HERE=$(cd "$(dirname "$0")" && pwd)
CACHE=${RDM_VCANVM_CACHE:-${XDG_CACHE_HOME:-${HOME:-/root}/.cache}/rdm-vcanvm}
PY=${PYTHON:-python3}
# Kernel modules the guest loads (written to /modules in the initramfs, which init reads;
# their dependencies are added below).
MODULES="virtio_pci virtio_mmio 9pnet_virtio 9p can can-raw can-bcm can-gw can-isotp can-j1939 vcan vxcan"

say() { echo "vcanvm: $*" >&2; }
die() { echo "vcanvm: ERROR: $*" >&2; exit 1; }
is_root() { [ "$(id -u)" = 0 ]; }
apt_noninteractive() { DEBIAN_FRONTEND=noninteractive apt-get "$@" </dev/null; }

# --- host packages --------------------------------------------------------------------------
missing=()
command -v qemu-system-x86_64 >/dev/null || missing+=(qemu-system-x86)
# busybox must be the static build: the initramfs has no shared libraries.
dpkg-query -W -f='${Status}' busybox-static 2>/dev/null | grep -q "ok installed" \
  || missing+=(busybox-static)
command -v cpio >/dev/null || missing+=(cpio)
if [ ${#missing[@]} -gt 0 ]; then
  is_root || die "missing packages: ${missing[*]}. Install them as root:
  apt-get update && apt-get install -y --no-install-recommends ${missing[*]}"
  say "installing ${missing[*]} (apt-get update + install)"
  apt_noninteractive update -qq >&2
  apt_noninteractive install -y -qq --no-install-recommends "${missing[@]}" >&2
fi
command -v dpkg-deb >/dev/null && command -v apt-get >/dev/null \
  || die "needs a Debian/Ubuntu host (apt-get, dpkg-deb)"

# --- which kernel ----------------------------------------------------------------------------
# The ABI name changes with Debian point and security releases, so resolve it through the meta
# package instead of hard-coding it. That needs apt's package lists (apt-get update).
resolve_abi() {
  apt-cache depends linux-image-amd64 2>/dev/null \
    | awk '/Depends: linux-image-[0-9]/ {sub("linux-image-", "", $2); print $2; exit}'
}
# apt-cache takes seconds on a busy host: remember its answer until apt's lists change.
resolve_abi_cached() {
  local stamp memo=$CACHE/.resolved
  stamp=$(stat -c %Y /var/lib/apt/lists 2>/dev/null) || { resolve_abi; return; }
  if [ -f "$memo" ] && [ "$(cut -d' ' -f1 "$memo")" = "$stamp" ]; then
    cut -d' ' -f2 "$memo"
    return
  fi
  local abi
  abi=$(resolve_abi)
  if [ -n "$abi" ]; then mkdir -p "$CACHE" && echo "$stamp $abi" > "$memo"; fi
  echo "$abi"
}
ABI=${RDM_VCANVM_KERNEL:-$(resolve_abi_cached)}
if [ -z "$ABI" ]; then
  # No package lists: reuse the newest cached kernel if there is one (no network needed).
  ABI=$(ls -1 "$CACHE" 2>/dev/null | grep -E -- '-amd64$' | sort -V | tail -1 || true)
  if [ -z "$ABI" ] || [ ! -f "$CACHE/$ABI/vmlinux" ]; then
    is_root || die "cannot resolve linux-image-amd64 (no apt lists); run 'apt-get update' as root"
    say "apt-get update (to resolve linux-image-amd64)"
    apt_noninteractive update -qq >&2
    ABI=$(resolve_abi)
  fi
fi
[ -n "$ABI" ] || die "could not resolve the kernel behind linux-image-amd64"
K=$CACHE/$ABI
mkdir -p "$CACHE"

# Concurrent runs share the cache: one builder at a time, and artifacts appear atomically (mv).
exec 9>"$CACHE/.lock"
flock 9

# --- kernel: download, unpack, vmlinux, modules ------------------------------------------------
if [ ! -f "$K/vmlinux" ] || [ ! -f "$K/lib/modules/$ABI/modules.dep" ]; then
  say "building kernel $ABI into $K (download ~70 MB, once)"
  T=$(mktemp -d "$CACHE/tmp.XXXXXX")
  trap 'rm -rf "$T"' EXIT
  download() { (cd "$T" && apt-get download -q -o APT::Sandbox::User=root "linux-image-$ABI" >&2) </dev/null; }
  if ! download; then
    # Stale lists point at a package the mirror has dropped: refresh once and retry.
    is_root || die "apt-get download linux-image-$ABI failed"
    [ -z "${RDM_VCANVM_KERNEL:-}" ] || die "apt-get download linux-image-$ABI failed"
    say "download failed; apt-get update and retry"
    apt_noninteractive update -qq >&2
    ABI=$(resolve_abi); K=$CACHE/$ABI
    download || die "apt-get download linux-image-$ABI failed"
  fi
  dpkg-deb -x "$T"/linux-image-"$ABI"_*.deb "$T/root"
  # modules.dep from busybox's depmod: no kmod needed on the host
  busybox depmod -b "$T/root" "$ABI"
  # Debian amd64 kernels are XZ-compressed bzImages: cut out the XZ stream -> ELF vmlinux.
  "$PY" - "$T/root/boot/vmlinuz-$ABI" "$T/vmlinux" <<'PY'
import lzma
import sys

image = open(sys.argv[1], "rb").read()
start = image.find(b"\xfd7zXZ\x00")
if start < 0:
    sys.exit("vmlinuz is not XZ-compressed")
with open(sys.argv[2], "wb") as out:
    out.write(lzma.LZMADecompressor().decompress(image[start:]))
PY
  # Keep only the modules we load and everything they depend on.
  M=$T/root/lib/modules/$ABI
  O=$T/out/lib/modules/$ABI
  mkdir -p "$O"
  for m in $MODULES; do
    rel=$(grep -E "/$m\.ko(\.xz)?:" "$M/modules.dep" | cut -d: -f1)
    [ -n "$rel" ] || die "kernel $ABI has no module $m"
    for f in $rel $(grep -E "^$rel:" "$M/modules.dep" | cut -d: -f2); do
      mkdir -p "$O/$(dirname "$f")"
      cp "$M/$f" "$O/$f"
    done
  done
  cp "$M"/modules.builtin "$M"/modules.order "$O/"
  busybox depmod -b "$T/out" "$ABI"
  mv "$T/vmlinux" "$T/out/vmlinux"
  rm -rf "$K" && mv "$T/out" "$K"
  rm -rf "$T"; trap - EXIT
fi

# --- initramfs ---------------------------------------------------------------------------------
HASH=$(cat "$HERE/init" <(echo "$MODULES") | sha256sum | cut -c1-12)
INITRD=$K/initramfs-$HASH.cpio.gz
if [ ! -f "$INITRD" ]; then
  say "building initramfs $(basename "$INITRD")"
  R=$(mktemp -d "$CACHE/tmp.XXXXXX")
  trap 'rm -rf "$R"' EXIT
  mkdir -p "$R"/{bin,proc,sys,dev,newroot}
  cp "$(command -v busybox)" "$R/bin/busybox"
  install -m 755 "$HERE/init" "$R/init"
  echo "$MODULES" > "$R/modules"
  cp -r "$K/lib" "$R/lib"
  (cd "$R" && find . | cpio -o -H newc --quiet | gzip -6) > "$INITRD.tmp"
  mv "$INITRD.tmp" "$INITRD"
  for old in "$K"/initramfs-*.cpio.gz; do [ "$old" = "$INITRD" ] || rm -f "$old"; done
  rm -rf "$R"; trap - EXIT
fi
echo "$K/vmlinux"
echo "$INITRD"
