#!/usr/bin/env bash
# The SocketCAN test subset (tests/vcan, marker `vcan`) on a real kernel vcan0:
#   bash scripts/test-vcan.sh [pytest args]
#
# If this host already has vcan0 (real CAN hardware machines, or after
#   sudo modprobe vcan && sudo ip link add vcan0 type vcan && sudo ip link set up vcan0)
# pytest runs here. Otherwise the tests run inside a throw-away qemu VM with a Debian kernel
# that has SocketCAN (scripts/vcanvm/): the first run installs qemu/busybox/cpio (as root)
# and builds a cached kernel + initramfs; later runs boot in a few seconds.
#
# Exit status: pytest's (5, "no tests collected", is a failure here too), 255 if the VM failed.
# Environment: PYTHON (default python3; the interpreter whose packages the tests use),
#   RDM_VCANVM_FORCE=1 (use the VM even when the host has vcan0), and the RDM_VCANVM_* knobs
#   of scripts/vcanvm/run.sh (timeout, memory, accelerator).
set -euo pipefail
cd "$(dirname "$0")/.."
started=$SECONDS

PY=${PYTHON:-python3}
# The real interpreter path, not a wrapper: a pyenv shim is a bash script that costs ~3 s per
# call inside the emulated guest. sys.executable keeps a venv's own bin/python (its packages).
PY_REAL=$("$PY" -c 'import sys; print(sys.executable)')
PYTEST=("$PY_REAL" -m pytest -m vcan tests/vcan -p no:cacheprovider --import-mode=importlib "$@")
# Inside the harness a missing vcan0 is an error, never a silent skip.
export RDM_VCAN_REQUIRED=1
# The two process-level scenario runs (hover ~4.5 min, perching ~8 min under TCG) take the
# stage past run.sh's default 900 s bound.
export RDM_VCANVM_TIMEOUT=${RDM_VCANVM_TIMEOUT:-2400}

set +e
if [ -e /sys/class/net/vcan0 ] && [ "${RDM_VCANVM_FORCE:-0}" != 1 ]; then
  echo "vcan: this host has vcan0: running pytest here ($PY_REAL)"
  "${PYTEST[@]}"
  rc=$?
else
  echo "vcan: no vcan0 on this host: running pytest in the SocketCAN VM (scripts/vcanvm/run.sh)"
  # Hypothesis's pytest plugin doubles pytest's start-up in the emulated guest (~20 s at 16x);
  # @given still works without it.
  scripts/vcanvm/run.sh -- "${PYTEST[@]}" -p no:hypothesispytest
  rc=$?
fi
set -e

case $rc in
  0) echo "vcan: passed ($((SECONDS - started)) s in all)" ;;
  5) echo "vcan: FAILED: pytest collected no tests (tests/vcan must not be empty)" >&2 ;;
  255) echo "vcan: FAILED: the VM did not report an exit status (see output above)" >&2 ;;
  *) echo "vcan: FAILED (pytest exit status $rc)" >&2 ;;
esac
exit "$rc"
