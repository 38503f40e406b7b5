#!/usr/bin/env bash
# Installs missing dependencies, builds, and runs every test through CTest.
# Usage: scripts/test.sh [preset]   (release, debug or asan; default release)
set -euo pipefail
cd "$(dirname "$0")/.."
preset="${1:-release}"
./scripts/build.sh "$preset"
ctest --preset "$preset" -j "$(nproc)" --timeout 600
