#!/usr/bin/env bash
# Installs what Meshsweeper needs (Debian 12 packages), extracts the bundled meshes and builds
# everything (library, tools, tests, benchmarks) into build/ (Release). Idempotent: a second
# run installs nothing and rebuilds only what changed.
#
# Environment:
#   MESHSWEEPER_BUILD_DIR   build directory (default: build)
#   MESHSWEEPER_CMAKE_ARGS  extra CMake arguments, e.g. "-DMESHSWEEPER_BUILD_BENCH=OFF"
#   MESHSWEEPER_JOBS        parallel build jobs (default: nproc)
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
build_dir="${MESHSWEEPER_BUILD_DIR:-build}"
jobs="${MESHSWEEPER_JOBS:-$(nproc)}"

say() { printf 'setup: %s\n' "$*" >&2; }

# 1. Packages. libcgal-demo ships the real meshes (/usr/share/doc/libcgal-dev/data.tar.gz).
packages=(build-essential cmake libeigen3-dev libtbb-dev catch2 libbenchmark-dev libcgal-dev
          libcgal-demo libembree-dev libopenvdb-dev libpng-dev libstb-dev)
missing=()
for package in "${packages[@]}"; do
  status="$(dpkg-query -W -f='${db:Status-Status}' "$package" 2>/dev/null || true)"
  [[ "$status" == installed ]] || missing+=("$package")
done
if ((${#missing[@]})); then
  if [[ $(id -u) -eq 0 ]]; then
    sudo=()
  elif command -v sudo >/dev/null 2>&1; then
    sudo=(sudo)
  else
    say "missing packages: ${missing[*]}"
    say "run as root: apt-get update && apt-get install -y --no-install-recommends ${missing[*]}"
    exit 1
  fi
  log="$(mktemp)"
  say "installing ${missing[*]}"
  say "(apt-get update and install: a few minutes on a fresh machine; log kept if it fails)"
  if ! { "${sudo[@]}" apt-get update &&
         "${sudo[@]}" env DEBIAN_FRONTEND=noninteractive \
           apt-get install -y --no-install-recommends "${missing[@]}"; } >"$log" 2>&1; then
    tail -n 40 "$log" >&2
    say "package installation failed (full log: $log)"
    exit 1
  fi
  rm -f "$log"
fi

# 2. Real meshes into data/meshes.
if [[ -f scripts/fetch_data.sh ]]; then
  bash scripts/fetch_data.sh
else
  say "scripts/fetch_data.sh not found: skipping the real meshes"
fi

# 3. Configure and build. Progress lines go to the log; compiler warnings and errors show.
mkdir -p "$build_dir"
configure_log="$build_dir/configure.log"
# shellcheck disable=SC2086  # MESHSWEEPER_CMAKE_ARGS is a list of arguments
if ! cmake -S . -B "$build_dir" -DCMAKE_BUILD_TYPE=Release ${MESHSWEEPER_CMAKE_ARGS:-} \
     >"$configure_log" 2>&1; then
  cat "$configure_log" >&2
  say "configure failed (log: $configure_log)"
  exit 1
fi
say "building into $build_dir with $jobs jobs (progress: $build_dir/build.log)"
start=$SECONDS
if ! cmake --build "$build_dir" -j "$jobs" >"$build_dir/build.log"; then
  grep -E 'error|Error' "$build_dir/build.log" | tail -n 40 >&2 || true
  say "build failed (log: $build_dir/build.log)"
  exit 1
fi
say "built in $((SECONDS - start)) s"
