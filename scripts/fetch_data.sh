#!/usr/bin/env bash
# Extracts the real test meshes (data/meshes/*.off, plus a few .ply and .stl) from the CGAL data
# archive that Debian's libcgal-demo package installs, into <repo>/data/meshes.
#
# Idempotent: does nothing when the meshes are already there (pass --force to extract again).
# Installs nothing: when the archive is missing it says which package to install and fails.
#
# Usage: scripts/fetch_data.sh [--force]
#   CGAL_DATA_ARCHIVE  the archive (default /usr/share/doc/libcgal-dev/data.tar.gz)
set -euo pipefail

repo_root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
archive="${CGAL_DATA_ARCHIVE:-/usr/share/doc/libcgal-dev/data.tar.gz}"
target="${repo_root}/data/meshes"
# Meshes the tests and benchmarks name: an extraction must hold them.
required=(armadillo bunny00 refined_elephant elephant holes mannequin-devil camel fandisk blobby_3cc)
# Written last by a finished extraction: the name of every mesh it put there. A run is needed
# again when it is missing (an interrupted run) or a mesh it lists is missing or empty.
stamp="${target}/.extracted"

all_present() {
  local name
  for name in "${required[@]}"; do
    [[ -s "${target}/${name}.off" ]] || return 1
  done
}

complete() {
  [[ -s "${stamp}" ]] && all_present || return 1
  local name
  while IFS= read -r name; do
    [[ -s "${target}/${name}" ]] || return 1
  done <"${stamp}"
}

force=0
case "${1:-}" in
  "") ;;
  --force) force=1 ;;
  *) echo "usage: $0 [--force]" >&2; exit 2 ;;
esac

if [[ ${force} -eq 0 ]] && complete; then
  echo "fetch_data: meshes already in ${target}"
  exit 0
fi

if [[ ! -r "${archive}" ]]; then
  echo "fetch_data: ${archive} not found." >&2
  echo "fetch_data: it comes with Debian's libcgal-demo package: install libcgal-demo" >&2
  echo "fetch_data: (e.g. 'apt-get install libcgal-demo'), or set CGAL_DATA_ARCHIVE." >&2
  exit 1
fi

# Extract into a scratch folder next to the target, then move into place; the stamp goes first
# and comes back last, so that an interrupted run never leaves a data/meshes that looks finished.
mkdir -p "${repo_root}/data"
scratch="$(mktemp -d "${repo_root}/data/.fetch.XXXXXX")"
trap 'rm -rf "${scratch}"' EXIT
tar -xzf "${archive}" -C "${scratch}" --strip-components=2 --wildcards \
  'data/meshes/*.off' 'data/meshes/*.ply' 'data/meshes/*.stl'

mkdir -p "${target}"
rm -f "${stamp}"
find "${scratch}" -maxdepth 1 -type f \( -name '*.off' -o -name '*.ply' -o -name '*.stl' \) \
  -printf '%f\n' | LC_ALL=C sort >"${scratch}/.list"
find "${scratch}" -maxdepth 1 -type f \( -name '*.off' -o -name '*.ply' -o -name '*.stl' \) \
  -exec mv -f {} "${target}/" \;

if ! all_present; then
  echo "fetch_data: extraction finished but some expected meshes are missing:" >&2
  for name in "${required[@]}"; do
    [[ -s "${target}/${name}.off" ]] || echo "  ${name}.off" >&2
  done
  exit 1
fi
mv -f "${scratch}/.list" "${stamp}"
count="$(wc -l <"${stamp}")"
echo "fetch_data: ${count} meshes in ${target}"
