#!/usr/bin/env bash
# Installs Loom's build dependencies from Debian packages. Idempotent: only
# missing packages are installed. When not root, prints the apt-get line.
set -euo pipefail

PACKAGES=(
  build-essential cmake ninja-build pkg-config
  libglm-dev libglfw3-dev libtinygltf-dev nlohmann-json3-dev
  libopenexr-dev libimath-dev libspdlog-dev libfmt-dev
  libembree-dev libtbb-dev libimgui-dev libstb-dev libcli11-dev libhwy-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  libopencv-contrib-dev
  python3-matplotlib
  libegl-dev libgl-dev libegl1-mesa-dev libgl1-mesa-dri libgles-dev
  xvfb xauth xdotool
  slurm-wlm munge
)

missing=()
for p in "${PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  exit 0
fi

if [ "$(id -u)" -ne 0 ]; then
  echo "Loom needs these Debian packages, which are missing:" >&2
  echo "  sudo apt-get update && sudo apt-get install -y ${missing[*]}" >&2
  exit 1
fi

echo "setup: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
if ! apt-get install -y --no-install-recommends "${missing[@]}"; then
  apt-get update
  apt-get install -y --no-install-recommends "${missing[@]}"
fi
