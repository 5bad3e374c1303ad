#!/usr/bin/env bash
# The main job: sets the machine up (idempotent), builds Fogsmith and opens the editor on the
# bundled demo room (or on the project given as an argument). Without a display the editor
# says so and points to `fogsmith render`.
set -euo pipefail
cd "$(dirname "$0")/.."
./setup.sh --no-validators   # the test-only Python validators are not needed to run
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-$(mktemp -d /tmp/fogsmith-xdg.XXXXXX)}"
chmod 700 "$XDG_RUNTIME_DIR"
cargo run --release --locked -- "$@"
