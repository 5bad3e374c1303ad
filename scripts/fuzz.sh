#!/usr/bin/env bash
# A longer run of the mutation fuzzer in tests/fuzz.rs over every reader (VDB, project files
# of every version, the particle sidecar, EXR, KTX2, farm.json).
#   FOGSMITH_FUZZ_SEED   seed (default: the time), FOGSMITH_FUZZ_CASES  cases per reader (default 5000)
# Failing inputs land in target/fuzz-failures/; minimise one into tests/corpus/damaged/ with
# a test that fails before its fix.
set -euo pipefail
cd "$(dirname "$0")/.."
export FOGSMITH_FUZZ_SEED="${FOGSMITH_FUZZ_SEED:-$(date +%s)}"
export FOGSMITH_FUZZ_CASES="${FOGSMITH_FUZZ_CASES:-5000}"
echo "fuzz: seed $FOGSMITH_FUZZ_SEED, $FOGSMITH_FUZZ_CASES cases per reader"
exec cargo test --release --locked --test fuzz -- --nocapture
