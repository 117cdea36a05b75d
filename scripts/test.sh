#!/usr/bin/env bash
# Installs what is missing, builds everything (tests included) and runs every test with CTest.
# Exit status: CTest's (0 when every test passed). Idempotent.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
# Tests and the tool are switched on whatever an earlier configure of the build folder chose
# (CMake keeps options in its cache: a demo run with MESHSWEEPER_BUILD_TESTS=OFF left them off,
# and CTest then ran an old list of tests that were never built, or none at all).
MESHSWEEPER_CMAKE_ARGS="${MESHSWEEPER_CMAKE_ARGS:-} -DMESHSWEEPER_BUILD_TESTS=ON -DMESHSWEEPER_BUILD_TOOLS=ON" \
  bash scripts/setup.sh
# No tests found is a failure, not a pass.
cd "${MESHSWEEPER_BUILD_DIR:-build}"
ctest --output-on-failure --no-tests=error -j "${MESHSWEEPER_JOBS:-2}"
