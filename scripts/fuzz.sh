#!/usr/bin/env bash
# Fuzzing campaign (docs/fuzzing.md): every target, one at a time, for N inputs each.
#
#   bash scripts/fuzz.sh                 # every target, 1,000,000 inputs each
#   bash scripts/fuzz.sh -n 20000        # a shorter run
#   bash scripts/fuzz.sh rosserial_scan ground_verify   # only these targets
#
# Rust targets run under cargo-fuzz (libFuzzer + ASan, nightly toolchain) from fuzz/; Python
# targets under atheris (libFuzzer, coverage-guided) or, for the isolated `description`
# target, the mutation engine in a child process per batch (fuzz/python/engines.py).
# Installs atheris and cargo-fuzz when missing. Runs at the lowest priority (nice 19).
# Each target's result is a JSON line in fuzz/out/results.jsonl (or $FUZZ_RESULTS); the
# table is printed at
# the end. Exits non-zero when anything new (not a known open finding) was found.
set -euo pipefail
cd "$(dirname "$0")/.."

PY=${PYTHON:-python3}
RUNS=1000000
if [[ "${1:-}" == "-n" ]]; then
    RUNS=$2
    shift 2
fi
RUST_TARGETS=(rosserial_scan neuron_frame leptrino_ok_run description)
PY_TARGETS=(rosserial_server rosserial_client neuron_can candump_log candump_asc
            leptrino_stream capture_index description ground_decode ground_verify)
WANT=("$@")

wanted() {
    [[ ${#WANT[@]} -eq 0 ]] && return 0
    local t
    for t in "${WANT[@]}"; do [[ "$t" == "$1" ]] && return 0; done
    return 1
}

"$PY" -c "import atheris" 2>/dev/null || "$PY" -m pip install --quiet atheris
cargo +nightly fuzz --version >/dev/null 2>&1 || cargo install --quiet cargo-fuzz

mkdir -p fuzz/out
RESULTS=${FUZZ_RESULTS:-fuzz/out/results.jsonl}
: >"$RESULTS"
status=0
for t in "${RUST_TARGETS[@]}"; do
    wanted "$t" || wanted "rust:$t" || continue
    echo "== rust $t: $RUNS inputs" >&2
    nice -n 19 "$PY" fuzz/python/fuzz.py rust "$t" --runs "$RUNS" >>"$RESULTS" || status=1
    tail -n 1 "$RESULTS" >&2
done
for t in "${PY_TARGETS[@]}"; do
    wanted "$t" || wanted "py:$t" || continue
    echo "== python $t: $RUNS inputs" >&2
    nice -n 19 "$PY" fuzz/python/fuzz.py run "$t" --runs "$RUNS" --keep-going >>"$RESULTS" \
        || status=1
    tail -n 1 "$RESULTS" >&2
done
"$PY" fuzz/python/fuzz.py table "$RESULTS"
exit $status
