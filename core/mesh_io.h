#pragma once
// Reading meshes and point lists from files. Every function here meets untrusted input: it
// returns a result or throws MeshError naming the file and the problem; it never crashes,
// hangs or allocates according to an absurd count in a header.
#include "core/mesh.h"

#include <string>
#include <string_view>
#include <vector>

namespace meshsweeper {

// Reads OFF, OBJ, PLY (ASCII or binary) or STL (ASCII or binary), chosen by extension
// (case-insensitive), through CGAL's polygon-soup readers (binary STL by the project's own
// reader), each file checked first (README "Mesh input").
// Vertex order and face order are the file's; polygons are fan-triangulated in face order
// (face f with corners c0..ck gives (c0,c1,c2), (c0,c2,c3), ...), so a result's triangle index
// indexes that triangle list (a polygon that its first corner does not see whole is cut into
// ears instead, within a work budget per file; README "Mesh input"). Exception: STL stores three corners per triangle and no
// vertices; corners with exactly equal coordinates are merged into one vertex, numbered in order
// of first appearance, so an STL mesh has shared vertices and triangle t is the file's triangle
// t. Degenerate triangles, duplicate and isolated vertices are kept; OBJ 'l' (line) elements are
// skipped. Binary OFF, SKEL, nOFF and polygons of more than 2^20 corners are refused.
// Throws MeshError ("PATH: problem") on a missing, unreadable, truncated or garbage file, header
// counts the file size cannot hold (checked before anything is allocated), non-finite
// coordinates, out-of-range indices, a face with fewer than 3 corners or a mesh without faces.
Mesh readMesh(const std::string& path);

// Writes an ASCII OFF file. Throws MeshError when the file cannot be written.
void writeOff(const Mesh& mesh, const std::string& path);

// Reads query points: text, one "x y z" per line, '#' starts a comment, blank lines ignored;
// path "-" reads standard input. Throws MeshError ("PATH:LINE: problem") on malformed lines or
// non-finite values.
std::vector<Vec3> readPoints(const std::string& path);

// `text` made fit for a one-line message: a control byte (below 0x20, and 0x7f) written as its
// C escape ("\n", "\r", "\t", "\x1b"), and with `escape_non_ascii` every byte past 0x7e too (a
// file's garbage; without it UTF-8 stays as it is); a backslash as it is.
std::string escapedText(std::string_view text, bool escape_non_ascii);

}  // namespace meshsweeper
