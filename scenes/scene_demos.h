#pragma once
// Demo scenes that write pictures (PNG, through scenes/render.h), run by
// `meshsweep scene NAME [--out DIR]` and scripts/demo.sh. Each prints what it computed (bounds,
// timings) to `log` and returns the path of the PNG it wrote.
// Throws MeshError when a mesh cannot be read or the PNG cannot be written.
#include "core/mesh.h"

#include <cstdio>
#include <string>
#include <vector>

namespace meshsweeper::scenes {

// Names of the scenes, in the order `meshsweep scene all` runs them.
const std::vector<std::string>& sceneNames();

// Runs the scene `name` ("hausdorff", "particle", "cloth"), writing DIR/NAME.png.
// Throws std::invalid_argument for an unknown name. `out_dir` must exist.
std::string runScene(const std::string& name, const std::string& out_dir, std::FILE* log);

// Vertex clustering on a regular grid (Rossignac-Borrel): every vertex moves to the mean of
// the vertices in its cell of a grid of `cells` cells along the longest side of the bounding
// box; triangles that collapse, and repeated triangles, are dropped. Deterministic.
// Precondition: checkMesh(mesh) passes; cells >= 1.
Mesh clusterVertices(const Mesh& mesh, int cells);

// The scenes (each writes DIR/NAME.png and returns its path).
std::string hausdorffScene(const std::string& out_dir, std::FILE* log);
std::string particleScene(const std::string& out_dir, std::FILE* log);
std::string clothScene(const std::string& out_dir, std::FILE* log);

}  // namespace meshsweeper::scenes
