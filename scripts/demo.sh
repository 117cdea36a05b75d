#!/usr/bin/env bash
# The main job on real bundled data: installs what is missing and builds (scripts/setup.sh),
# then answers closest-point queries on the armadillo (52k triangles) for 10,000 points near
# its surface. Outputs go to out/ (not committed):
#   out/points.txt    the query points (meshsweep sample, fixed seed)
#   out/closest.csv   one row per point: point,rank,distance,lower,upper,triangle,x,y,z,b0,b1,b2
# The JSON summary of the run is printed (and kept in out/closest.json).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
bash scripts/setup.sh

build_dir="${MESHSWEEPER_BUILD_DIR:-build}"
meshsweep="$build_dir/tools/meshsweep"
mesh=data/meshes/armadillo.off
mkdir -p out

# 1. Closest points: 10,000 points within 1% of the bounding-box diagonal of the surface.
"$meshsweep" sample "$mesh" 10000 --near 0.01 --seed 1 --out out/points.txt
if ! "$meshsweep" closest "$mesh" out/points.txt --out out/closest.csv 2>out/closest.json; then
  cat out/closest.json >&2
  exit 1
fi
echo "closest points: out/closest.csv"
cat out/closest.json

# 2. Hausdorff distance and scene pictures: added here by their issues.
# Scene pictures (PNG): meshsweep scene NAME writes out/scenes/NAME.png and prints its bounds
# and timings (see README "Scenes and pictures").
for scene in hausdorff particle cloth; do
  "$meshsweep" scene "$scene" --out out/scenes
done
echo "pictures (PNG): $root/out/scenes/hausdorff.png, particle.png, cloth.png"
