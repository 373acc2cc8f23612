#!/usr/bin/env bash
# The distribution files of rdm, into dist/ (gitignored): `bash scripts/build_wheels.sh`.
#
#   dist/rdm-<version>-cp310-abi3-manylinux2014_x86_64.manylinux_2_17_x86_64.whl
#                                   one wheel for CPython >= 3.10 on glibc >= 2.17 (x86_64)
#   dist/rdm-<version>.tar.gz                                  the sdist (Rust sources included)
#
# maturin builds both: the wheel in the release profile, linked by zig (the ziglang package)
# against glibc 2.17's symbol versions whatever the host's glibc, tagged with the manylinux
# policy RDM_MANYLINUX, which maturin checks before writing the wheel; auditwheel then
# reports the policy it finds on its own (it must agree). Build tools come from the test
# extra: pip install ".[test]" (maturin, ziglang, auditwheel). docs/onboard.md, "Deploying on
# the robot", tells how to use the files, also on aarch64 from the sdist.
#
# Environment: PYTHON (default python3), RDM_MANYLINUX (a maturin --compatibility value),
# RDM_DIST (the output folder, default dist), CARGO_TARGET_DIR (cargo's build folder; default
# target/, which `pip install .` shares: a wheel after an install rebuilds little).
set -euo pipefail
cd "$(dirname "$0")/.."

PY=${PYTHON:-python3}
# The oldest policy Rust's x86_64-unknown-linux-gnu target supports (glibc 2.17). Without zig,
# the host's linker ties the extension to the host glibc's symbol versions (a Debian 12 host:
# manylinux_2_35, which a robot computer on Ubuntu 20.04, glibc 2.31, cannot install).
POLICY=${RDM_MANYLINUX:-manylinux_2_17}

OUT=${RDM_DIST:-dist}
mkdir -p "$OUT"
echo "== wheel ($POLICY, abi3, release, linked by zig)"
"$PY" -m maturin build --release --zig --compatibility "$POLICY" --out "$OUT"
echo "== sdist"
"$PY" -m maturin sdist --out "$OUT"

version=$(sed -n 's/^version *= *"\(.*\)"/\1/p' Cargo.toml | head -n 1)
echo "== auditwheel show"
for wheel in "$OUT"/rdm-"$version"-*.whl; do
    "$PY" -m auditwheel show "$wheel"
done
ls -l "$OUT"/rdm-"$version"*
