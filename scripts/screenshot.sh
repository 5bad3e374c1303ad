#!/usr/bin/env bash
# Opens the editor in a real window on a virtual X display (Xvfb), waits for the first
# preview frame and saves a PNG of the window, then closes it.
# Usage: scripts/screenshot.sh OUT.png [PROJECT.ron]
# FOGSMITH_BIN names the binary to run (default: build and use the debug binary).
# Editor settings are kept in a temporary folder, so the default layout is shown.
set -euo pipefail
if [ $# -lt 1 ]; then
  echo "usage: $0 OUT.png [PROJECT.ron]" >&2
  exit 2
fi
out=$1
shift
command -v xvfb-run >/dev/null || { echo "$0: xvfb-run not found; run ./setup.sh" >&2; exit 1; }
bin=${FOGSMITH_BIN:-}
if [ -z "$bin" ]; then
  cargo build --quiet --bin fogsmith
  bin=${CARGO_TARGET_DIR:-$(dirname "$0")/../target}/debug/fogsmith
fi
state=$(mktemp -d)
trap 'rm -rf "$state"' EXIT
XDG_DATA_HOME=$state XDG_CONFIG_HOME=$state XDG_RUNTIME_DIR=$state \
  timeout 300 xvfb-run -a -s "-screen 0 1400x900x24" "$bin" "$@" --screenshot "$out"
test -s "$out"
