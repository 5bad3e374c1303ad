#!/usr/bin/env bash
# Runs a Fogsmith export in Bevy and compares Bevy's screenshots with Fogsmith's renders of the
# same view (docs/engine-check.md records the last result). Opt-in, not part of scripts/test.sh:
# it builds Bevy (engines/bevy, its own Cargo project).
#
#   scripts/engine-check.sh [PROJECT.ron]      # default projects/cloud.ron
#
# 1. exports the project's density (`--ktx2`) and light bake (`--bake-light --ktx2`);
# 2. renders with Fogsmith the lit image (linear EXR), and the exported bake as emission and
#    absorption (scripts/as_baked.py, the "as baked" view);
# 3. renders the same view in Bevy under Xvfb (the density in Bevy's FogVolume with the
#    project's lights, and once more in front of a grey background for its opacity; the bake
#    through the viewer's emission-absorption material);
# 4. compares (scripts/engine_compare.py): the bake's mean within 3 % and robust rel-RMSE
#    <= 5 %; the IoU of the fog's opacity silhouettes >= 0.9 (placement, orientation, scale),
#    and that of the lit silhouettes (pixels above 5 % of the maximum) >= 0.9.
#
# FOGSMITH_BIN names a built fogsmith (default: cargo build --release). The files land in
# $ENGINE_CHECK_OUT (default out/engine-check), the summary in its results.txt.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
project=${1:-projects/cloud.ron}
name=$(basename "$project" .ron)
out=${ENGINE_CHECK_OUT:-$root/out/engine-check}
mkdir -p "$out"
out=$(cd "$out" && pwd)

./setup.sh --no-validators
venv=$root/.venv
[ -x "$venv/bin/python" ] || /usr/bin/python3 -m venv "$venv"
"$venv/bin/python" -c "import numpy, OpenEXR; OpenEXR.File" 2>/dev/null ||
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check "openexr==3.5.3"
py=$venv/bin/python

bin=${FOGSMITH_BIN:-}
if [ -z "$bin" ]; then
  cargo build --release --quiet --bin fogsmith
  bin=${CARGO_TARGET_DIR:-$root/target}/release/fogsmith
fi
viewer_target=${CARGO_TARGET_DIR:-$root/engines/bevy/target}
echo "building the Bevy viewer (engines/bevy) ..."
cargo build --quiet --locked --manifest-path engines/bevy/Cargo.toml --target-dir "$viewer_target"
viewer=$viewer_target/debug/fogsmith-bevy-viewer

if [ -z "${XDG_RUNTIME_DIR:-}" ] || [ ! -w "${XDG_RUNTIME_DIR:-/nonexistent}" ]; then
  XDG_RUNTIME_DIR=$(mktemp -d)
  chmod 700 "$XDG_RUNTIME_DIR"
  export XDG_RUNTIME_DIR
fi
export WGPU_BACKEND=${WGPU_BACKEND:-vulkan}

echo "exporting $project ..."
"$bin" export "$project" --quiet --ktx2 "$out/$name.ktx2"
"$bin" export "$project" --quiet --bake-light --bake-phase camera --ktx2 "$out/$name-baked.ktx2"
echo "rendering with Fogsmith ..."
# One ray per pixel, as Bevy's, where fogsmith has the choice.
sampling=()
"$bin" render --help | grep -- --image-sampling >/dev/null && sampling=(--image-sampling per-pixel)
"$bin" render "$project" --quiet "${sampling[@]}" -o "$out/fogsmith-lit.exr"
"$bin" render "$project" --quiet "${sampling[@]}" -o "$out/fogsmith-lit.png"
# `fogsmith render` cannot render the bake itself; as_baked.py renders the exported texture
# as shaders/as_baked.wgsl does.
"$py" scripts/as_baked.py "$out/$name-baked.ktx2" "$project" "$out/fogsmith-baked.exr"

# Bevy's image has no tone curve: exposures that put its brightest pixel near 0.9, so nothing
# clips and the dark fog keeps its 8-bit steps. The bake's peak is Fogsmith's; Bevy lights its
# FogVolume otherwise, so the lit shot is taken once to measure its peak, then again.
peak() { "$py" scripts/engine_compare.py peak "$1"; }
scaled() { "$py" -c "import sys; print(float(sys.argv[1]) * 0.9 / max(float(sys.argv[2]), 1e-30))" "$1" "$2"; }
shot() {
  timeout 600 xvfb-run -a -s "-screen 0 1280x720x24" "$viewer" "$@" >>"$out/viewer.log" 2>&1 ||
    { echo "the Bevy viewer failed ($*); its log: $out/viewer.log" >&2; tail -20 "$out/viewer.log" >&2; exit 1; }
}
: >"$out/viewer.log"
echo "rendering in Bevy (lavapipe under Xvfb) ..."
bake_exposure=$(scaled 1 "$(peak "$out/fogsmith-baked.exr")")
shot --baked "$out/$name-baked.ktx2" --project "$project" --exposure "$bake_exposure" --out "$out/bevy-baked.png"
lit_exposure=$(scaled 1 "$(peak "$out/fogsmith-lit.exr")")
shot --density "$out/$name.ktx2" --project "$project" --exposure "$lit_exposure" --out "$out/bevy-lit.png"
lit_peak=$(peak "$out/bevy-lit.png")
if "$py" -c "import sys; sys.exit(0 if float(sys.argv[1]) >= 0.99 else 1)" "$lit_peak"; then
  lit_exposure=$("$py" -c "import sys; print(float(sys.argv[1]) / 16)" "$lit_exposure")
  shot --density "$out/$name.ktx2" --project "$project" --exposure "$lit_exposure" --out "$out/bevy-lit.png"
  lit_peak=$(peak "$out/bevy-lit.png")
fi
lit_exposure=$(scaled "$lit_exposure" "$lit_peak")
shot --density "$out/$name.ktx2" --project "$project" --exposure "$lit_exposure" --out "$out/bevy-lit.png"
# The fog's opacity: in front of a grey background, with its own light exposed away.
shot --density "$out/$name.ktx2" --project "$project" --exposure 1e-6 --background 0.8 --out "$out/bevy-opacity.png"

results=$out/results.txt
echo "project: $project; exposures: bake $bake_exposure, lit $lit_exposure" >"$results"
status=0
"$py" scripts/engine_compare.py bake "$out/bevy-baked.png" "$out/fogsmith-baked.exr" "$bake_exposure" >>"$results" || status=1
"$py" scripts/engine_compare.py opacity "$out/bevy-opacity.png" 0.8 "$out/fogsmith-lit.exr" >>"$results" || status=1
"$py" scripts/engine_compare.py shape "$out/bevy-lit.png" "$out/fogsmith-lit.exr" >>"$results" || status=1
# For information (no bound): the bake in Bevy against Fogsmith's lit render, which the bake
# approximates (camera phase) up to its grid's resolution.
"$py" scripts/engine_compare.py bake "$out/bevy-baked.png" "$out/fogsmith-lit.exr" "$bake_exposure" --label "bake vs lit" >>"$results" || true
cat "$results"
if [ "$status" -eq 0 ]; then
  echo "engine check: within bounds"
else
  echo "engine check: FAILED: a figure is out of bounds (above)"
fi
exit "$status"
