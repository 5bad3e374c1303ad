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
#    project's lights; the bake through the viewer's emission-absorption material);
# 4. compares (scripts/engine_compare.py): the bake's mean within 3 % and robust rel-RMSE
#    <= 5 %; the silhouettes' IoU >= 0.9.
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
cargo build --quiet --manifest-path engines/bevy/Cargo.toml --target-dir "$viewer_target"
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
"$bin" render "$project" --quiet --image-sampling per-pixel -o "$out/fogsmith-lit.exr"
"$bin" render "$project" --quiet --image-sampling per-pixel -o "$out/fogsmith-lit.png"
# `fogsmith render` cannot render the bake itself; as_baked.py renders the exported texture
# as shaders/as_baked.wgsl does.
"$py" scripts/as_baked.py "$out/$name-baked.ktx2" "$project" "$out/fogsmith-baked.exr"

# Exposures that keep Bevy's brightest pixel below 1 (its image has no tone curve): 0.9 of
# the bake's peak; a quarter of the lit render's, as Bevy's unshadowed fog is brighter.
peak() { "$py" -c "import sys, numpy, OpenEXR
with OpenEXR.File(sys.argv[1], separate_channels=True) as f:
    c = f.channels(); print(max(float(numpy.max(c[k].pixels)) for k in 'RGB'))" "$1"; }
bake_exposure=$("$py" -c "print(0.9 / $(peak "$out/fogsmith-baked.exr"))")
lit_exposure=$("$py" -c "print(0.25 / $(peak "$out/fogsmith-lit.exr"))")

shot() {
  timeout 600 xvfb-run -a -s "-screen 0 1280x720x24" "$viewer" "$@"
}
echo "rendering in Bevy (lavapipe under Xvfb) ..."
shot --baked "$out/$name-baked.ktx2" --project "$project" --exposure "$bake_exposure" --out "$out/bevy-baked.png"
shot --density "$out/$name.ktx2" --project "$project" --exposure "$lit_exposure" --out "$out/bevy-lit.png"

results=$out/results.txt
echo "project: $project; exposures: bake $bake_exposure, lit $lit_exposure" >"$results"
status=0
"$py" scripts/engine_compare.py bake "$out/bevy-baked.png" "$out/fogsmith-baked.exr" "$bake_exposure" >>"$results" || status=1
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
