#!/usr/bin/env bash
# Installs what is missing, builds everything (tests included) and runs every test with CTest.
# Exit status: CTest's (0 when every test passed). Idempotent.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
bash scripts/setup.sh
ctest --test-dir "${MESHSWEEPER_BUILD_DIR:-build}" --output-on-failure -j "${MESHSWEEPER_JOBS:-2}"
