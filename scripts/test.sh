#!/usr/bin/env bash
# The test command: sets the machine up (idempotent), checks formatting and clippy, then runs
# the whole suite in release mode on the GPU adapter wgpu finds (Mesa's lavapipe on machines without a GPU).
set -euo pipefail
cd "$(dirname "$0")/.."
./setup.sh
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-$(mktemp -d /tmp/fogsmith-xdg.XXXXXX)}"
chmod 700 "$XDG_RUNTIME_DIR"
# Lint first: formatting, then clippy with every warning an error.
cargo fmt --check
cargo clippy --release --all-targets --locked -- -D warnings
cargo test --release --locked "$@"
