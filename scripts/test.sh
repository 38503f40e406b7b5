#!/usr/bin/env bash
# Installs missing dependencies, builds, and runs the tests through CTest.
# Usage: scripts/test.sh [preset]     every test of a preset (release, debug or asan; default release)
#        scripts/test.sh --sanitize   the asan preset (Debug, AddressSanitizer + UBSan + LeakSanitizer, their options
#                                     and tests/sanitizers/lsan.supp set by CTest): the tests labelled "sanitize"
#                                     (those of tests/unit/ and passes/*/tests/, and the seeded fuzz samples)
#        scripts/test.sh --sanitize --all   every test of the asan preset
set -euo pipefail
cd "$(dirname "$0")/.."
if [ "${1:-}" = "--sanitize" ]; then
  ./scripts/build.sh asan
  if [ "${2:-}" = "--all" ]; then
    ctest --preset asan -j "$(nproc)" --timeout 1500
  else
    ctest --preset asan -j "$(nproc)" --timeout 1500 -L sanitize
  fi
  exit
fi
preset="${1:-release}"
./scripts/build.sh "$preset"
ctest --preset "$preset" -j "$(nproc)" --timeout 600
