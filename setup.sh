#!/usr/bin/env bash
# Installs what a fresh Debian/Ubuntu machine lacks to build, run and test Fogsmith.
# Idempotent: packages already present are skipped, so it is cheap to run every time.
set -euo pipefail

PACKAGES=(
  mesa-vulkan-drivers   # lavapipe: a software Vulkan adapter when there is no GPU
  libvulkan1            # the Vulkan loader wgpu opens
  xvfb                  # a virtual display for the editor's window tests
  xauth
  python3-openvdb       # OpenVDB itself, to check exported .vdb files
  python3-venv          # the validators' virtual environment below
  libopenvdb-tools      # vdb_tool: writes zip / uncompressed .vdb files for the import tests
  libnanovdb-tools      # nanovdb_validate / _print / _convert, to check exported .nvdb files
  openexr               # exrheader / exrinfo, to check exported .exr files
  fonts-dejavu-core     # the font of the benchmark plots
  pkg-config
  libxkbcommon-x11-0    # winit on X11
  libx11-xcb1
  slurm-wlm             # for the tests only: slurmctld, slurmd and sbatch for a single-node cluster
  munge                 # Slurm's authentication daemon, started by the same test
  libllvm19             # the LLVM that Mitsuba 3's CPU variants load (LLVM 15 aborts)
)

missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done

if [ ${#missing[@]} -gt 0 ]; then
  SUDO=""
  [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -y
  $SUDO apt-get install -y --no-install-recommends "${missing[@]}"
fi

if ! command -v cargo >/dev/null 2>&1; then
  echo "setup.sh: cargo not found. Install Rust (https://rustup.rs) and run again." >&2
  exit 1
fi
echo "setup.sh: system packages ready (${#missing[@]} installed now)."

# Test-only validators from PyPI, in a git-ignored virtual environment inside the project
# (never needed to run Fogsmith: `./setup.sh --no-validators` skips them): Pixar's usd-core
# checks the USD export, Blender as a Python module (bpy 4.5, for Debian's Python 3.11)
# imports it, OpenEXR's own bindings read the EXR exports, and openjd-cli checks and runs the
# render-farm job bundles. Each package is installed only when the venv cannot import it yet.
if [ "${1:-}" = "--no-validators" ]; then
  exit 0
fi
VENV="$(cd "$(dirname "$0")" && pwd)/.venv"
PY=/usr/bin/python3
if [ ! -x "$VENV/bin/python" ]; then
  "$PY" -m venv "$VENV"
fi
need=()
"$VENV/bin/python" -c "from pxr import Usd, UsdVol, UsdLux, UsdValidation" 2>/dev/null || need+=("usd-core==26.11")
"$VENV/bin/python" -c "import OpenEXR; OpenEXR.File" 2>/dev/null || need+=("openexr==3.5.3")
"$VENV/bin/python" -c "import openjd.cli" 2>/dev/null || need+=("openjd-cli==0.8.0")
"$VENV/bin/python" -c "import bpy, sys; sys.exit(0 if bpy.app.version[:2] == (4, 5) else 1)" 2>/dev/null || need+=("bpy==4.5.*")
# Mitsuba 3, the path tracer that scripts/mitsuba_reference.py renders reference images with.
"$VENV/bin/python" -c "import mitsuba, sys; sys.exit(0 if mitsuba.__version__ == '3.9.1' else 1)" 2>/dev/null || need+=("mitsuba==3.9.1")
if [ ${#need[@]} -gt 0 ]; then
  echo "setup.sh: installing ${need[*]} into $VENV (bpy is a ~370 MB download)"
  "$VENV/bin/python" -m pip install --quiet --disable-pip-version-check "${need[@]}"
fi
echo "setup.sh: validators ready in $VENV (${#need[@]} installed now)."
