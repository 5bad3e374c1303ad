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
  libopenvdb-tools      # vdb_tool: writes zip / uncompressed .vdb files for the import tests
  openexr               # exrheader / exrinfo, to check exported .exr files
  fonts-dejavu-core     # the font of the benchmark plots
  pkg-config
  libxkbcommon-x11-0    # winit on X11
  libx11-xcb1
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
