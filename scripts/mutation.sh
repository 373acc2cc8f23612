#!/usr/bin/env bash
# Mutation campaign (docs/fuzzing.md, "Mutation testing"): mutmut over the Python modules of the robot path,
# cargo-mutants over the Rust wire codecs, the model's allocation, statics and aerial ZMP,
# the position, LQI and perching-QP controllers and the estimator.
#
#   bash scripts/mutation.sh python [OUT]   # mutmut; survivors listed in OUT/mutmut.txt
#   bash scripts/mutation.sh rust [OUT]     # cargo-mutants; OUT/mutants.out/{caught,missed}.txt
#
# Each runs in a copy of the committed tree (git archive HEAD) under OUT (default
# ./mutation-out), never in the working tree. The Python form needs the test extra and the
# built extension (python/rdm/_rdm.abi3.so, `pip install -e .`), mutmut>=3.4 and pytest;
# the Rust form needs `cargo install cargo-mutants`.
set -euo pipefail
cd "$(dirname "$0")/.."
what=${1:?python or rust}
out=$(realpath -m "${2:-mutation-out}")
mkdir -p "$out"
tree="$out/tree-$what"
rm -rf "$tree"
mkdir -p "$tree"
git archive HEAD | tar -x -C "$tree"

# The modules under mutation and the tests that are their oracle.
PY_MODULES=(
  rdm/nodes/onboard_monitors.py
  rdm/ground/auth.py
  rdm/ground/message.py
  rdm/protocol/leptrino.py
)
PY_TESTS=(
  tests/test_onboard_monitors.py
  tests/test_onboard_monitor_rules.py
  tests/test_onboard_flight_safety.py
  tests/test_ground_link.py
  tests/test_ground_verifier.py
  tests/test_ground_message_rules.py
  tests/test_leptrino.py
  tests/test_leptrino_conversions.py
  tests/test_decode_streaming.py
  tests/test_decode.py
  tests/test_fuzz_short.py
  tests/test_onboard_foot.py
  tests/test_onboard_perch.py
)
RUST_FILES=(
  crates/rdm_core/src/firmware/rosserial_frame.rs
  crates/rdm_core/src/firmware/neuron_frame.rs
  crates/rdm_core/src/control/position.rs
  crates/rdm_core/src/estimate/mod.rs
  crates/rdm_core/src/model/allocation.rs
  crates/rdm_core/src/model/aerial_zmp.rs
  crates/rdm_core/src/model/statics.rs
  crates/rdm_core/src/control/lqi/gain_map.rs
  crates/rdm_core/src/control/lqi/system.rs
  crates/rdm_core/src/control/lqi/mod.rs
  crates/rdm_core/src/control/perch/qp/rows.rs
)

case "$what" in
python)
  cp python/rdm/_rdm.abi3.so "$tree/python/rdm/"
  # mutmut names a module by its path below the source folder, and strips only "src.":
  # the package folder is reached as src/rdm so the mutants are rdm.* modules.
  ln -s python "$tree/src"
  {
    echo "[mutmut]"
    echo "source_paths=src"
    echo "only_mutate="
    for m in "${PY_MODULES[@]}"; do echo "    src/$m"; done
    echo "also_copy="
    echo "    firmware_protocol"
    echo "    fuzz"
    echo "pytest_add_cli_args_test_selection="
    for t in "${PY_TESTS[@]}"; do echo "    $t"; done
  } >"$tree/setup.cfg"
  (cd "$tree" && mutmut run --max-children "${JOBS:-1}" >"$out/mutmut.log" 2>&1 || true)
  (cd "$tree" && mutmut results --all true >"$out/mutmut-all.txt" 2>&1 || true)
  (cd "$tree" && mutmut results >"$out/mutmut.txt" 2>&1 || true)
  echo "survivors: $(grep -c ': survived' "$out/mutmut.txt" || true) ($out/mutmut.txt)"
  ;;
rust)
  args=()
  for f in "${RUST_FILES[@]}"; do args+=(--file "$f"); done
  (cd "$tree" && cargo mutants -p rdm_core "${args[@]}" -j 1 --timeout 300 --shuffle \
    -o "$out" ${CARGO_MUTANTS_ARGS:-} || true)
  echo "missed: $(wc -l <"$out/mutants.out/missed.txt") ($out/mutants.out/missed.txt)"
  ;;
*)
  echo "usage: bash scripts/mutation.sh python|rust [OUT]" >&2
  exit 2
  ;;
esac
