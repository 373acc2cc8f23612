#!/usr/bin/env bash
# Run a host command inside a throw-away qemu VM whose kernel has real SocketCAN (vcan0, vcan1).
#
# Usage: scripts/vcanvm/run.sh [--timeout SECS] [--ifaces vcan0,vcan1] -- CMD [ARGS...]
#
# The guest mounts the host's / over virtio-9p (read-write) and chroots into it, so CMD runs
# with the host's own programs, venvs and files, as root, in the current directory, with the
# current exported environment. Its output streams back through the serial console; files it
# writes land on the host. Exit status: CMD's, or 255 when the VM failed or timed out.
#
# Environment:
#   RDM_VCANVM_TIMEOUT  bound on the whole VM run in seconds (default 900; --timeout wins)
#   RDM_VCANVM_ACCEL    tcg (default) or kvm. Under a PVM-backed /dev/kvm (/sys/module/kvm_pvm,
#                       as on the machines this was built on) a stock kernel cannot boot with
#                       KVM, so TCG software emulation is the default: ~2 s boot, guest Python
#                       ~16x slower than the host. kvm is only for hosts with real VT-x/AMD-V.
#   RDM_VCANVM_MEM      guest memory in MB (default 1024; only touched pages cost host RAM)
#   RDM_VCANVM_VERBOSE  1: show the raw console (kernel messages, markers, CRs)
set -uo pipefail
HERE=$(cd "$(dirname "$0")" && pwd)
TIMEOUT=${RDM_VCANVM_TIMEOUT:-900}
IFACES=vcan0,vcan1
while [ $# -gt 0 ]; do
  case "$1" in
    --timeout) TIMEOUT=$2; shift 2 ;;
    --ifaces) IFACES=$2; shift 2 ;;
    --) shift; break ;;
    *) break ;;
  esac
done
[ $# -gt 0 ] || { echo "usage: $0 [--timeout SECS] [--ifaces LIST] -- CMD [ARGS...]" >&2; exit 2; }

ARTIFACTS=$("$HERE/build.sh") || exit 255
KERNEL=$(sed -n 1p <<<"$ARTIFACTS")
INITRD=$(sed -n 2p <<<"$ARTIFACTS")
echo "vcanvm: booting $(basename "$(dirname "$KERNEL")") (${RDM_VCANVM_ACCEL:-tcg}, timeout ${TIMEOUT}s): $*" >&2

case "${RDM_VCANVM_ACCEL:-tcg}" in
  tcg) ACCEL=(-accel tcg -cpu "${RDM_VCANVM_CPU:-max}") ;;
  kvm) ACCEL=(-enable-kvm -cpu host) ;;
  *) echo "vcanvm: RDM_VCANVM_ACCEL must be tcg or kvm" >&2; exit 2 ;;
esac
# qboot is a faster firmware than SeaBIOS and prints no terminal-reset escapes.
BIOS=()
[ -f /usr/share/qemu/qboot.rom ] && BIOS=(-bios /usr/share/qemu/qboot.rom)
# As root, 9p passthrough keeps file ownership; otherwise ownership changes are ignored.
SECURITY=passthrough
[ "$(id -u)" = 0 ] || SECURITY=none

# The job directory must be visible to the guest, i.e. anywhere under the host's /.
RUN=$(mktemp -d "${TMPDIR:-/tmp}/rdm-vcanvm-run.XXXXXX")
QEMU_PID=
# On a signal to this script (e.g. from an outer `timeout`), stop qemu and the filter.
cleanup() {
  if [ -f "$RUN/qemu.pid" ]; then kill "$(cat "$RUN/qemu.pid")" 2>/dev/null; fi
  if [ -n "$QEMU_PID" ]; then kill "$QEMU_PID" 2>/dev/null; fi
  rm -rf "$RUN"
}
trap cleanup EXIT
trap 'exit 255' TERM INT HUP

# The job script restores the directory and environment, runs CMD and records its status.
{
  echo "#!/bin/bash"
  export -p | grep -vE '^declare -x (SHLVL|OLDPWD|_)='
  printf 'cd %q || exit 254\n' "$PWD"
  # Temporary files on a guest tmpfs: the host's /tmp arrives over 9p, which loses files
  # that are open but unlinked (pytest's capture files) once child processes come and go.
  echo 'mkdir -p /run/rdm-vcanvm-tmp && mount -t tmpfs -o size=256m tmpfs /run/rdm-vcanvm-tmp && export TMPDIR=/run/rdm-vcanvm-tmp'
  # The guest's stdout is its serial console, a tty even when ours is a pipe or file: tell
  # programs (pytest's colours) what the real output is.
  if [ -t 1 ]; then
    printf 'export COLUMNS=%q\n' "$(tput cols 2>/dev/null || echo 80)"
  else
    echo 'export TERM=dumb'
  fi
  printf '%q ' "$@"; echo
  echo 'rc=$?'
  printf 'echo $rc > %q\n' "$RUN/rc"
  echo 'exit $rc'
} > "$RUN/job.sh"
printf '#!/bin/sh\nexec /bin/bash %q\n' "$RUN/job.sh" > "$RUN/boot.sh"

APPEND="console=ttyS0 quiet loglevel=3 panic=-1 rdm.job=$RUN/boot.sh rdm.ifaces=$IFACES"
# The serial console ends lines with CRLF: strip the CRs and the power-off line.
if [ "${RDM_VCANVM_VERBOSE:-0}" = 1 ]; then FILTER=(cat); else
  FILTER=(sed -u -e 's/\r$//' -e '/reboot: Power down$/d'); fi

# -no-reboot: a guest panic ends qemu instead of looping. `timeout` bounds the run even when
# the guest hangs; qemu runs in the background so a signal to this script can stop it.
timeout -k 5 "$TIMEOUT" qemu-system-x86_64 "${ACCEL[@]}" -m "${RDM_VCANVM_MEM:-1024}" -smp "${RDM_VCANVM_SMP:-2}" \
  -nographic -no-reboot -nodefaults -serial stdio -monitor none "${BIOS[@]}" \
  -pidfile "$RUN/qemu.pid" -kernel "$KERNEL" -initrd "$INITRD" -append "$APPEND" \
  -virtfs "local,path=/,mount_tag=hostroot,security_model=$SECURITY,multidevs=remap,id=hostroot" \
  </dev/null | "${FILTER[@]}" &
QEMU_PID=$!
wait "$QEMU_PID"
# qemu has exited: forget its pid so cleanup never signals a reused pid.
QEMU_PID=
rm -f "$RUN/qemu.pid"
if [ -f "$RUN/rc" ]; then
  exit "$(cat "$RUN/rc")"
fi
echo "vcanvm: the guest produced no exit status (VM failure, or timed out after ${TIMEOUT}s)" >&2
exit 255
