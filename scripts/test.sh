#!/usr/bin/env bash
# The whole test suite, Rust and Python: `bash scripts/test.sh`.
# Installs what it needs (the package with its test extras), then runs lint, cargo tests
# and pytest. Exits non-zero on any failure.
set -euo pipefail
cd "$(dirname "$0")/.."

PY=${PYTHON:-python3}

echo "== install rdm with test extras (builds the Rust extension)"
"$PY" -m pip install --quiet --disable-pip-version-check ".[test]"

echo "== rust: fmt, clippy, tests"
cargo fmt --all -- --check
cargo clippy --workspace --all-targets --quiet -- -D warnings
cargo test --workspace --exclude rdm_py --quiet

echo "== python: ruff"
"$PY" -m ruff check python tests
"$PY" -m ruff format --check python tests

echo "== python: pytest"
# Against the installed wheel: python/ is not on sys.path, tests/ is (shared test helpers).
# tests/test_lean_install.py builds the wheel again (cargo reuses the build of the install
# above: seconds) and installs it without extras into a fresh venv (its dependencies from PyPI).
"$PY" -m pytest tests -q -p no:cacheprovider

echo "== python: SocketCAN tests on vcan0 (VM harness)"
# tests/vcan on a real kernel vcan0: here if the host has one, else in a small qemu VM
# (scripts/vcanvm/; installs qemu on first use as root). See docs/processes.md.
bash scripts/test-vcan.sh -q
